//! The seeded synthetic surface: craters drawn from a cumulative power law
//! `N(>D) = c D^-b` per m^2, fresh bowl-and-rim shapes with an ejecta blanket, a regional
//! slope and optional boulders, each stamped additively on a grid about the site.
//!
//! Random draws come from ChaCha8 streams of their own (craters, boulders), seeded from
//! the spec's seed, so enabling boulders never moves a crater.

use super::grid::Grid;
use super::spec::{nodes_per_side, BoulderSpec, SyntheticSpec};
use super::TerrainError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};

/// Equilibrium cumulative crater density coefficient, per m^2 with D in m:
/// `N(>D) = 10^-1.1 D^-2` (Gault 1970, Radio Science 5(2) 273-291; Trask 1966).
pub const EQUILIBRIUM_C_PER_M2: f64 = 0.079_432_823_472_428_15; // 10^-1.1
/// Ejecta reach in crater radii; the blanket `h_rim (r/R)^-3` (McGetchin et al. 1973) is
/// tapered to zero there (assumed cut-off).
pub const EJECTA_REACH_RADII: f64 = 3.0;
/// Boulder height over diameter (Golombek & Rapp 1997: rock heights ~ half the
/// diameter); shaped as a half-ellipsoid cap.
pub const BOULDER_HEIGHT_TO_DIAMETER: f64 = 0.5;
/// ChaCha stream ids ("ter_crat", "ter_bold").
const CRATER_STREAM: u64 = 0x7465_725f_6372_6174;
const BOULDER_STREAM: u64 = 0x7465_725f_626f_6c64;

/// One crater (or boulder) drawn: centre in map coordinates and diameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feature {
    /// Centre, map east, m.
    pub e_m: f64,
    /// Centre, map north, m.
    pub n_m: f64,
    /// Diameter, m.
    pub diameter_m: f64,
}

/// Half side of the square in which crater centres are drawn: the grid plus the
/// largest crater's ejecta reach, so the grid's edge sees partial craters too.
pub fn crater_half_side_m(s: &SyntheticSpec) -> f64 {
    0.5 * s.extent_m + 0.5 * EJECTA_REACH_RADII * s.crater_max_diameter_m
}

/// Expected crater count over the draw square (what the Poisson draw is centred on).
pub fn expected_craters(s: &SyntheticSpec) -> f64 {
    let half = crater_half_side_m(s);
    let b = s.crater_sfd_exponent;
    let c = EQUILIBRIUM_C_PER_M2 * s.crater_density;
    c * 4.0 * half * half * (s.crater_min_diameter_m.powf(-b) - s.crater_max_diameter_m.powf(-b))
}

/// The craters of `s`, in draw order (count ~ Poisson, diameters by inverse CDF of the
/// truncated power law, centres uniform on the draw square).
pub fn craters(s: &SyntheticSpec) -> Vec<Feature> {
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(CRATER_STREAM);
    let n = poisson(&mut rng, expected_craters(s));
    let half = crater_half_side_m(s);
    let b = s.crater_sfd_exponent;
    let (lo, hi) = (
        s.crater_min_diameter_m.powf(-b),
        s.crater_max_diameter_m.powf(-b),
    );
    (0..n)
        .map(|_| {
            let u: f64 = rng.gen();
            let d = (lo - u * (lo - hi)).powf(-1.0 / b);
            Feature {
                e_m: rng.gen_range(-half..half),
                n_m: rng.gen_range(-half..half),
                diameter_m: d,
            }
        })
        .collect()
}

/// Boulder number density per m^2 per m of diameter at `d` (Golombek & Rapp 1997).
pub(super) fn boulder_density(k: f64, d: f64) -> f64 {
    let q = 1.79 + 0.152 / k;
    k * q * (-q * d).exp() / (std::f64::consts::PI * 0.25 * d * d)
}

/// Expected boulder count over the grid.
pub fn expected_boulders(s: &SyntheticSpec, b: &BoulderSpec) -> f64 {
    // Simpson's rule on ln D (the density spans decades); 256 panels.
    let (l0, l1) = (b.min_diameter_m.ln(), b.max_diameter_m.ln());
    let m = 256;
    let h = (l1 - l0) / m as f64;
    let f = |l: f64| {
        let d = l.exp();
        boulder_density(b.rock_abundance, d) * d
    };
    let mut acc = f(l0) + f(l1);
    for i in 1..m {
        acc += f(l0 + h * i as f64) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    acc * h / 3.0 * s.extent_m * s.extent_m
}

/// The boulders of `s` (count ~ Poisson; diameters by rejection from a `D^-2` proposal,
/// accepted with `exp(-q (D - D_min))`; centres uniform on the grid).
pub fn boulders(s: &SyntheticSpec, b: &BoulderSpec) -> Vec<Feature> {
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(BOULDER_STREAM);
    let n = poisson(&mut rng, expected_boulders(s, b));
    let q = 1.79 + 0.152 / b.rock_abundance;
    let (lo, hi) = (1.0 / b.min_diameter_m, 1.0 / b.max_diameter_m);
    let half = 0.5 * s.extent_m;
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let u: f64 = rng.gen();
        let d = 1.0 / (lo - u * (lo - hi));
        let accept: f64 = rng.gen();
        if accept < (-q * (d - b.min_diameter_m)).exp() {
            out.push(Feature {
                e_m: rng.gen_range(-half..half),
                n_m: rng.gen_range(-half..half),
                diameter_m: d,
            });
        }
    }
    out
}

fn poisson(rng: &mut ChaCha8Rng, mean: f64) -> usize {
    if mean <= 0.0 {
        return 0;
    }
    match Poisson::new(mean) {
        Ok(p) => {
            let x: f64 = p.sample(rng);
            x as usize
        }
        Err(_) => 0,
    }
}

/// Height of a fresh crater of diameter `d_m` at distance `r_m` from its centre, m:
/// a parabolic bowl from the floor (`rim - depth`) to the rim crest at `r = D/2`, then
/// the ejecta blanket `rim (r/R)^-3`, tapered to zero at [`EJECTA_REACH_RADII`].
pub fn crater_profile_m(s: &SyntheticSpec, d_m: f64, r_m: f64) -> f64 {
    let rim = s.rim_height_to_diameter * d_m;
    let depth = s.depth_to_diameter * d_m;
    let x = r_m / (0.5 * d_m);
    if x < 1.0 {
        rim - depth * (1.0 - x * x)
    } else if x < EJECTA_REACH_RADII {
        let tail = EJECTA_REACH_RADII.powi(-3);
        rim * (x.powi(-3) - tail) / (1.0 - tail)
    } else {
        0.0
    }
}

/// Builds the grid of `s` (validated by the caller).
pub fn build_grid(s: &SyntheticSpec) -> Result<Grid, TerrainError> {
    let side = nodes_per_side(s.extent_m, s.spacing_m) as usize;
    let half = 0.5 * s.spacing_m * (side - 1) as f64;
    let mut grid = Grid::new(
        side,
        side,
        -half,
        -half,
        s.spacing_m,
        vec![0.0; side * side],
    )
    .ok_or(TerrainError::NonFinite)?;

    // Regional slope: downhill toward the azimuth (clockwise from north).
    let tan_s = s.regional_slope_deg.to_radians().tan();
    let (sa, ca) = s.slope_azimuth_deg.to_radians().sin_cos();
    if tan_s != 0.0 {
        grid.add_in_box(-half, half, -half, half, |e, n| -tan_s * (e * sa + n * ca));
    }

    for c in craters(s) {
        let reach = 0.5 * EJECTA_REACH_RADII * c.diameter_m;
        let (ce, cn, d) = (c.e_m, c.n_m, c.diameter_m);
        grid.add_in_box(ce - reach, ce + reach, cn - reach, cn + reach, |e, n| {
            crater_profile_m(s, d, (e - ce).hypot(n - cn))
        });
    }

    if let Some(b) = &s.boulders {
        for r in boulders(s, b) {
            let rad = 0.5 * r.diameter_m;
            let height = BOULDER_HEIGHT_TO_DIAMETER * r.diameter_m;
            let (ce, cn) = (r.e_m, r.n_m);
            grid.add_in_box(ce - rad, ce + rad, cn - rad, cn + rad, |e, n| {
                let x = (e - ce).hypot(n - cn) / rad;
                if x < 1.0 {
                    height * (1.0 - x * x).sqrt()
                } else {
                    0.0
                }
            });
        }
    }
    if !grid.finish() {
        return Err(TerrainError::NonFinite);
    }
    Ok(grid)
}
