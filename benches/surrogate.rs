//! One 10 ms step of the surrogate propulsion model for four engines (the step alone; the figure that matters is a whole descent, `emulator/examples/surrogate_descent.rs`).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::{build, EngineCommand, PropulsionKind, PropulsionSpec};

fn surrogate_step(c: &mut Criterion) {
    let mut model = build(&PropulsionSpec::new(
        PropulsionKind::Surrogate,
        &PropulsionConfig::default(),
    ))
    .unwrap();
    let mut cmd = EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true; 4],
    };
    let mut k = 0u64;
    c.bench_function("surrogate_step_10ms_4_engines", |b| {
        b.iter(|| {
            k += 1;
            // A slowly varying command keeps the model in its envelope.
            cmd.thrust_cmd_n[(k % 4) as usize] = 400.0 + (k % 300) as f64;
            black_box(model.step(black_box(&cmd), 10_000_000))
        })
    });
}

criterion_group!(benches, surrogate_step);
criterion_main!(benches);
