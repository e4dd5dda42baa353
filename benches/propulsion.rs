//! Cost of one 10 ms control step of each propulsion model at mid throttle: hifi,
//! ideal and the surrogate (committed default model, four engines) in one run, so their
//! ratio comes from one measurement session.
//!
//! `cargo bench --bench propulsion -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, Criterion};
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::{HifiParams, HifiPropulsion};
use oils_emulator::propulsion::ideal::IdealPropulsion;
use oils_emulator::propulsion::surrogate::SurrogatePropulsion;
use oils_emulator::propulsion::{EngineCommand, Propulsion};
use std::hint::black_box;
use std::time::{Duration, Instant};

const STEP_NS: u64 = 10_000_000;

fn mid_throttle() -> EngineCommand {
    EngineCommand {
        thrust_cmd_n: [560.0; 4],
        on: [true; 4],
    }
}

/// Times `iters` steps of clones of a warmed-up model; the model is re-cloned every
/// 20 000 steps (200 s simulated) so it never runs its tanks dry whatever the count.
fn time_steps<P: Propulsion + Clone>(warm: &P, iters: u64) -> Duration {
    let cmd = mid_throttle();
    let mut total = Duration::ZERO;
    let mut left = iters;
    while left > 0 {
        let chunk = left.min(20_000);
        let mut m = warm.clone();
        let start = Instant::now();
        for _ in 0..chunk {
            black_box(m.step(black_box(&cmd), STEP_NS));
        }
        total += start.elapsed();
        left -= chunk;
    }
    total
}

fn bench(c: &mut Criterion) {
    let cfg = PropulsionConfig::default();
    let mut hifi = HifiPropulsion::new(&HifiParams::default(), &cfg).expect("default hifi");
    let mut ideal = IdealPropulsion::new(&cfg);
    let mut surrogate =
        SurrogatePropulsion::default_model(&cfg, Some(STEP_NS)).expect("committed surrogate");
    for _ in 0..300 {
        hifi.step(&mid_throttle(), STEP_NS);
        ideal.step(&mid_throttle(), STEP_NS);
        surrogate.step(&mid_throttle(), STEP_NS);
    }
    c.bench_function("hifi_step_10ms", |b| {
        b.iter_custom(|n| time_steps(&hifi, n))
    });
    c.bench_function("ideal_step_10ms", |b| {
        b.iter_custom(|n| time_steps(&ideal, n))
    });
    c.bench_function("surrogate_step_10ms_4_engines", |b| {
        b.iter_custom(|n| time_steps(&surrogate, n))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
