//! Orthographic rendering of the terrain with the camera's photometry and shadows: the
//! reflectance an onboard terrain map holds (`oils map`, `docs/gnc.md`,
//! "Terrain-relative navigation").
//!
//! A map cell at `(e, n)` gets the lunar-Lambert I/F ([`super::photometry`]) of the
//! surface there, seen from straight above, under the map's sun, black (the camera's
//! shadow floor) where the shadow map says a cast shadow falls or the surface faces away
//! from the sun: the same reflectance and the same shadows the camera renders, without
//! the optics and the detector. A cell is the mean of `k x k` samples across it (`k`
//! from the cell's size against the terrain's finest spacing, at most 4), as a camera
//! pixel integrates the ground it sees.

use super::photometry::iof_at;
use super::shadow::ShadowMap;
use crate::world::terrain::Terrain;
use nalgebra::Vector3;

/// One rendered level: `width x height` cells `spacing_m` apart from `(e0_m, n0_m)`
/// (column `j` at `e0 + j s`, row `i` at `n0 + i s`, row 0 the southernmost).
#[derive(Debug, Clone, PartialEq)]
pub struct OrthoLevel {
    /// Cell spacing, m.
    pub spacing_m: f64,
    /// Map east of column 0, m.
    pub e0_m: f64,
    /// Map north of row 0, m.
    pub n0_m: f64,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// I/F per cell.
    pub iof: Vec<f32>,
    /// Terrain elevation above the sphere per cell, m (at the cell's centre).
    pub height_m: Vec<f32>,
}

/// How the surface reflects (the camera's photometric settings).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reflectance {
    /// Normal albedo of the lunar-Lambert model.
    pub normal_albedo: f64,
    /// I/F where the sun does not reach.
    pub shadow_floor_iof: f64,
}

/// Renders a `cells x cells` level of `spacing_m` centred on the site over `terrain`
/// (`None`: the bare sphere, featureless), lit by the unit site-frame sun
/// `sun_dir_site`, shadows from `shadow`; `finest_m`: the terrain's finest spacing
/// (sets the samples per cell).
pub fn render_level(
    terrain: Option<&Terrain>,
    shadow: Option<&ShadowMap>,
    sun_dir_site: &Vector3<f64>,
    refl: Reflectance,
    spacing_m: f64,
    cells: u32,
    finest_m: f64,
) -> OrthoLevel {
    let n = cells as usize;
    let half = 0.5 * (cells as f64 - 1.0) * spacing_m;
    let (e0, n0) = (-half, -half);
    let k = ((spacing_m / finest_m.max(1e-3)).ceil() as usize).clamp(1, 4);
    let mut iof = vec![0.0f32; n * n];
    let mut height_m = vec![0.0f32; n * n];
    for i in 0..n {
        for j in 0..n {
            let (ec, nc) = (e0 + j as f64 * spacing_m, n0 + i as f64 * spacing_m);
            let mut sum = 0.0;
            for a in 0..k {
                for b in 0..k {
                    let e = ec + ((b as f64 + 0.5) / k as f64 - 0.5) * spacing_m;
                    let nn = nc + ((a as f64 + 0.5) / k as f64 - 0.5) * spacing_m;
                    sum += sample_iof(terrain, shadow, sun_dir_site, refl, e, nn);
                }
            }
            iof[i * n + j] = (sum / (k * k) as f64) as f32;
            height_m[i * n + j] = terrain.map_or(0.0, |t| t.elevation_m(ec, nc)) as f32;
        }
    }
    OrthoLevel {
        spacing_m,
        e0_m: e0,
        n0_m: n0,
        width: cells,
        height: cells,
        iof,
        height_m,
    }
}

/// The I/F at map `(e, n)` seen from straight above.
fn sample_iof(
    terrain: Option<&Terrain>,
    shadow: Option<&ShadowMap>,
    sun: &Vector3<f64>,
    refl: Reflectance,
    e_m: f64,
    n_m: f64,
) -> f64 {
    let Some(t) = terrain else {
        // The sphere: its normal is local up, seen from straight above.
        let up = Vector3::z();
        return iof_at(refl.normal_albedo, &up, &-up, sun).max(refl.shadow_floor_iof);
    };
    let normal = t.normal_site(e_m, n_m);
    let up = t.map().up(e_m, n_m);
    if normal.dot(sun) <= 0.0 {
        return refl.shadow_floor_iof;
    }
    if let Some(map) = shadow {
        let p = t.surface_point_site(e_m, n_m);
        if map.margin_m(e_m, n_m, &p).is_some_and(|m| m < 0.0) {
            return refl.shadow_floor_iof;
        }
    }
    iof_at(refl.normal_albedo, &normal, &-up, sun).max(refl.shadow_floor_iof)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bare_sphere_is_one_lambert_grey() {
        let sun = Vector3::new(0.0, 0.6, 0.8);
        let refl = Reflectance {
            normal_albedo: 0.12,
            shadow_floor_iof: 0.0,
        };
        let l = render_level(None, None, &sun, refl, 4.0, 8, 4.0);
        // mu0 = 0.8, mu = 1, phase = acos(0.8): the closed form, every cell.
        let want =
            super::super::photometry::lunar_lambert_iof(0.12, 0.8, 1.0, 0.8f64.acos().to_degrees());
        assert!(
            l.iof.iter().all(|&v| (v as f64 - want).abs() < 1e-6),
            "{:?}",
            &l.iof[..4]
        );
        assert_eq!((l.e0_m, l.n0_m), (-14.0, -14.0));
    }
}
