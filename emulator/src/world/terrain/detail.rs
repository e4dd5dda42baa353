//! The detail layer: what lies below the base DEM's resolution near the site, down to
//! sub-metre node spacing over a tile of about a kilometre (`docs/terrain.md`).
//!
//! Contents, each from a ChaCha8 stream of its own seeded from [`DetailSpec::seed`]:
//! - small craters from a cumulative power law `N(>D) = c D^-b` per m^2 (`c` as a multiple
//!   of the Gault 1970 equilibrium; `b` = 2 in steady state, ~2.8 for a production
//!   population: Moore, Boyce & Hahn 1980), each either fresh (the bowl, rim and ejecta of
//!   [`super::synthetic::crater_profile_m`]) or degraded by topographic diffusion
//!   `dh/dt = kappa lap(h)` (Soderblom 1970; Fassett & Thomson 2014) to a state
//!   `tau = kappa t / D^2` drawn uniformly in `(0, max_degradation]`;
//! - boulders from the Golombek & Rapp (1997) rock-abundance model, as half-ellipsoid caps.
//!
//! Only features below the base's resolution are drawn (a synthetic base's smallest
//! crater and boulder; a GeoTIFF base's `base_resolution_pixels` pixels), so a real DTM
//! keeps what it resolves. The layer is tapered to zero across `taper_m` at the tile's
//! edge, and the tile stores the *total* height `base + detail` at its nodes: its nodes
//! include every base node in the tile (spacing a whole fraction of the base's), so the
//! tile's bilinear surface is the base's bilinear surface plus the bilinear detail, and it
//! meets the base exactly at the tile's edge.

use super::grid::Grid;
use super::spec::{in_range, positive};
use super::synthetic::{self, EQUILIBRIUM_C_PER_M2};
use super::TerrainError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use serde::{Deserialize, Serialize};

/// ChaCha stream ids ("det_crat", "det_bold").
const CRATER_STREAM: u64 = 0x6465_745f_6372_6174;
const BOULDER_STREAM: u64 = 0x6465_745f_626f_6c64;
/// Largest tile a build accepts: 8 M nodes (64 MB of f64 heights, 85 MB of pyramid).
pub const MAX_DETAIL_NODES: u64 = 1 << 23;
/// Expected feature counts a build accepts (each kind).
const MAX_FEATURES: f64 = 2e6;
/// Radial sample step of the degraded-profile table, crater diameters.
const PROFILE_DX: f64 = 0.005;
/// Outer radius of the degraded-profile table, crater diameters (the fresh ejecta end at
/// 1.5; diffusion to `tau` = 0.1 spreads them by about `sqrt(4 tau)` = 0.6).
const PROFILE_X_MAX: f64 = 2.5;
/// Degradation states tabulated between fresh and `max_degradation`.
const PROFILE_LEVELS: usize = 32;
/// A degraded profile is cut where it falls below this fraction of the diameter.
const PROFILE_CUT: f64 = 1e-5;

/// The detail layer's configuration (TOML `[terrain.detail]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DetailSpec {
    /// Seed of the layer's random streams.
    pub seed: u64,
    /// Side of the square tile centred on the site, m (clipped to the base grid).
    pub extent_m: f64,
    /// Largest node spacing, m; over a base grid the spacing is the base's divided by the
    /// smallest whole number that reaches it.
    pub spacing_m: f64,
    /// Width of the band inside the tile's edge over which the detail fades to zero, m.
    pub taper_m: f64,
    /// Crater density as a multiple of the equilibrium `N(>D) = 0.079 D^-2` per m^2
    /// (Gault 1970), at D = 1 m.
    pub crater_density: f64,
    /// Exponent `b` of `N(>D) = c D^-b`: 2 steady state, ~2.8 production (Moore et al.
    /// 1980).
    pub crater_sfd_exponent: f64,
    /// Smallest crater drawn, m (at least four node spacings to be resolved).
    pub crater_min_diameter_m: f64,
    /// Largest crater drawn, m (further capped by what the base resolves).
    pub crater_max_diameter_m: f64,
    /// Fraction of craters drawn degraded (the rest fresh).
    pub degraded_fraction: f64,
    /// Largest degradation state `tau = kappa t / D^2` of a degraded crater.
    pub max_degradation: f64,
    /// Fresh depth (rim crest to floor) over diameter (Pike 1977: ~0.2).
    pub depth_to_diameter: f64,
    /// Fresh rim height over diameter (Pike 1977: ~0.04).
    pub rim_height_to_diameter: f64,
    /// Golombek & Rapp rock abundance `k` (0 for no boulders).
    pub rock_abundance: f64,
    /// Smallest boulder drawn, m (at least two node spacings).
    pub boulder_min_diameter_m: f64,
    /// Largest boulder drawn, m (further capped by what the base resolves).
    pub boulder_max_diameter_m: f64,
    /// Over a GeoTIFF base: features are drawn up to this many of its pixels across.
    pub base_resolution_pixels: f64,
    /// Refine the base inside the tile with Catmull-Rom bicubic interpolation of its nodes
    /// (through every node, continuous slopes) instead of its bilinear facets, faded in
    /// across the taper band like the detail.
    pub smooth_base: bool,
}

impl Default for DetailSpec {
    fn default() -> Self {
        Self {
            seed: 1,
            extent_m: 1000.0,
            spacing_m: 0.5,
            taper_m: 50.0,
            crater_density: 1.0,
            crater_sfd_exponent: 2.0,
            crater_min_diameter_m: 2.0,
            crater_max_diameter_m: 100.0,
            degraded_fraction: 0.8,
            max_degradation: 0.05,
            depth_to_diameter: 0.2,
            rim_height_to_diameter: 0.04,
            rock_abundance: 0.05,
            boulder_min_diameter_m: 1.0,
            boulder_max_diameter_m: 4.0,
            base_resolution_pixels: 3.0,
            smooth_base: true,
        }
    }
}

impl DetailSpec {
    /// Checks every field's range; run before tick 0.
    pub fn validate(&self) -> Result<(), TerrainError> {
        let bad = |field: &'static str, reason: String| TerrainError::InvalidSpec { field, reason };
        positive("detail.extent_m", self.extent_m)?;
        positive("detail.spacing_m", self.spacing_m)?;
        in_range("detail.spacing_m", self.spacing_m, 0.01, 10.0)?;
        in_range("detail.taper_m", self.taper_m, 0.0, 0.25 * self.extent_m)?;
        let side = (self.extent_m / self.spacing_m).ceil() as u64 + 1;
        if side.saturating_mul(side) > MAX_DETAIL_NODES {
            return Err(TerrainError::GridTooLarge {
                nodes: side.saturating_mul(side),
                limit: MAX_DETAIL_NODES,
            });
        }
        in_range("detail.crater_density", self.crater_density, 0.0, 100.0)?;
        in_range(
            "detail.crater_sfd_exponent",
            self.crater_sfd_exponent,
            0.5,
            5.0,
        )?;
        positive("detail.crater_min_diameter_m", self.crater_min_diameter_m)?;
        positive("detail.crater_max_diameter_m", self.crater_max_diameter_m)?;
        if self.crater_max_diameter_m < self.crater_min_diameter_m {
            return Err(bad(
                "detail.crater_max_diameter_m",
                "must be at least detail.crater_min_diameter_m".into(),
            ));
        }
        in_range("detail.degraded_fraction", self.degraded_fraction, 0.0, 1.0)?;
        in_range("detail.max_degradation", self.max_degradation, 0.0, 0.1)?;
        in_range("detail.depth_to_diameter", self.depth_to_diameter, 0.0, 1.0)?;
        in_range(
            "detail.rim_height_to_diameter",
            self.rim_height_to_diameter,
            0.0,
            1.0,
        )?;
        in_range("detail.rock_abundance", self.rock_abundance, 0.0, 0.5)?;
        positive("detail.boulder_min_diameter_m", self.boulder_min_diameter_m)?;
        positive("detail.boulder_max_diameter_m", self.boulder_max_diameter_m)?;
        if self.boulder_max_diameter_m < self.boulder_min_diameter_m {
            return Err(bad(
                "detail.boulder_max_diameter_m",
                "must be at least detail.boulder_min_diameter_m".into(),
            ));
        }
        in_range(
            "detail.base_resolution_pixels",
            self.base_resolution_pixels,
            1.0,
            100.0,
        )?;
        let area = self.extent_m * self.extent_m;
        let craters = crater_rate_per_m2(self, self.crater_max_diameter_m) * area;
        if craters > MAX_FEATURES {
            return Err(bad(
                "detail.crater_min_diameter_m",
                format!("gives {craters:.3e} expected craters (limit {MAX_FEATURES:e})"),
            ));
        }
        let rocks = boulders_per_m2(self, self.boulder_max_diameter_m) * area;
        if rocks > MAX_FEATURES {
            return Err(bad(
                "detail.boulder_min_diameter_m",
                format!("gives {rocks:.3e} expected boulders (limit {MAX_FEATURES:e})"),
            ));
        }
        Ok(())
    }
}

/// What the base resolves, for the rule "only what is below its resolution": the largest
/// crater and boulder diameters the detail may add.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaseLimits {
    /// Craters up to this diameter, m.
    pub crater_max_diameter_m: f64,
    /// Boulders up to this diameter, m.
    pub boulder_max_diameter_m: f64,
}

impl BaseLimits {
    /// No limit (the smooth sphere resolves nothing).
    pub const NONE: BaseLimits = BaseLimits {
        crater_max_diameter_m: f64::INFINITY,
        boulder_max_diameter_m: f64::INFINITY,
    };

    /// A synthetic base: below its smallest crater and boulder.
    pub fn synthetic(s: &super::SyntheticSpec) -> Self {
        Self {
            crater_max_diameter_m: s.crater_min_diameter_m,
            boulder_max_diameter_m: s
                .boulders
                .as_ref()
                .map_or(f64::INFINITY, |b| b.min_diameter_m),
        }
    }

    /// A DEM of pixel `spacing_m`: features up to `pixels` of its pixels.
    pub fn dem(spacing_m: f64, pixels: f64) -> Self {
        Self {
            crater_max_diameter_m: pixels * spacing_m,
            boulder_max_diameter_m: pixels * spacing_m,
        }
    }
}

/// One crater of the layer: centre, diameter and degradation state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetailCrater {
    /// Centre, map east, m.
    pub e_m: f64,
    /// Centre, map north, m.
    pub n_m: f64,
    /// Diameter, m.
    pub diameter_m: f64,
    /// `tau = kappa t / D^2` (0: fresh).
    pub degradation: f64,
}

/// The layer's square tile on the map: origin, spacing and nodes per side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileLayout {
    /// Node (0, 0), map east and north, m.
    pub e0_m: f64,
    /// Node (0, 0), map north, m.
    pub n0_m: f64,
    /// Node spacing, m.
    pub spacing_m: f64,
    /// Nodes along e.
    pub nx: usize,
    /// Nodes along n.
    pub ny: usize,
}

impl TileLayout {
    /// Map extent `(e_min, e_max, n_min, n_max)`, m.
    pub fn bounds_m(&self) -> (f64, f64, f64, f64) {
        (
            self.e0_m,
            self.e0_m + self.spacing_m * (self.nx - 1) as f64,
            self.n0_m,
            self.n0_m + self.spacing_m * (self.ny - 1) as f64,
        )
    }
}

/// The tile of `s` over an optional base grid: centred on the site, clipped to the base,
/// its nodes on every base node within it.
pub fn layout(s: &DetailSpec, base: Option<&Grid>) -> Result<TileLayout, TerrainError> {
    let half = 0.5 * s.extent_m;
    let too_small = || TerrainError::InvalidSpec {
        field: "detail.extent_m",
        reason: "leaves fewer than 2 x 2 base cells of tile over the base grid".into(),
    };
    let Some(g) = base else {
        let cells = (s.extent_m / s.spacing_m).ceil() as usize;
        let h = 0.5 * s.spacing_m * cells as f64;
        return Ok(TileLayout {
            e0_m: -h,
            n0_m: -h,
            spacing_m: s.spacing_m,
            nx: cells + 1,
            ny: cells + 1,
        });
    };
    let sb = g.spacing_m();
    let k = (sb / s.spacing_m).ceil().max(1.0) as usize;
    let spacing_m = sb / k as f64;
    let (e0, n0) = g.origin_m();
    // Whole base cells, from the base node at or below -half to the one at or above
    // +half, within the base grid.
    let span = |x0: f64, n: usize| {
        let lo = ((-half - x0) / sb).floor().max(0.0) as usize;
        let hi = (((half - x0) / sb).ceil().max(0.0) as usize).min(n - 1);
        (lo, hi)
    };
    let (i0, i1) = span(e0, g.nx());
    let (j0, j1) = span(n0, g.ny());
    if i1 < i0 + 2 || j1 < j0 + 2 {
        return Err(too_small());
    }
    let (nx, ny) = ((i1 - i0) * k + 1, (j1 - j0) * k + 1);
    // The whole fraction of the base's spacing may be finer than asked (a 0.51 m base
    // and 0.5 m asked give 0.255 m): the node count is checked again here.
    let nodes = (nx as u64).saturating_mul(ny as u64);
    if nodes > MAX_DETAIL_NODES {
        return Err(TerrainError::GridTooLarge {
            nodes,
            limit: MAX_DETAIL_NODES,
        });
    }
    Ok(TileLayout {
        e0_m: e0 + sb * i0 as f64,
        n0_m: n0 + sb * j0 as f64,
        spacing_m,
        nx,
        ny,
    })
}

/// Cumulative crater rate `N(>D_min) - N(>d_max)` per m^2.
fn crater_rate_per_m2(s: &DetailSpec, d_max: f64) -> f64 {
    let b = s.crater_sfd_exponent;
    let c = EQUILIBRIUM_C_PER_M2 * s.crater_density;
    let d_max = d_max.max(s.crater_min_diameter_m);
    c * (s.crater_min_diameter_m.powf(-b) - d_max.powf(-b))
}

/// Expected boulders per m^2 with diameters in `[min, d_max]` (Golombek & Rapp 1997).
pub fn boulders_per_m2(s: &DetailSpec, d_max: f64) -> f64 {
    let k = s.rock_abundance;
    let d_max = d_max.max(s.boulder_min_diameter_m);
    if k <= 0.0 || d_max <= s.boulder_min_diameter_m {
        return 0.0;
    }
    // Simpson's rule on ln D; 256 panels.
    let (l0, l1) = (s.boulder_min_diameter_m.ln(), d_max.ln());
    let m = 256;
    let h = (l1 - l0) / m as f64;
    let f = |l: f64| {
        let d = l.exp();
        synthetic::boulder_density(k, d) * d
    };
    let mut acc = f(l0) + f(l1);
    for i in 1..m {
        acc += f(l0 + h * i as f64) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    acc * h / 3.0
}

/// The cumulative fractional area of boulders wider than `d` (Golombek & Rapp 1997):
/// `F(D) = k exp(-q D)`, `q = 1.79 + 0.152 / k`.
pub fn boulder_area_fraction_above(k: f64, d: f64) -> f64 {
    k * (-(1.79 + 0.152 / k) * d).exp()
}

/// Half side of the square in which crater centres are drawn about the tile's centre:
/// the tile plus the reach of the largest crater's (degraded) profile.
fn crater_draw_half_m(t: &TileLayout, d_max: f64) -> (f64, f64, f64) {
    let (e0, e1, n0, n1) = t.bounds_m();
    let margin = PROFILE_X_MAX * d_max;
    (
        0.5 * (e0 + e1),
        0.5 * (n0 + n1),
        0.5 * (e1 - e0).max(n1 - n0) + margin,
    )
}

/// The layer's craters over tile `t` with the base's limits, in draw order.
pub fn craters(s: &DetailSpec, t: &TileLayout, limits: &BaseLimits) -> Vec<DetailCrater> {
    let d_max = s.crater_max_diameter_m.min(limits.crater_max_diameter_m);
    if d_max <= s.crater_min_diameter_m || s.crater_density <= 0.0 {
        return Vec::new();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(CRATER_STREAM);
    let (ce, cn, half) = crater_draw_half_m(t, d_max);
    let n = poisson(&mut rng, crater_rate_per_m2(s, d_max) * 4.0 * half * half);
    let b = s.crater_sfd_exponent;
    let (lo, hi) = (s.crater_min_diameter_m.powf(-b), d_max.powf(-b));
    (0..n)
        .map(|_| {
            let u: f64 = rng.gen();
            let e = ce + rng.gen_range(-half..half);
            let nn = cn + rng.gen_range(-half..half);
            let degraded = rng.gen::<f64>() < s.degraded_fraction;
            let tau_u: f64 = rng.gen();
            DetailCrater {
                e_m: e,
                n_m: nn,
                diameter_m: (lo - u * (lo - hi)).powf(-1.0 / b),
                // (0, max]: uniform on the states, never exactly fresh.
                degradation: if degraded {
                    s.max_degradation * (1.0 - tau_u)
                } else {
                    0.0
                },
            }
        })
        .collect()
}

/// The layer's boulders over tile `t` (centres uniform on the tile; diameters by rejection
/// from a `D^-2` proposal accepted with `exp(-q (D - D_min))`, as the synthetic base's).
pub fn boulders(s: &DetailSpec, t: &TileLayout, limits: &BaseLimits) -> Vec<synthetic::Feature> {
    let d_max = s.boulder_max_diameter_m.min(limits.boulder_max_diameter_m);
    let (e0, e1, n0, n1) = t.bounds_m();
    let mean = boulders_per_m2(s, d_max) * (e1 - e0) * (n1 - n0);
    if mean <= 0.0 {
        return Vec::new();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(BOULDER_STREAM);
    let n = poisson(&mut rng, mean);
    let k = s.rock_abundance;
    let q = 1.79 + 0.152 / k;
    let (lo, hi) = (1.0 / s.boulder_min_diameter_m, 1.0 / d_max);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let u: f64 = rng.gen();
        let d = 1.0 / (lo - u * (lo - hi));
        let accept: f64 = rng.gen();
        if accept < (-q * (d - s.boulder_min_diameter_m)).exp() {
            out.push(synthetic::Feature {
                e_m: rng.gen_range(e0..e1),
                n_m: rng.gen_range(n0..n1),
                diameter_m: d,
            });
        }
    }
    out
}

fn poisson(rng: &mut ChaCha8Rng, mean: f64) -> usize {
    match Poisson::new(mean) {
        Ok(p) if mean > 0.0 => {
            let x: f64 = p.sample(rng);
            x as usize
        }
        _ => 0,
    }
}

/// Diffuses an axisymmetric profile `h(x)` (values at ring centres `(i + 1/2) dx`) by
/// `dh/dtau = (1/x) d/dx(x dh/dx)` over `tau`, with no flux through the outer edge:
/// explicit finite volumes on rings, which keep `sum(h_i * area_i)` (the volume) exactly.
/// Hand-written: a 1-D explicit heat step is a dozen lines.
pub fn diffuse_radial(h: &mut [f64], dx: f64, tau: f64) {
    let m = h.len();
    if m < 2 || tau <= 0.0 {
        return;
    }
    // Stable for dt <= dx^2 / 2 (the centre ring's coefficient is 2 / dx^2); 0.4 of it.
    let steps = (tau / (0.4 * dx * dx)).ceil() as usize;
    let dt = tau / steps as f64;
    let mut flux = vec![0.0; m - 1];
    for _ in 0..steps {
        // Face i between rings i and i + 1 at x = (i + 1) dx: x dh/dx.
        for (i, f) in flux.iter_mut().enumerate() {
            *f = (i + 1) as f64 * (h[i + 1] - h[i]);
        }
        for i in 0..m {
            let inflow = if i + 1 < m { flux[i] } else { 0.0 };
            let outflow = if i > 0 { flux[i - 1] } else { 0.0 };
            // Ring area / (2 pi dx^2) = (2i + 1) / 2.
            h[i] += dt * (inflow - outflow) / (0.5 * (2 * i + 1) as f64 * dx * dx);
        }
    }
}

/// Tabulated crater profiles in units of the diameter, from fresh to `max_degradation`.
#[derive(Debug, Clone)]
pub struct ProfileTable {
    /// `levels[j][i]`: height over diameter at `x = (i + 1/2) dx` diameters, state
    /// `tau_j = max * j / (levels - 1)`.
    levels: Vec<Vec<f64>>,
    /// Where each level's profile ends (|h| below the cut beyond), diameters.
    reach: Vec<f64>,
    max_degradation: f64,
}

impl ProfileTable {
    /// Fresh profiles of `s`'s shape diffused to each tabulated state.
    pub fn new(s: &DetailSpec) -> Self {
        let m = (PROFILE_X_MAX / PROFILE_DX).round() as usize;
        let shape = fresh_shape(s);
        let fresh: Vec<f64> = (0..m)
            .map(|i| synthetic::crater_profile_m(&shape, 1.0, (i as f64 + 0.5) * PROFILE_DX))
            .collect();
        let mut levels = Vec::with_capacity(PROFILE_LEVELS);
        let mut h = fresh.clone();
        let dtau = s.max_degradation / (PROFILE_LEVELS - 1) as f64;
        levels.push(fresh);
        for _ in 1..PROFILE_LEVELS {
            diffuse_radial(&mut h, PROFILE_DX, dtau);
            levels.push(h.clone());
        }
        let reach = levels
            .iter()
            .map(|l| {
                let last = l.iter().rposition(|v| v.abs() > PROFILE_CUT).unwrap_or(0);
                (last as f64 + 1.0) * PROFILE_DX
            })
            .collect();
        Self {
            levels,
            reach,
            max_degradation: s.max_degradation,
        }
    }

    fn level(&self, tau: f64) -> usize {
        if self.max_degradation <= 0.0 {
            return 0;
        }
        let j = (tau / self.max_degradation * (PROFILE_LEVELS - 1) as f64).round();
        (j.max(0.0) as usize).min(PROFILE_LEVELS - 1)
    }

    /// The tabulated state nearest `tau` (what a crater of state `tau` is drawn with).
    pub fn tabulated_degradation(&self, tau: f64) -> f64 {
        self.max_degradation * self.level(tau) as f64 / (PROFILE_LEVELS - 1) as f64
    }

    /// Reach of the profile of state `tau`, diameters.
    pub fn reach_diameters(&self, tau: f64) -> f64 {
        self.reach[self.level(tau)]
    }

    /// Height over diameter at `x` diameters from the centre, state `tau` (linear between
    /// ring centres; 0 beyond the reach).
    pub fn height_over_diameter(&self, tau: f64, x: f64) -> f64 {
        let j = self.level(tau);
        if x >= self.reach[j] {
            return 0.0;
        }
        let l = &self.levels[j];
        let u = (x / PROFILE_DX - 0.5).max(0.0);
        let i = (u.floor() as usize).min(l.len() - 2);
        let f = (u - i as f64).min(1.0);
        l[i] + (l[i + 1] - l[i]) * f
    }
}

/// A [`super::SyntheticSpec`] carrying only the detail's fresh shape (what
/// [`synthetic::crater_profile_m`] reads).
fn fresh_shape(s: &DetailSpec) -> super::SyntheticSpec {
    super::SyntheticSpec {
        depth_to_diameter: s.depth_to_diameter,
        rim_height_to_diameter: s.rim_height_to_diameter,
        ..super::SyntheticSpec::default()
    }
}

/// Height of a detail crater at distance `r_m` from its centre, m: the fresh profile, or
/// the tabulated diffused one.
pub fn crater_height_m(s: &DetailSpec, table: &ProfileTable, c: &DetailCrater, r_m: f64) -> f64 {
    if c.degradation == 0.0 {
        synthetic::crater_profile_m(&fresh_shape(s), c.diameter_m, r_m)
    } else {
        c.diameter_m * table.height_over_diameter(c.degradation, r_m / c.diameter_m)
    }
}

/// The taper weight at map `(e, n)` of tile bounds `b`: 0 at the edge, 1 beyond `taper_m`
/// inside it, smoothstep `3x^2 - 2x^3` between.
pub fn taper_weight(b: (f64, f64, f64, f64), taper_m: f64, e: f64, n: f64) -> f64 {
    let d = (e - b.0).min(b.1 - e).min(n - b.2).min(b.3 - n);
    if taper_m <= 0.0 {
        return if d > 0.0 { 1.0 } else { 0.0 };
    }
    let x = (d / taper_m).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// The detail heights alone (before the taper and without the base) on tile `t`.
pub fn detail_only_grid(
    s: &DetailSpec,
    t: &TileLayout,
    limits: &BaseLimits,
) -> Result<Grid, TerrainError> {
    let mut g = Grid::new(
        t.nx,
        t.ny,
        t.e0_m,
        t.n0_m,
        t.spacing_m,
        vec![0.0; t.nx * t.ny],
    )
    .ok_or(TerrainError::NonFinite)?;
    let table = ProfileTable::new(s);
    let shape = fresh_shape(s);
    for c in craters(s, t, limits) {
        let (ce, cn, d) = (c.e_m, c.n_m, c.diameter_m);
        if c.degradation == 0.0 {
            let reach = 0.5 * synthetic::EJECTA_REACH_RADII * d;
            g.add_in_box(ce - reach, ce + reach, cn - reach, cn + reach, |e, n| {
                synthetic::crater_profile_m(&shape, d, (e - ce).hypot(n - cn))
            });
        } else {
            let reach = table.reach_diameters(c.degradation) * d;
            g.add_in_box(ce - reach, ce + reach, cn - reach, cn + reach, |e, n| {
                d * table.height_over_diameter(c.degradation, (e - ce).hypot(n - cn) / d)
            });
        }
    }
    for r in boulders(s, t, limits) {
        let rad = 0.5 * r.diameter_m;
        let height = synthetic::BOULDER_HEIGHT_TO_DIAMETER * r.diameter_m;
        let (ce, cn) = (r.e_m, r.n_m);
        g.add_in_box(ce - rad, ce + rad, cn - rad, cn + rad, |e, n| {
            let x = (e - ce).hypot(n - cn) / rad;
            if x < 1.0 {
                height * (1.0 - x * x).sqrt()
            } else {
                0.0
            }
        });
    }
    if !g.finish() {
        return Err(TerrainError::NonFinite);
    }
    Ok(g)
}

/// Catmull-Rom weights of the four nodes about a point at fraction `t` of its cell.
fn catmull_rom_weights(t: f64) -> [f64; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// The base's Catmull-Rom bicubic surface at map `(e, n)` (nodes beyond the grid's edge
/// repeat the edge's): equal to the bilinear one on every node, with continuous slopes
/// between (Catmull & Rom 1974; Keys 1981, `a = -1/2`).
pub fn catmull_rom_m(g: &Grid, e_m: f64, n_m: f64) -> f64 {
    let (e0, n0) = g.origin_m();
    let s = g.spacing_m();
    let cell = |x: f64, x0: f64, n: usize| {
        let u = ((x - x0) / s).clamp(0.0, (n - 1) as f64);
        let i = (u.floor() as usize).min(n - 2);
        (i, u - i as f64)
    };
    let (i, fx) = cell(e_m, e0, g.nx());
    let (j, fy) = cell(n_m, n0, g.ny());
    let (wx, wy) = (catmull_rom_weights(fx), catmull_rom_weights(fy));
    let clamp = |k: usize, d: usize, n: usize| (k + d).saturating_sub(1).min(n - 1);
    let mut acc = 0.0;
    for (dy, wyv) in wy.iter().enumerate() {
        let jj = clamp(j, dy, g.ny());
        let mut row = 0.0;
        for (dx, wxv) in wx.iter().enumerate() {
            row += wxv * g.at(clamp(i, dx, g.nx()), jj);
        }
        acc += wyv * row;
    }
    acc
}

/// The tile's total heights: the base at each node plus the tapered detail (and, with
/// `smooth_base`, the tapered difference between the base's bicubic and bilinear
/// surfaces), so the tile is exactly the base at its edge.
pub fn build_tile(
    s: &DetailSpec,
    base: Option<&Grid>,
    limits: &BaseLimits,
) -> Result<Grid, TerrainError> {
    s.validate()?;
    let t = layout(s, base)?;
    let detail = detail_only_grid(s, &t, limits)?;
    let b = t.bounds_m();
    let mut h = detail.samples().to_vec();
    for j in 0..t.ny {
        let n = t.n0_m + t.spacing_m * j as f64;
        for i in 0..t.nx {
            let e = t.e0_m + t.spacing_m * i as f64;
            let k = j * t.nx + i;
            let w = taper_weight(b, s.taper_m, e, n);
            let (linear, refined) = match base {
                None => (0.0, 0.0),
                Some(g) => {
                    let lin = g.sample(e, n).h_m;
                    let cubic = if s.smooth_base && w > 0.0 {
                        catmull_rom_m(g, e, n)
                    } else {
                        lin
                    };
                    (lin, cubic)
                }
            };
            h[k] = linear + w * (h[k] + refined - linear);
        }
    }
    Grid::new(t.nx, t.ny, t.e0_m, t.n0_m, t.spacing_m, h).ok_or(TerrainError::NonFinite)
}
