//! The ground the footpads meet, as the plant sees it: height of a Moon-fixed point
//! above the surface and the surface normal there.
//!
//! The reference sphere (`moon.radius_m`), or the sphere plus the terrain elevation
//! about the site (`[terrain]`, [`crate::world::terrain`]) through the same queries, so
//! the contact and touchdown code does not change with the ground.

use crate::world::terrain::{SiteFrame, Terrain, TerrainCache, TerrainError, TerrainSpec};
use nalgebra::Vector3;
use std::sync::{Arc, OnceLock};

/// Terrains built in this process, shared by every plant (a campaign's cases build
/// their common terrain once). Locked only when a plant is built, never per step.
fn cache() -> &'static TerrainCache {
    static CACHE: OnceLock<TerrainCache> = OnceLock::new();
    CACHE.get_or_init(TerrainCache::new)
}

/// The surface of the Moon, Moon-fixed.
#[derive(Debug, Clone)]
pub enum Ground {
    /// The reference sphere.
    Sphere {
        /// Radius, metres.
        radius_m: f64,
    },
    /// The sphere plus a terrain elevation about a site.
    Terrain {
        /// The terrain (shared).
        terrain: Arc<Terrain>,
        /// Its site frame.
        site: SiteFrame,
        /// Highest elevation above the sphere, metres.
        max_elevation_m: f64,
    },
}

impl Ground {
    /// The ground of `spec` about the site at `latitude_deg`, `longitude_deg` on a
    /// sphere of `radius_m` (the bare sphere for `smooth`).
    pub fn new(
        spec: &TerrainSpec,
        latitude_deg: f64,
        longitude_deg: f64,
        radius_m: f64,
    ) -> Result<Self, TerrainError> {
        if spec.is_bare_sphere() {
            return Ok(Ground::Sphere { radius_m });
        }
        let site = SiteFrame::from_deg(latitude_deg, longitude_deg, radius_m);
        let terrain = cache().get_or_build(spec, &site)?;
        let max_elevation_m = terrain.max_elevation_m().max(0.0);
        Ok(Ground::Terrain {
            terrain,
            site,
            max_elevation_m,
        })
    }

    /// The ground of an already built `terrain` about `site` (tests and tools that
    /// shape their own surface; the plant builds through [`Ground::new`]).
    pub fn from_terrain(terrain: Arc<Terrain>, site: SiteFrame) -> Self {
        let max_elevation_m = terrain.max_elevation_m().max(0.0);
        Ground::Terrain {
            terrain,
            site,
            max_elevation_m,
        }
    }
}

/// Where a ray meets the ground, Moon-fixed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundHit {
    /// Distance from the ray's origin along its unit direction, m.
    pub range_m: f64,
    /// The hit point, `mcmf`, m.
    pub point_mcmf: Vector3<f64>,
    /// Unit outward surface normal at the hit, `mcmf`.
    pub normal_mcmf: Vector3<f64>,
    /// Angle between the reversed ray and the normal, degrees (0: head-on).
    pub incidence_deg: f64,
}

impl Ground {
    /// Height of `p_mcmf` above the surface along the local radial, metres (negative
    /// below it).
    pub fn height_m(&self, p_mcmf: &Vector3<f64>) -> f64 {
        match self {
            Ground::Sphere { radius_m } => p_mcmf.norm() - radius_m,
            Ground::Terrain { terrain, site, .. } => {
                terrain.height_above_surface_m(&site.site_from_mcmf(p_mcmf))
            }
        }
    }

    /// Outward unit normal of the surface below `p_mcmf`, `mcmf`.
    pub fn normal_mcmf(&self, p_mcmf: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Ground::Sphere { .. } => p_mcmf.normalize(),
            Ground::Terrain { terrain, site, .. } => {
                let (e, n) = terrain.map_of_site(&site.site_from_mcmf(p_mcmf));
                site.mcmf_dir_from_site(&terrain.normal_site(e, n))
            }
        }
    }

    /// The first point where the ray `origin + t dir` (t in `[0, max_range_m]`, `mcmf`)
    /// meets the ground: an exact ray-sphere intersection on the reference sphere, the
    /// terrain's ray march ([`Terrain::ray_cast`], in the site frame) otherwise. `dir`
    /// need not be unit length. `None` if it misses within range or an input is not
    /// finite; an origin at or below the ground hits at range 0. No allocation.
    pub fn ray_cast_mcmf(
        &self,
        origin_mcmf: &Vector3<f64>,
        dir_mcmf: &Vector3<f64>,
        max_range_m: f64,
    ) -> Option<GroundHit> {
        match self {
            Ground::Sphere { radius_m } => {
                sphere_ray_cast(origin_mcmf, dir_mcmf, max_range_m, *radius_m)
            }
            Ground::Terrain { terrain, site, .. } => {
                let o = site.site_from_mcmf(origin_mcmf);
                let d = site.site_dir_from_mcmf(dir_mcmf);
                let hit = terrain.ray_cast(&o, &d, max_range_m)?;
                Some(GroundHit {
                    range_m: hit.range_m,
                    point_mcmf: site.mcmf_from_site(&hit.point_site),
                    normal_mcmf: site.mcmf_dir_from_site(&hit.normal_site),
                    incidence_deg: hit.incidence_deg,
                })
            }
        }
    }

    /// Highest the surface rises above the reference sphere anywhere, metres: above
    /// this plus the legs' reach no footpad can touch, so contact is not searched.
    pub fn max_elevation_m(&self) -> f64 {
        match self {
            Ground::Sphere { .. } => 0.0,
            Ground::Terrain {
                max_elevation_m, ..
            } => *max_elevation_m,
        }
    }
}

/// Exact first intersection of a ray with the sphere `|p| = radius_m` about the origin.
fn sphere_ray_cast(
    o: &Vector3<f64>,
    dir: &Vector3<f64>,
    max_range_m: f64,
    radius_m: f64,
) -> Option<GroundHit> {
    let norm = dir.norm();
    let finite = o.iter().all(|x| x.is_finite()) && norm.is_finite();
    if !finite || norm == 0.0 || max_range_m.is_nan() || max_range_m < 0.0 {
        return None;
    }
    let d = dir / norm;
    // |o + t d|^2 = R^2  <=>  t^2 + 2 b t + c = 0.
    let b = o.dot(&d);
    let c = (o.norm() - radius_m) * (o.norm() + radius_m);
    let t = if c <= 0.0 {
        0.0
    } else {
        let disc = b * b - c;
        if b >= 0.0 || disc < 0.0 {
            return None;
        }
        // The nearer root, in the cancellation-free form c / (-b + sqrt(disc)).
        c / (-b + disc.sqrt())
    };
    if t > max_range_m {
        return None;
    }
    let p = o + d * t;
    let n = p.normalize();
    Some(GroundHit {
        range_m: t,
        point_mcmf: p,
        normal_mcmf: n,
        incidence_deg: (-d.dot(&n)).clamp(-1.0, 1.0).acos().to_degrees(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_ray_cast_has_the_closed_form_range() {
        let g = Ground::Sphere { radius_m: 1000.0 };
        let o = Vector3::new(0.0, 0.0, 1100.0);
        let hit = g.ray_cast_mcmf(&o, &-Vector3::z(), 1e4).unwrap();
        assert!((hit.range_m - 100.0).abs() < 1e-9);
        assert!(hit.incidence_deg.abs() < 1e-6);
        // Tilted by 20 degrees: the law of cosines.
        let th = 20f64.to_radians();
        let d = Vector3::new(th.sin(), 0.0, -th.cos());
        let hit = g.ray_cast_mcmf(&o, &d, 1e4).unwrap();
        let want = 1100.0 * th.cos() - (1000.0f64.powi(2) - (1100.0 * th.sin()).powi(2)).sqrt();
        assert!(
            (hit.range_m - want).abs() < 1e-9,
            "{} vs {want}",
            hit.range_m
        );
        assert!(((hit.point_mcmf.norm()) - 1000.0).abs() < 1e-9);
        assert!(g.ray_cast_mcmf(&o, &Vector3::z(), 1e4).is_none(), "upward");
        assert!(g.ray_cast_mcmf(&o, &Vector3::x(), 1e4).is_none(), "misses");
        assert!(g.ray_cast_mcmf(&o, &-Vector3::z(), 99.0).is_none(), "short");
        let inside = g
            .ray_cast_mcmf(&Vector3::new(0.0, 0.0, 900.0), &Vector3::x(), 10.0)
            .unwrap();
        assert_eq!(inside.range_m, 0.0);
    }
}
