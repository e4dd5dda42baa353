//! Cast shadows precomputed for one sun direction: the sun barely moves during a
//! descent (0.5 deg an hour at the Moon), so what depends on the sun alone is built once
//! per (terrain, sun) and shared read-only by every run of a campaign (`Arc`).
//!
//! A horizon sweep. Let `s` be the unit sun direction and `m` the unit vector
//! perpendicular to `s` in the vertical plane that holds it (site frame). Every point
//! of the ray from `p` towards the sun has the same `w = p . m`; a surface point `q`
//! sunward of `p` along the sun's azimuth blocks the ray exactly when `w(q) > w(p)`.
//! So on a lattice whose rows run along the sun's azimuth, one pass per row from the
//! sunward end with a running maximum gives each node its horizon
//! `H = max { w(q) : q sunward of the node on its row }`, and a point is in a cast
//! shadow when its margin `w(p) - H(p)` (with `H` bilinear between nodes) is negative.
//! The lattice holds the planet's curvature through `w` (3D site-frame points).
//!
//! Levels of `nodes x nodes` nodes about the site at several spacings (fine near the
//! site, coarse far out); each level starts its rows from the next coarser level's
//! horizon two coarse spacings beyond its sunward edge, with its own samples in
//! between, so shadows cast from outside a level are kept. The sun is a point: no
//! penumbra (the sun's 0.53 deg disk would blur a shadow edge by 1 % of its length).

use crate::plant::ground::Ground;
use crate::world::terrain::Terrain;
use nalgebra::Vector3;
use std::sync::Arc;

/// What the shadow map covers and how finely.
#[derive(Debug, Clone, PartialEq)]
pub struct ShadowMapConfig {
    /// Lattice spacings, m, finest first (each level `nodes` nodes a side about the site).
    pub spacings_m: Vec<f64>,
    /// Nodes per side of each level.
    pub nodes: usize,
}

impl Default for ShadowMapConfig {
    /// 1024^2 nodes at 0.125, 0.5, 2, 8 and 32 m: 128 m to 32 km about the site, 20 MB.
    fn default() -> Self {
        Self {
            spacings_m: vec![0.125, 0.5, 2.0, 8.0, 32.0],
            nodes: 1024,
        }
    }
}

/// Why a shadow map was not built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ShadowMapError {
    /// The sun direction is zero or not finite.
    #[error("sun direction must be a finite non-zero vector")]
    BadSun,
    /// A spacing is not positive and finite, or the spacings do not grow.
    #[error("shadow-map spacings must be positive, finite and increasing")]
    BadSpacing,
    /// Fewer than 4 or more than 8192 nodes a side.
    #[error("shadow-map nodes per side must be 4 to 8192")]
    BadNodes,
}

#[derive(Debug, Clone)]
struct Level {
    spacing_m: f64,
    /// Horizon `H` per node, row-major: row `j` across the sun, node `i` towards it.
    horizon: Vec<f32>,
}

/// Horizons for one sun over one terrain.
#[derive(Debug, Clone)]
pub struct ShadowMap {
    terrain: Option<Arc<Terrain>>,
    sun_dir_mcmf: Vector3<f64>,
    sun_dir_site: Vector3<f64>,
    /// Unit sun azimuth in map (e, n) and its left perpendicular.
    along: [f64; 2],
    across: [f64; 2],
    /// `m`, site frame.
    m_site: Vector3<f64>,
    nodes: usize,
    /// Finest first.
    levels: Vec<Level>,
}

/// "No horizon": below any surface.
const NO_HORIZON: f32 = -1.0e30;

/// Shadow maps at most kept by [`ShadowMap::shared`] (20 MB each at the default size).
const SHARED_MAPS: usize = 4;

/// What a shared map was built for: the terrain (by identity), the site, the sun and the
/// lattice, bit for bit.
struct SharedKey {
    terrain: Option<Arc<Terrain>>,
    site_bits: [u64; 3],
    sun_bits: [u64; 3],
    cfg: ShadowMapConfig,
}

impl SharedKey {
    fn new(ground: &Ground, sun_dir_mcmf: &Vector3<f64>, cfg: &ShadowMapConfig) -> Self {
        let (terrain, site_bits) = match ground {
            Ground::Sphere { radius_m } => (None, [radius_m.to_bits(), 0, 0]),
            Ground::Terrain { terrain, site, .. } => (
                Some(terrain.clone()),
                [
                    site.lat_rad.to_bits(),
                    site.lon_rad.to_bits(),
                    site.radius_m.to_bits(),
                ],
            ),
        };
        Self {
            terrain,
            site_bits,
            sun_bits: [sun_dir_mcmf.x, sun_dir_mcmf.y, sun_dir_mcmf.z].map(f64::to_bits),
            cfg: cfg.clone(),
        }
    }

    fn same(&self, other: &Self) -> bool {
        let terrain = match (&self.terrain, &other.terrain) {
            (None, None) => true,
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            _ => false,
        };
        terrain
            && self.site_bits == other.site_bits
            && self.sun_bits == other.sun_bits
            && self.cfg == other.cfg
    }
}

impl ShadowMap {
    /// [`ShadowMap::build`], once per process for the same terrain (the one instance the
    /// terrain cache hands every case), site, sun and lattice: a campaign's cases share
    /// one map (0.5 s and 20 MB at the default size) instead of building their own.
    /// Keeps the last few maps built; locked only here, before tick 0.
    pub fn shared(
        ground: &Ground,
        sun_dir_mcmf: &Vector3<f64>,
        cfg: &ShadowMapConfig,
    ) -> Result<Arc<Self>, ShadowMapError> {
        static MAPS: std::sync::Mutex<Vec<(SharedKey, Arc<ShadowMap>)>> =
            std::sync::Mutex::new(Vec::new());
        let key = SharedKey::new(ground, sun_dir_mcmf, cfg);
        // A poisoned lock only means another case panicked while building: the list
        // itself is always whole.
        let mut maps = MAPS.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, map)) = maps.iter().find(|(k, _)| k.same(&key)) {
            return Ok(map.clone());
        }
        let map = Arc::new(Self::build(ground, sun_dir_mcmf, cfg)?);
        if maps.len() >= SHARED_MAPS {
            maps.remove(0);
        }
        maps.push((key, map.clone()));
        Ok(map)
    }

    /// The horizons of `ground` under the sun in unit direction `sun_dir_mcmf`. On the
    /// bare sphere there are no cast shadows (a point facing the sun sees it) and the map
    /// is empty. Allocates its levels; run it before tick 0.
    pub fn build(
        ground: &Ground,
        sun_dir_mcmf: &Vector3<f64>,
        cfg: &ShadowMapConfig,
    ) -> Result<Self, ShadowMapError> {
        let norm = sun_dir_mcmf.norm();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(ShadowMapError::BadSun);
        }
        if cfg.nodes < 4 || cfg.nodes > 8192 {
            return Err(ShadowMapError::BadNodes);
        }
        let ok = cfg.spacings_m.iter().all(|s| s.is_finite() && *s > 0.0)
            && cfg.spacings_m.windows(2).all(|w| w[1] > w[0]);
        if !ok {
            return Err(ShadowMapError::BadSpacing);
        }
        let sun_mcmf = sun_dir_mcmf / norm;
        let (terrain, site) = match ground {
            Ground::Sphere { .. } => {
                return Ok(Self {
                    terrain: None,
                    sun_dir_mcmf: sun_mcmf,
                    sun_dir_site: sun_mcmf,
                    along: [1.0, 0.0],
                    across: [0.0, 1.0],
                    m_site: Vector3::z(),
                    nodes: cfg.nodes,
                    levels: Vec::new(),
                })
            }
            Ground::Terrain { terrain, site, .. } => (terrain, site),
        };
        let s = site.site_dir_from_mcmf(&sun_mcmf);
        let hor = s.x.hypot(s.y);
        let mut map = Self {
            terrain: Some(terrain.clone()),
            sun_dir_mcmf: sun_mcmf,
            sun_dir_site: s,
            along: [1.0, 0.0],
            across: [0.0, 1.0],
            m_site: Vector3::z(),
            nodes: cfg.nodes,
            levels: Vec::new(),
        };
        if hor < 1e-9 {
            // The sun at the zenith: a heightfield casts no shadow.
            return Ok(map);
        }
        map.along = [s.x / hor, s.y / hor];
        map.across = [-map.along[1], map.along[0]];
        let z = Vector3::z();
        map.m_site = (z - s * z.dot(&s)).normalize();
        // Coarsest first, so each level starts from the one outside it.
        let mut built: Vec<Level> = Vec::with_capacity(cfg.spacings_m.len());
        for &spacing in cfg.spacings_m.iter().rev() {
            let outer = built.last();
            let level = map.sweep(terrain, spacing, outer);
            built.push(level);
        }
        built.reverse();
        map.levels = built;
        Ok(map)
    }

    fn node_map(&self, spacing: f64, i: f64, j: f64) -> (f64, f64) {
        let half = 0.5 * (self.nodes - 1) as f64;
        let (a, b) = ((i - half) * spacing, (j - half) * spacing);
        (
            a * self.along[0] + b * self.across[0],
            a * self.along[1] + b * self.across[1],
        )
    }

    fn w(&self, terrain: &Terrain, e: f64, n: f64) -> f64 {
        let h = terrain.elevation_m(e, n);
        terrain.map().site_of_map(e, n, h).dot(&self.m_site)
    }

    fn sweep(&self, terrain: &Terrain, spacing: f64, outer: Option<&Level>) -> Level {
        let n = self.nodes;
        let mut horizon = vec![NO_HORIZON; n * n];
        let extra = outer.map_or(0, |o| (2.0 * o.spacing_m / spacing).ceil() as usize);
        for j in 0..n {
            let far = (n + extra) as f64;
            let mut run = match outer {
                Some(o) => {
                    let (e, nn) = self.node_map(spacing, far, j as f64);
                    self.level_horizon(o, e, nn).unwrap_or(NO_HORIZON as f64)
                }
                None => NO_HORIZON as f64,
            };
            for i in (0..n + extra).rev() {
                let (e, nn) = self.node_map(spacing, i as f64, j as f64);
                let w = self.w(terrain, e, nn);
                if i < n {
                    horizon[j * n + i] = run as f32;
                }
                run = run.max(w);
            }
        }
        Level {
            spacing_m: spacing,
            horizon,
        }
    }

    /// Bilinear horizon of `level` at map `(e, n)`; `None` outside it.
    fn level_horizon(&self, level: &Level, e: f64, n: f64) -> Option<f64> {
        let half = 0.5 * (self.nodes - 1) as f64;
        let a = (e * self.along[0] + n * self.along[1]) / level.spacing_m + half;
        let b = (e * self.across[0] + n * self.across[1]) / level.spacing_m + half;
        let last = (self.nodes - 1) as f64;
        if !(a >= 0.0 && b >= 0.0 && a < last && b < last) {
            return None;
        }
        let (i, j) = (a as usize, b as usize);
        let (fa, fb) = (a - i as f64, b - j as f64);
        let k = j * self.nodes + i;
        let h = &level.horizon;
        let h00 = h[k] as f64;
        let h10 = h[k + 1] as f64;
        let h01 = h[k + self.nodes] as f64;
        let h11 = h[k + self.nodes + 1] as f64;
        Some((h00 * (1.0 - fa) + h10 * fa) * (1.0 - fb) + (h01 * (1.0 - fa) + h11 * fa) * fb)
    }

    /// The shadow margin of the surface point `p_site` at map `(e, n)`, m: negative in
    /// a cast shadow, positive lit (as far as the terrain goes; the caller checks that
    /// the point faces the sun). `Some(+inf)` where nothing can cast a shadow (the
    /// sphere, the sun at the zenith); `None` outside every level.
    #[inline]
    pub fn margin_m(&self, e_m: f64, n_m: f64, p_site: &Vector3<f64>) -> Option<f64> {
        if self.levels.is_empty() {
            return Some(f64::INFINITY);
        }
        let w = p_site.dot(&self.m_site);
        self.levels
            .iter()
            .find_map(|l| self.level_horizon(l, e_m, n_m))
            .map(|h| w - h)
    }

    /// The sun this map was built for, unit, `mcmf`.
    pub fn sun_dir_mcmf(&self) -> &Vector3<f64> {
        &self.sun_dir_mcmf
    }

    /// The sun in the site frame.
    pub fn sun_dir_site(&self) -> &Vector3<f64> {
        &self.sun_dir_site
    }

    /// Whether this map was built over `ground` (the same shared terrain, or both the
    /// sphere).
    pub fn is_for(&self, ground: &Ground) -> bool {
        match (ground, &self.terrain) {
            (Ground::Sphere { .. }, None) => true,
            (Ground::Terrain { terrain, .. }, Some(t)) => Arc::ptr_eq(terrain, t),
            _ => false,
        }
    }

    /// Memory held by the levels, bytes.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.horizon.len() * 4).sum()
    }
}
