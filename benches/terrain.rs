//! Cost of the terrain queries per call (elevation, normal, height above ground, ray
//! casts) on the default synthetic surface about the Chandrayaan-3 site, the cost of
//! building that surface once, and ray-cast throughput (rays per second) on the default
//! surface and on a 8192 x 8192-node DEM (67 million nodes at 1 m: 0.5 GB of heights and
//! 0.7 GB of pyramid; a gigapixel DEM would take 20 GB of this 24 GB machine, which its
//! other work shares).
//!
//! The detail layer (`terrain_detail/*`): building the default base with the default
//! 1 km tile at 0.5 m, and ray throughput inside the tile and for a 128 x 128 flash lidar.
//!
//! `cargo bench --bench terrain -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::Vector3;
use oils_emulator::world::terrain::{
    build, DetailSpec, Grid, SiteFrame, SyntheticSpec, Terrain, TerrainSpec,
};
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

/// A batch of rays as an altimeter, a velocimeter or a lidar casts them: origins 20 m to
/// 5 km above the ground, directions up to 40 deg off nadir.
fn ray_batch(t: &Terrain, half_m: f64) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    (0..4096)
        .map(|k| {
            let x = k as f64;
            let (e, n) = (half_m * (0.37 * x).sin(), half_m * (0.61 * x).cos());
            let up = 20.0 + 5000.0 * (0.5 + 0.5 * (1.3 * x).sin()).powi(3);
            let o = t.map().site_of_map(e, n, t.elevation_m(e, n) + up);
            let (off, az) = (40f64.to_radians() * (0.5 + 0.5 * (2.1 * x).sin()), 0.9 * x);
            let d = Vector3::new(off.sin() * az.cos(), off.sin() * az.sin(), -off.cos());
            (o, d)
        })
        .collect()
}

fn throughput(c: &mut Criterion) {
    let default = build(&default_synthetic(), &site()).expect("default synthetic builds");
    // Rolling ground with craters-like bowls every 200 m, 1 m spacing.
    let side = 8192usize;
    let half = (side / 2) as f64;
    let h = (0..side * side)
        .map(|k| {
            let (e, n) = ((k % side) as f64 - half, (k / side) as f64 - half);
            let bowl = (0.0314 * e).cos() * (0.0314 * n).cos();
            40.0 * (0.0021 * e).sin() * (0.0017 * n).cos() + 6.0 * bowl * bowl.abs()
        })
        .collect();
    let grid = Grid::new(side, side, -half, -half, 1.0, h).expect("large grid");
    let large = Terrain::new(Some(grid), site().radius_m).expect("large terrain");
    let mut g = c.benchmark_group("terrain_rays");
    for (name, t, half_m) in [
        ("default_dem", &default, 1700.0),
        ("8k_dem", &large, 3500.0),
    ] {
        let rays = ray_batch(t, half_m);
        g.throughput(Throughput::Elements(rays.len() as u64));
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut hits = 0usize;
                for (o, d) in &rays {
                    hits += t.ray_cast(black_box(o), black_box(d), 20_000.0).is_some() as usize;
                }
                black_box(hits)
            })
        });
    }
    g.finish();
}

/// The default synthetic base with the default detail layer (1 km at 0.5 m about the
/// site): what `pinpoint` flies over.
fn detailed_synthetic() -> TerrainSpec {
    TerrainSpec::Synthetic(SyntheticSpec {
        detail: Some(DetailSpec::default()),
        ..SyntheticSpec::default()
    })
}

/// A flash lidar's rays from `alt_m` above the site: 128 x 128 over a 20 deg field about
/// nadir.
fn lidar_rays(t: &Terrain, alt_m: f64) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let o = t
        .map()
        .site_of_map(0.0, 0.0, t.elevation_m(0.0, 0.0) + alt_m);
    let half = 10f64.to_radians().tan();
    (0..128 * 128)
        .map(|k| {
            let (i, j) = ((k % 128) as f64, (k / 128) as f64);
            let (x, y) = (
                half * (2.0 * i / 127.0 - 1.0),
                half * (2.0 * j / 127.0 - 1.0),
            );
            (o, Vector3::new(x, y, -1.0))
        })
        .collect()
}

fn detail(c: &mut Criterion) {
    let mut g = c.benchmark_group("terrain_detail");
    g.sample_size(10);
    g.bench_function("build_default_synthetic_with_detail", |b| {
        b.iter(|| black_box(build(black_box(&detailed_synthetic()), &site())))
    });
    let t = build(&detailed_synthetic(), &site()).expect("detailed synthetic builds");
    let batches = [
        ("rays_in_tile", ray_batch(&t, 450.0)),
        ("lidar_128x128_from_100m", lidar_rays(&t, 100.0)),
        ("lidar_128x128_from_1km", lidar_rays(&t, 1000.0)),
    ];
    for (name, rays) in &batches {
        g.throughput(Throughput::Elements(rays.len() as u64));
        g.bench_function(*name, |b| {
            b.iter(|| {
                let mut hits = 0usize;
                for (o, d) in rays {
                    hits += t.ray_cast(black_box(o), black_box(d), 20_000.0).is_some() as usize;
                }
                black_box(hits)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, queries, build_cost, detail, throughput);
criterion_main!(benches);
