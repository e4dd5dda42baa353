//! Steps the default surrogate a million times (for `perf stat`; the real measurement is
//! the criterion bench `benches/surrogate.rs`).
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::{build, EngineCommand, PropulsionKind};

fn main() {
    let mut model = build(PropulsionKind::Surrogate, &PropulsionConfig::default());
    let mut cmd = EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true; 4],
    };
    let mut sum = 0.0;
    let t0 = std::time::Instant::now();
    for k in 0..1_000_000u64 {
        cmd.thrust_cmd_n[(k % 4) as usize] = 400.0 + (k % 300) as f64;
        sum += model.step(&cmd, 10_000_000).thrust_n[0];
    }
    println!("{sum} {:.1} ns/step", t0.elapsed().as_nanos() as f64 / 1e6);
}
