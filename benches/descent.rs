//! Whole default descents in process, the figure campaigns feel: wall time of one
//! landing with the reference GNC, per propulsion model (`cargo bench --bench descent`).
//! Across processes the same descent is measured by the run report (`oils run
//! --report`), since it needs two processes.

use criterion::{criterion_group, criterion_main, Criterion};
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::run_config::{LinkKind, RunConfig};
use std::sync::atomic::AtomicBool;

fn descent(c: &mut Criterion) {
    let mut group = c.benchmark_group("descent_inproc");
    group.sample_size(10);
    for model in [PropulsionKind::Ideal, PropulsionKind::Surrogate] {
        let mut cfg = RunConfig {
            link: LinkKind::Inproc,
            propulsion: model,
            ..Default::default()
        };
        cfg.log.enabled = false;
        let stop = AtomicBool::new(false);
        group.bench_function(model.as_str(), |b| {
            b.iter(|| {
                let r =
                    oils_lab::onboard::fly_in_process(&cfg, 1, &stop, Default::default()).unwrap();
                assert_eq!(r.summary.outcome, oils_emulator::scheduler::Outcome::Landed);
                r.summary.steps
            })
        });
    }
    group.finish();
}

criterion_group!(benches, descent);
criterion_main!(benches);
