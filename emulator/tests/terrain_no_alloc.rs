//! The terrain's queries (elevation, normal, slope, height above ground, ray cast) run
//! in the plant's and the sensors' steps: none may touch the heap. A counting global
//! allocator in its own test binary proves it.

use nalgebra::Vector3;
use oils_emulator::world::terrain::{build, DetailSpec, SiteFrame, SyntheticSpec, TerrainSpec};

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn terrain_queries_do_not_allocate() {
    let site = SiteFrame::from_deg(-69.373, 32.319, 1_737_400.0);
    let rough = TerrainSpec::Synthetic(SyntheticSpec {
        extent_m: 1000.0,
        spacing_m: 2.0,
        crater_min_diameter_m: 8.0,
        regional_slope_deg: 3.0,
        ..SyntheticSpec::default()
    });
    let detailed = TerrainSpec::Synthetic(SyntheticSpec {
        extent_m: 1000.0,
        spacing_m: 2.0,
        crater_min_diameter_m: 8.0,
        detail: Some(DetailSpec {
            extent_m: 400.0,
            ..DetailSpec::default()
        }),
        ..SyntheticSpec::default()
    });
    let terrains = [
        build(&TerrainSpec::default(), &site).unwrap(),
        build(&rough, &site).unwrap(),
        build(&detailed, &site).unwrap(),
    ];
    let before = common::allocations();
    let mut acc = 0.0;
    for t in &terrains {
        for k in 0..2000 {
            let e = -600.0 + 0.61 * k as f64;
            let n = 400.0 - 0.37 * k as f64;
            acc += t.elevation_m(e, n) + t.slope_deg(e, n) + t.normal_site(e, n).z;
            let p = Vector3::new(e, n, 20.0);
            acc += t.height_above_surface_m(&p);
            let d = Vector3::new((k as f64).cos(), (k as f64).sin(), -0.3);
            if let Some(hit) = t.ray_cast(&p, &d, 500.0) {
                acc += hit.range_m + hit.incidence_deg;
            }
        }
    }
    let after = common::allocations();
    std::hint::black_box(acc);
    assert_eq!(
        after - before,
        0,
        "terrain queries allocated {} times",
        after - before
    );
}
