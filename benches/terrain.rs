//! Cost of the terrain queries per call (elevation, normal, height above ground, ray
//! casts) on the default synthetic surface about the Chandrayaan-3 site, and the cost of
//! building that surface once.
//!
//! `cargo bench --bench terrain -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use oils_emulator::world::terrain::{build, SiteFrame, SyntheticSpec, Terrain, TerrainSpec};
use std::hint::black_box;

fn site() -> SiteFrame {
    SiteFrame::from_deg(-69.373, 32.319, 1_737_400.0)
}

fn default_synthetic() -> TerrainSpec {
    TerrainSpec::Synthetic(SyntheticSpec::default())
}

/// Query points spread over the grid (a fixed pseudo-random walk).
fn points() -> Vec<(f64, f64)> {
    (0..1024)
        .map(|k| {
            let x = k as f64;
            (1700.0 * (0.37 * x).sin(), 1700.0 * (0.61 * x).cos())
        })
        .collect()
}

fn queries(c: &mut Criterion) {
    let t: Terrain = build(&default_synthetic(), &site()).expect("default synthetic builds");
    let pts = points();
    let mut k = 0usize;
    let mut next = move || {
        k = (k + 1) & 1023;
        pts[k]
    };
    c.bench_function("terrain/elevation_m", |b| {
        b.iter(|| {
            let (e, n) = next();
            black_box(t.elevation_m(black_box(e), black_box(n)))
        })
    });
    c.bench_function("terrain/normal_site", |b| {
        b.iter(|| {
            let (e, n) = next();
            black_box(t.normal_site(black_box(e), black_box(n)))
        })
    });
    c.bench_function("terrain/height_above_surface_m", |b| {
        b.iter(|| {
            let (e, n) = next();
            black_box(t.height_above_surface_m(black_box(&Vector3::new(e, n, 50.0))))
        })
    });
    for (name, alt_m, dir) in [
        (
            "ray_cast_vertical_2km",
            2000.0,
            Vector3::new(0.0, 0.0, -1.0),
        ),
        ("ray_cast_30deg_2km", 2000.0, Vector3::new(0.5, 0.0, -0.866)),
        (
            "ray_cast_80deg_100m",
            100.0,
            Vector3::new(0.985, 0.0, -0.174),
        ),
    ] {
        c.bench_function(&format!("terrain/{name}"), |b| {
            b.iter(|| {
                let (e, n) = next();
                let o = Vector3::new(0.3 * e, 0.3 * n, alt_m);
                black_box(t.ray_cast(black_box(&o), black_box(&dir), 10_000.0))
            })
        });
    }
}

fn build_cost(c: &mut Criterion) {
    let mut g = c.benchmark_group("terrain");
    g.sample_size(10);
    g.bench_function("build_default_synthetic", |b| {
        b.iter(|| black_box(build(black_box(&default_synthetic()), &site())))
    });
    g.finish();
}

criterion_group!(benches, queries, build_cost);
criterion_main!(benches);
