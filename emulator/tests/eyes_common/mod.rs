//! Grounds and poses shared by the camera and lidar tests.
#![allow(dead_code)]

use nalgebra::Vector3;
use oils_emulator::plant::ground::Ground;
use oils_emulator::world::terrain::{Grid, SiteFrame, Terrain};
use std::sync::Arc;

pub const R_M: f64 = 1_737_400.0;

pub fn site() -> SiteFrame {
    SiteFrame::from_deg(-69.373, 32.319, R_M)
}

/// A flat world (`z = h(x, y)` in the site frame) from `h` on a square grid of
/// `extent_m` at `spacing_m` centred on the site.
pub fn flat_world(extent_m: f64, spacing_m: f64, h: impl Fn(f64, f64) -> f64) -> Ground {
    let n = (extent_m / spacing_m).round() as usize + 1;
    let e0 = -0.5 * extent_m;
    let mut v = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            v.push(h(e0 + spacing_m * i as f64, e0 + spacing_m * j as f64));
        }
    }
    let grid = Grid::new(n, n, e0, e0, spacing_m, v).unwrap();
    let terrain = Terrain::new(Some(grid), f64::INFINITY).unwrap();
    Ground::from_terrain(Arc::new(terrain), site())
}

/// The plane `z = 0` with no grid.
pub fn plane() -> Ground {
    Ground::from_terrain(Arc::new(Terrain::smooth(f64::INFINITY).unwrap()), site())
}

/// Site-frame direction towards the sun at `elevation_deg`, `azimuth_deg` (clockwise
/// from north), in `mcmf`.
pub fn sun_mcmf(elevation_deg: f64, azimuth_deg: f64) -> Vector3<f64> {
    let (el, az) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    let s = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
    site().mcmf_dir_from_site(&s)
}
