//! One 10 ms step of the surrogate propulsion model for four engines (the step alone; the figure that matters is a whole descent, `emulator/examples/surrogate_descent.rs`):
//! steady running (the phase terms skipped, the common case) and engines switching
//! off and on in turn (stop phases and ignition windows, their terms evaluated in some
//! lanes and not others). The four engines are the four lanes of one vector.

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

fn surrogate_step_switching(c: &mut Criterion) {
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
    c.bench_function("surrogate_step_10ms_4_engines_switching", |b| {
        b.iter(|| {
            k += 1;
            // Every 40 steps the next engine goes off for 20 steps: always one engine in
            // a stop phase or an ignition window, the others running.
            let e = ((k / 40) % 4) as usize;
            cmd.on = [true; 4];
            cmd.on[e] = k % 40 >= 20;
            black_box(model.step(black_box(&cmd), 10_000_000))
        })
    });
}

criterion_group!(benches, surrogate_step, surrogate_step_switching);
criterion_main!(benches);
