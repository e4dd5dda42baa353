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
        if *spec == TerrainSpec::Smooth {
            return Ok(Ground::Sphere { radius_m });
        }
        let site = SiteFrame::from_deg(latitude_deg, longitude_deg, radius_m);
        let terrain = cache().get_or_build(spec, &site)?;
        let max_elevation_m = terrain
            .grid()
            .map_or(0.0, |g| g.elevation_range_m().1.max(0.0));
        Ok(Ground::Terrain {
            terrain,
            site,
            max_elevation_m,
        })
    }
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
