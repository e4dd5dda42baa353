//! Building a terrain from its spec, once per campaign: a cache keyed by the spec's
//! hash and the site, handing out `Arc<Terrain>` to every case that asks.

use super::detail::{self, BaseLimits};
use super::frame::SiteFrame;
use super::spec::TerrainSpec;
use super::surface::Terrain;
use super::{geotiff, synthetic, TerrainError};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Builds the terrain of `spec` about `site` (validating both first).
pub fn build(spec: &TerrainSpec, site: &SiteFrame) -> Result<Terrain, TerrainError> {
    spec.validate()?;
    let finite = site.lat_rad.is_finite() && site.lon_rad.is_finite();
    if !finite || site.lat_rad.abs() > std::f64::consts::FRAC_PI_2 {
        return Err(TerrainError::InvalidSite(format!(
            "latitude {} rad / longitude {} rad",
            site.lat_rad, site.lon_rad
        )));
    }
    if !(site.radius_m.is_finite() && site.radius_m > 0.0) {
        return Err(TerrainError::InvalidSite(format!(
            "radius_m must be positive and finite, got {}",
            site.radius_m
        )));
    }
    let grid = match spec {
        TerrainSpec::Smooth(_) => None,
        TerrainSpec::Synthetic(s) => Some(synthetic::build_grid(s)?),
        TerrainSpec::Geotiff(g) => Some(geotiff::build_grid(g, site)?),
    };
    let tile = match spec.detail() {
        None => None,
        Some(d) => {
            let limits = match (spec, &grid) {
                (TerrainSpec::Synthetic(s), _) => BaseLimits::synthetic(s),
                (TerrainSpec::Geotiff(_), Some(g)) => {
                    BaseLimits::dem(g.spacing_m(), d.base_resolution_pixels)
                }
                _ => BaseLimits::NONE,
            };
            Some(detail::build_tile(d, grid.as_ref(), &limits)?)
        }
    };
    Terrain::with_detail(grid, tile, site.radius_m).ok_or(TerrainError::NonFinite)
}

/// Key of a built terrain: the spec's hash and the site's numbers, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TerrainKey {
    /// [`TerrainSpec::spec_hash`].
    pub spec_hash: u64,
    /// Site latitude, longitude and radius as raw bits.
    pub site_bits: [u64; 3],
}

impl TerrainKey {
    /// The key of `spec` about `site`.
    pub fn new(spec: &TerrainSpec, site: &SiteFrame) -> Self {
        Self {
            spec_hash: spec.spec_hash(),
            site_bits: [
                site.lat_rad.to_bits(),
                site.lon_rad.to_bits(),
                site.radius_m.to_bits(),
            ],
        }
    }
}

/// Built terrains shared across the cases of a campaign (thread-safe). A build holds
/// the lock, so concurrent cases asking for the same terrain build it once.
#[derive(Debug, Default)]
pub struct TerrainCache {
    built: Mutex<HashMap<TerrainKey, Arc<Terrain>>>,
}

impl TerrainCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// The terrain of `spec` about `site`, built on first request.
    pub fn get_or_build(
        &self,
        spec: &TerrainSpec,
        site: &SiteFrame,
    ) -> Result<Arc<Terrain>, TerrainError> {
        let key = TerrainKey::new(spec, site);
        let mut map = self.built.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(t) = map.get(&key) {
            return Ok(Arc::clone(t));
        }
        let t = Arc::new(build(spec, site)?);
        map.insert(key, Arc::clone(&t));
        Ok(t)
    }

    /// How many distinct terrains have been built.
    pub fn len(&self) -> usize {
        self.built.lock().unwrap_or_else(|p| p.into_inner()).len()
    }

    /// True if nothing has been built yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
