//! The detail layer against closed forms and statistics (`docs/terrain.md`): fresh and
//! degraded crater shapes, the diffusion solver, the crater size-frequency distribution,
//! the boulder cover fraction, determinism, continuity at the tile's edge, the base
//! resolution rule, and ray casts that see it.

use nalgebra::Vector3;
use oils_emulator::world::terrain::detail::{
    self, boulder_area_fraction_above, diffuse_radial, BaseLimits, DetailCrater, ProfileTable,
};
use oils_emulator::world::terrain::ray::RANGE_TOL_M;
use oils_emulator::world::terrain::synthetic::crater_profile_m;
use oils_emulator::world::terrain::{
    build, BoulderSpec, DetailSpec, SiteFrame, SmoothSpec, SyntheticSpec, Terrain, TerrainError,
    TerrainSpec,
};

const R_M: f64 = 1_737_400.0;

fn site() -> SiteFrame {
    SiteFrame::from_deg(-69.373, 32.319, R_M)
}

fn smooth_with(d: DetailSpec) -> TerrainSpec {
    TerrainSpec::Smooth(SmoothSpec { detail: Some(d) })
}

fn base_synthetic(detail: Option<DetailSpec>) -> SyntheticSpec {
    SyntheticSpec {
        seed: 3,
        extent_m: 1200.0,
        spacing_m: 2.0,
        crater_min_diameter_m: 16.0,
        detail,
        ..SyntheticSpec::default()
    }
}

fn small_detail(seed: u64) -> DetailSpec {
    DetailSpec {
        seed,
        extent_m: 300.0,
        taper_m: 20.0,
        ..DetailSpec::default()
    }
}

/// A Gaussian `exp(-x^2 / (2 s^2))` under `dh/dtau = lap(h)` in 2-D stays Gaussian:
/// `s^2 / (s^2 + 2 tau) exp(-x^2 / (2 (s^2 + 2 tau)))`. The second-order solver matches it
/// to 3e-4 of the peak at `dx = s / 20` (measured 1.3e-4), and keeps the volume to
/// rounding.
#[test]
fn radial_diffusion_matches_the_gaussian_solution_and_keeps_volume() {
    let (dx, m, s2, tau) = (0.005, 800, 0.01, 0.004);
    let x = |i: usize| (i as f64 + 0.5) * dx;
    let mut h: Vec<f64> = (0..m).map(|i| (-x(i) * x(i) / (2.0 * s2)).exp()).collect();
    let vol = |h: &[f64]| -> f64 { h.iter().enumerate().map(|(i, v)| v * x(i)).sum() };
    let v0 = vol(&h);
    diffuse_radial(&mut h, dx, tau);
    let w = s2 + 2.0 * tau;
    for (i, v) in h.iter().enumerate() {
        let want = s2 / w * (-x(i) * x(i) / (2.0 * w)).exp();
        assert!((v - want).abs() < 3e-4, "x = {}: {v} vs {want}", x(i));
    }
    assert!((vol(&h) - v0).abs() < 1e-12 * v0, "{} vs {v0}", vol(&h));
}

/// Degradation fills the bowl and lowers the rim, monotonically in `tau`; the fresh level
/// is the fresh formula (Pike 1977 depth 0.2 D, rim 0.04 D); the profile's volume is kept.
#[test]
fn degraded_profiles_shallow_with_state_and_keep_volume() {
    let s = DetailSpec::default();
    let t = ProfileTable::new(&s);
    let shape = SyntheticSpec::default();
    for x in [0.0, 0.1, 0.3, 0.49, 0.6, 1.0, 1.4] {
        let want = crater_profile_m(&shape, 1.0, x);
        assert!(
            (t.height_over_diameter(0.0, x) - want).abs() < 2e-3,
            "x {x}"
        );
    }
    // Depth (rim crest - floor) and rim height, over D, by state.
    let mut last = (f64::INFINITY, f64::INFINITY);
    for k in 0..=10 {
        let tau = s.max_degradation * k as f64 / 10.0;
        let floor = t.height_over_diameter(tau, 0.0);
        let rim = (0..300)
            .map(|i| t.height_over_diameter(tau, i as f64 * 0.005))
            .fold(f64::NEG_INFINITY, f64::max);
        let depth = rim - floor;
        println!("tau {tau:.3}: depth/D {depth:.4}, rim/D {rim:.4}");
        assert!(depth <= last.0 + 1e-12 && rim <= last.1 + 1e-12);
        last = (depth, rim);
    }
    assert!(
        last.0 < 0.5 * 0.2,
        "depth/D {} at the largest state",
        last.0
    );
    // Volume of h(x) over the plane, 2 pi sum(h x dx), fresh vs most degraded.
    let vol = |tau: f64| -> f64 {
        (0..500)
            .map(|i| {
                let x = (i as f64 + 0.5) * 0.005;
                t.height_over_diameter(tau, x) * x
            })
            .sum::<f64>()
    };
    let scale = (0..500)
        .map(|i| {
            let x = (i as f64 + 0.5) * 0.005;
            t.height_over_diameter(0.0, x).abs() * x
        })
        .sum::<f64>();
    assert!(
        (vol(s.max_degradation) - vol(0.0)).abs() < 1e-3 * scale,
        "volume {} vs {}",
        vol(s.max_degradation),
        vol(0.0)
    );
}

/// Drawn diameters follow the truncated power law: the Kolmogorov-Smirnov distance to
/// `F(D) = (Dmin^-b - D^-b) / (Dmin^-b - Dmax^-b)` is below the 0.1 % critical value
/// `1.95 / sqrt(n)`, for the steady-state (b = 2) and production (b = 2.8) exponents; the
/// count is the expected one to 5 sigma (Poisson).
#[test]
fn crater_diameters_follow_the_size_frequency_distribution() {
    for b in [2.0, 2.8] {
        let s = DetailSpec {
            crater_sfd_exponent: b,
            crater_max_diameter_m: 50.0,
            ..small_detail(11)
        };
        let t = detail::layout(&s, None).unwrap();
        let mut d: Vec<f64> = detail::craters(&s, &t, &BaseLimits::NONE)
            .iter()
            .map(|c| c.diameter_m)
            .collect();
        let n = d.len();
        d.sort_by(f64::total_cmp);
        let (lo, hi) = (2f64.powf(-b), 50f64.powf(-b));
        let cdf = |x: f64| (lo - x.powf(-b)) / (lo - hi);
        let ks = d
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let f = cdf(x);
                (f - i as f64 / n as f64)
                    .abs()
                    .max(((i + 1) as f64 / n as f64 - f).abs())
            })
            .fold(0.0, f64::max);
        let crit = 1.95 / (n as f64).sqrt();
        println!("b = {b}: n = {n}, KS {ks:.4} (critical {crit:.4})");
        assert!(ks < crit, "b = {b}: KS {ks} >= {crit}");
        // Expected count over the draw square: tile side plus 2 x 2.5 Dmax.
        let (e0, e1, _, _) = t.bounds_m();
        let side = (e1 - e0) + 2.0 * 2.5 * 50.0;
        let mean = 0.079_432_823_472_428_15 * (lo - hi) * side * side;
        assert!(
            (n as f64 - mean).abs() < 5.0 * mean.sqrt(),
            "{n} craters, {mean} expected"
        );
    }
}

/// The fraction of area covered by drawn boulders with diameters in `[Dmin, Dmax]` is the
/// Golombek & Rapp `k (exp(-q Dmin) - exp(-q Dmax))`, to 4 sigma of its compound-Poisson
/// spread `sqrt(sum a_i^2) / A`.
#[test]
fn boulder_cover_matches_golombek_rapp() {
    for k in [0.05, 0.15] {
        let s = DetailSpec {
            rock_abundance: k,
            boulder_min_diameter_m: 0.5,
            boulder_max_diameter_m: 4.0,
            ..small_detail(5)
        };
        let t = detail::layout(&s, None).unwrap();
        let (e0, e1, n0, n1) = t.bounds_m();
        let area = (e1 - e0) * (n1 - n0);
        let rocks = detail::boulders(&s, &t, &BaseLimits::NONE);
        let a: Vec<f64> = rocks
            .iter()
            .map(|r| std::f64::consts::PI * 0.25 * r.diameter_m * r.diameter_m)
            .collect();
        let cover = a.iter().sum::<f64>() / area;
        let sigma = a.iter().map(|x| x * x).sum::<f64>().sqrt() / area;
        let want = boulder_area_fraction_above(k, 0.5) - boulder_area_fraction_above(k, 4.0);
        println!(
            "k {k}: {} boulders, cover {cover:.5} vs {want:.5} (sigma {sigma:.5})",
            rocks.len()
        );
        assert!(
            (cover - want).abs() < 4.0 * sigma,
            "k {k}: {cover} vs {want}"
        );
        assert!(rocks
            .iter()
            .all(|r| r.diameter_m >= 0.5 && r.diameter_m <= 4.0));
    }
}

/// An isolated fresh crater in the grid has its formula's floor and rim: with a sparse
/// population, the node nearest an isolated crater's centre holds `rim - depth`, and the
/// ring at the rim `rim`, to what the bilinear spacing allows.
#[test]
fn an_isolated_drawn_crater_has_its_formula_depth_and_rim() {
    let s = DetailSpec {
        extent_m: 600.0,
        crater_density: 2.0,
        crater_min_diameter_m: 20.0,
        crater_max_diameter_m: 21.0,
        degraded_fraction: 0.5,
        rock_abundance: 0.0,
        ..small_detail(2)
    };
    let t = detail::layout(&s, None).unwrap();
    let g = detail::detail_only_grid(&s, &t, &BaseLimits::NONE).unwrap();
    let table = ProfileTable::new(&s);
    let cs = detail::craters(&s, &t, &BaseLimits::NONE);
    let (e0, e1, n0, n1) = t.bounds_m();
    let isolated: Vec<&DetailCrater> = cs
        .iter()
        .filter(|c| {
            let inside =
                c.e_m > e0 + 40.0 && c.e_m < e1 - 40.0 && c.n_m > n0 + 40.0 && c.n_m < n1 - 40.0;
            let alone = cs.iter().all(|o| {
                std::ptr::eq(*c, o) || (o.e_m - c.e_m).hypot(o.n_m - c.n_m) > 2.6 * 21.0 * 2.0
            });
            inside && alone
        })
        .collect();
    assert!(
        isolated.len() >= 2,
        "{} isolated craters of {}",
        isolated.len(),
        cs.len()
    );
    let (mut fresh, mut degraded) = (0, 0);
    for c in isolated {
        let d = c.diameter_m;
        let want_floor = detail::crater_height_m(&s, &table, c, 0.0);
        let got_floor = g.sample(c.e_m, c.n_m).h_m;
        // Bilinear within 0.5 m of the centre of a parabola of curvature 2 depth / R^2.
        let curv_err = 2.0 * s.depth_to_diameter * d / (0.25 * d * d) * 0.25 * 0.5;
        assert!(
            (got_floor - want_floor).abs() < curv_err,
            "{got_floor} vs {want_floor}"
        );
        if c.degradation == 0.0 {
            fresh += 1;
            assert!((want_floor - (0.04 - 0.2) * d).abs() < 1e-12);
            // The rim crest at r = D/2: the grid's maximum around the crater is the rim.
            let mut top = f64::NEG_INFINITY;
            for k in 0..360 {
                let a = (k as f64).to_radians();
                let r = 0.5 * d;
                top = top.max(g.sample(c.e_m + r * a.cos(), c.n_m + r * a.sin()).h_m);
            }
            assert!((top - 0.04 * d).abs() < 0.05 * 0.04 * d + 0.05, "rim {top}");
        } else {
            degraded += 1;
            assert!(
                got_floor > (0.04 - 0.2) * d,
                "a degraded floor is shallower"
            );
        }
    }
    assert!(
        fresh > 0 && degraded > 0,
        "{fresh} fresh, {degraded} degraded"
    );
}

/// Same spec, same heights, bit for bit: built twice, and built in two threads at once;
/// another seed differs.
#[test]
fn detail_is_deterministic_and_thread_independent() {
    let spec = TerrainSpec::Synthetic(base_synthetic(Some(small_detail(9))));
    let a = build(&spec, &site()).unwrap();
    let (b, c) = std::thread::scope(|sc| {
        let hb = sc.spawn(|| build(&spec, &site()).unwrap());
        let hc = sc.spawn(|| build(&spec, &site()).unwrap());
        (hb.join().unwrap(), hc.join().unwrap())
    });
    let bits = |t: &Terrain| -> Vec<u64> {
        t.detail_grid()
            .unwrap()
            .samples()
            .iter()
            .map(|h| h.to_bits())
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(bits(&a), bits(&c));
    let other = build(
        &TerrainSpec::Synthetic(base_synthetic(Some(small_detail(10)))),
        &site(),
    )
    .unwrap();
    assert_ne!(bits(&a), bits(&other));
    // The base is the same with or without the layer.
    let plain = build(&TerrainSpec::Synthetic(base_synthetic(None)), &site()).unwrap();
    assert_eq!(a.grid(), plain.grid());
}

/// The surface is continuous at the tile's edge: walking across it, heights on either side
/// of the seam agree to what the slope allows over the step; and the tile's nodes on the
/// base's nodes, where the taper is zero, hold the base's heights exactly.
#[test]
fn the_tile_meets_the_base_at_its_edge() {
    let spec = TerrainSpec::Synthetic(base_synthetic(Some(small_detail(4))));
    let t = build(&spec, &site()).unwrap();
    let plain = build(&TerrainSpec::Synthetic(base_synthetic(None)), &site()).unwrap();
    let tile = t.detail_grid().unwrap();
    let (e0, e1, n0, n1) = tile.bounds_m();
    let slope = t.max_gradient();
    let eps = 1e-7;
    for k in 0..2000 {
        let u = k as f64 / 2000.0;
        for (ei, ni, eo, no) in [
            (e0 + eps, n0 + (n1 - n0) * u, e0 - eps, n0 + (n1 - n0) * u),
            (e1 - eps, n0 + (n1 - n0) * u, e1 + eps, n0 + (n1 - n0) * u),
            (e0 + (e1 - e0) * u, n0 + eps, e0 + (e1 - e0) * u, n0 - eps),
            (e0 + (e1 - e0) * u, n1 - eps, e0 + (e1 - e0) * u, n1 + eps),
        ] {
            let (hi, ho) = (t.elevation_m(ei, ni), t.elevation_m(eo, no));
            assert!(
                (hi - ho).abs() <= 2.0 * eps * slope + 1e-9,
                "seam at ({ei}, {ni}): {hi} vs {ho}"
            );
            // Outside the tile the surface is the base, untouched.
            assert_eq!(ho, plain.elevation_m(eo, no));
        }
    }
    // Within the taper band's outer edge the detail vanishes: the tile's edge nodes are
    // the base's values.
    let s = tile.spacing_m();
    for i in 0..tile.nx() {
        let e = e0 + s * i as f64;
        assert!((tile.at(i, 0) - plain.elevation_m(e, n0)).abs() < 1e-9);
    }
    assert!(
        s <= 0.5 && (2.0 / s - (2.0 / s).round()).abs() < 1e-12,
        "spacing {s}"
    );
}

/// Only what the base does not resolve: over a synthetic base, no detail crater reaches
/// its smallest crater nor boulder its smallest boulder; over a DEM of 5 m pixels with
/// the default 3 pixels, nothing above 15 m; over the smooth sphere, the spec's bounds.
#[test]
fn detail_adds_only_what_the_base_does_not_resolve() {
    let d = DetailSpec {
        crater_max_diameter_m: 100.0,
        boulder_max_diameter_m: 20.0,
        rock_abundance: 0.3,
        ..small_detail(6)
    };
    let t = detail::layout(&d, None).unwrap();
    let base = SyntheticSpec {
        crater_min_diameter_m: 16.0,
        boulders: Some(BoulderSpec {
            rock_abundance: 0.05,
            min_diameter_m: 3.0,
            max_diameter_m: 8.0,
        }),
        ..SyntheticSpec::default()
    };
    let cases = [
        (BaseLimits::synthetic(&base), 16.0, 3.0),
        (BaseLimits::dem(5.0, d.base_resolution_pixels), 15.0, 15.0),
        (BaseLimits::NONE, 100.0, 20.0),
    ];
    for (limits, crater_max, boulder_max) in cases {
        let cs = detail::craters(&d, &t, &limits);
        let bs = detail::boulders(&d, &t, &limits);
        assert!(!cs.is_empty() && !bs.is_empty());
        assert!(cs
            .iter()
            .all(|c| c.diameter_m <= crater_max && c.diameter_m >= 2.0));
        assert!(bs.iter().all(|b| b.diameter_m <= boulder_max));
        let biggest = cs.iter().map(|c| c.diameter_m).fold(0.0, f64::max);
        assert!(
            biggest > 0.5 * crater_max,
            "largest {biggest} of {crater_max}"
        );
    }
}

/// The pyramids change how far a ray jumps in the open, never where it meets the surface:
/// over a synthetic base with the detail tile and over the bare sphere with one, rays
/// from 5 m to 3 km hit (or miss) as the plain march does, to the refinement's tolerance.
#[test]
fn ray_casts_with_detail_agree_with_the_plain_march() {
    let specs = [
        TerrainSpec::Synthetic(base_synthetic(Some(small_detail(8)))),
        smooth_with(small_detail(8)),
    ];
    for spec in specs {
        let with = build(&spec, &site()).unwrap();
        let without = with.clone().without_pyramids();
        let (mut hits, mut in_tile) = (0, 0);
        for k in 0..1500 {
            let x = k as f64;
            let e = 160.0 * (0.713 * x).sin();
            let n = 160.0 * (0.377 * x).cos();
            let up = 5.0 + 3000.0 * (0.5 + 0.5 * (1.3 * x).sin()).powi(3);
            let origin = with.map().site_of_map(e, n, with.elevation_m(e, n) + up);
            let (off, az) = (75f64.to_radians() * (0.5 + 0.5 * (2.1 * x).sin()), 0.9 * x);
            let dir = Vector3::new(off.sin() * az.cos(), off.sin() * az.sin(), -off.cos());
            let a = with.ray_cast(&origin, &dir, 20_000.0);
            let b = without.ray_cast(&origin, &dir, 20_000.0);
            match (a, b) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!(
                        (a.range_m - b.range_m).abs() <= 2.0 * RANGE_TOL_M,
                        "ray {k}: {} against {}",
                        a.range_m,
                        b.range_m
                    );
                    let (he, hn) = with.map_of_site(&a.point_site);
                    if he.abs() < 140.0 && hn.abs() < 140.0 {
                        in_tile += 1;
                        // The hit is on the detailed surface.
                        let h = with.height_above_surface_m(&a.point_site);
                        assert!(h <= 1e-6 && h > -1e-3, "ray {k}: {h} off the surface");
                    }
                }
                (None, None) => {}
                (a, b) => panic!("ray {k}: {a:?} against {b:?}"),
            }
        }
        println!("{hits} hits, {in_tile} in the tile");
        assert!(
            hits > 1400 && in_tile > 300,
            "{hits} hits, {in_tile} in the tile"
        );
    }
}

/// `[terrain.detail]` parses under any kind, refuses unknown keys and bad numbers, and
/// leaves the spec's hash (the cache key) of a terrain without detail unchanged.
#[test]
fn detail_spec_parses_validates_and_keeps_old_hashes() {
    #[derive(serde::Deserialize)]
    struct Doc {
        terrain: TerrainSpec,
    }
    let doc: Doc = toml::from_str(
        "[terrain]\nkind = \"synthetic\"\nseed = 2\n[terrain.detail]\nseed = 5\nextent_m = 800.0\n",
    )
    .unwrap();
    let d = doc.terrain.detail().unwrap();
    assert_eq!((d.seed, d.extent_m, d.spacing_m), (5, 800.0, 0.5));
    let doc: Doc = toml::from_str("[terrain]\nkind = \"smooth\"\n[terrain.detail]\n").unwrap();
    assert_eq!(doc.terrain, smooth_with(DetailSpec::default()));
    assert!(!doc.terrain.is_bare_sphere());
    let doc: Doc = toml::from_str("[terrain]\nkind = \"smooth\"\n").unwrap();
    assert!(doc.terrain.is_bare_sphere());
    assert!(
        toml::from_str::<Doc>("[terrain]\nkind = \"smooth\"\n[terrain.detail]\nsed = 1\n").is_err()
    );
    assert!(toml::from_str::<Doc>("[terrain]\nkind = \"smooth\"\nextent_m = 1.0\n").is_err());
    for (bad, field) in [
        (
            DetailSpec {
                spacing_m: 0.0,
                ..DetailSpec::default()
            },
            "detail.spacing_m",
        ),
        (
            DetailSpec {
                extent_m: 4000.0,
                spacing_m: 0.25,
                ..DetailSpec::default()
            },
            "",
        ),
        (
            DetailSpec {
                crater_max_diameter_m: 1.0,
                ..DetailSpec::default()
            },
            "detail.crater_max_diameter_m",
        ),
        (
            DetailSpec {
                degraded_fraction: 1.5,
                ..DetailSpec::default()
            },
            "detail.degraded_fraction",
        ),
        (
            DetailSpec {
                rock_abundance: f64::NAN,
                ..DetailSpec::default()
            },
            "detail.rock_abundance",
        ),
    ] {
        match smooth_with(bad).validate() {
            Err(TerrainError::InvalidSpec { field: f, .. }) => assert_eq!(f, field),
            Err(TerrainError::GridTooLarge { .. }) => assert_eq!(field, ""),
            other => panic!("{field}: {other:?}"),
        }
    }
    // The JSON a spec without detail hashes is the one it hashed before the layer existed.
    let json = serde_json::to_string(&TerrainSpec::default()).unwrap();
    assert_eq!(json, r#"{"kind":"smooth"}"#);
    let json = serde_json::to_string(&TerrainSpec::Synthetic(SyntheticSpec::default())).unwrap();
    assert!(!json.contains("detail"), "{json}");
}

/// The default layer over the default synthetic base: its size, and where its memory goes.
#[test]
fn default_layer_over_the_default_base_builds_within_its_memory_budget() {
    let spec = TerrainSpec::Synthetic(SyntheticSpec {
        detail: Some(DetailSpec::default()),
        ..SyntheticSpec::default()
    });
    let t0 = std::time::Instant::now();
    let t = build(&spec, &site()).unwrap();
    let tile = t.detail_grid().unwrap();
    let nodes = tile.nx() * tile.ny();
    // Heights (f64) plus the pyramid (two f32 a tile over every level: 4/3 of 8 B).
    let bytes = nodes as f64 * (8.0 + 8.0 * 4.0 / 3.0);
    println!(
        "tile {} x {} at {} m: {:.1} MB, built in {:.2?} (with the base)",
        tile.nx(),
        tile.ny(),
        tile.spacing_m(),
        bytes / 1e6,
        t0.elapsed()
    );
    assert!(bytes < 200e6);
    assert_eq!(tile.spacing_m(), 0.5);
    let (e0, e1, _, _) = tile.bounds_m();
    assert!(e1 - e0 >= 1000.0 && e1 - e0 < 1004.0);
    assert!(t.max_elevation_m() >= t.grid().unwrap().elevation_range_m().1);
}

/// The committed `pinpoint` scenario: the default descent over a synthetic base with the
/// detail layer about the site, and the Chandrayaan-3 landing sun.
#[test]
fn pinpoint_scenario_carries_the_detail_layer() {
    let s = oils_emulator::run_config::load_scenario("pinpoint").unwrap();
    s.validate().unwrap();
    assert!(matches!(s.terrain, TerrainSpec::Synthetic(_)));
    let d = s.terrain.detail().expect("a detail layer");
    assert_eq!((d.extent_m, d.spacing_m), (1000.0, 0.5));
    assert_eq!(
        s.sun.epoch_utc.as_deref(),
        Some(oils_emulator::world::sun::DEFAULT_EPOCH_UTC)
    );
    let default = oils_emulator::run_config::load_scenario("default").unwrap();
    assert!(default.terrain.is_bare_sphere() && default.sun.is_default());
}

/// A detail tile on a GeoTIFF DTM (a polar stereographic file this test writes, 10 m
/// pixels about the south pole): the file's grid is untouched, the tile's spacing is a
/// whole fraction of it, the surface outside the tile is the file's, and the build caps
/// features at `base_resolution_pixels` pixels: asking for craters up to 100 m or up to
/// 3 pixels (30 m) gives the same tile, bit for bit, where over the bare sphere it does
/// not.
#[test]
fn over_a_geotiff_dtm_the_detail_stays_below_its_resolution() {
    use oils_emulator::world::terrain::GeoTiffSpec;
    use tiff::encoder::{colortype, TiffEncoder};
    use tiff::tags::Tag;
    let dir = std::env::temp_dir().join(format!("oils-detail-dtm-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("pole.tif");
    let (w, h) = (600u32, 600u32);
    let data: Vec<f32> = (0..h)
        .flat_map(|r| {
            (0..w).map(move |c| {
                let (x, y) = (c as f32 * 10.0 - 3000.0, 3000.0 - r as f32 * 10.0);
                0.01 * x + 5.0 * (x / 300.0).sin() * (y / 200.0).cos()
            })
        })
        .collect();
    {
        let file = std::fs::File::create(&path).unwrap();
        let mut enc = TiffEncoder::new(file).unwrap();
        let mut img = enc.new_image::<colortype::Gray32Float>(w, h).unwrap();
        let d = img.encoder();
        d.write_tag(Tag::ModelPixelScaleTag, &[10.0f64, 10.0, 0.0][..])
            .unwrap();
        d.write_tag(
            Tag::ModelTiepointTag,
            &[0.0f64, 0.0, 0.0, -3005.0, 3005.0, 0.0][..],
        )
        .unwrap();
        // Projected, PixelIsArea, sphere R, polar stereographic (15) about -90, scale 1.
        let keys: [u16; 36] = [
            1, 1, 0, 8, 1024, 0, 1, 1, 1025, 0, 1, 1, 2057, 34736, 1, 0, 2058, 34736, 1, 1, 3075,
            0, 1, 15, 3081, 34736, 1, 2, 3095, 34736, 1, 3, 3092, 34736, 1, 4,
        ];
        d.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
        d.write_tag(Tag::GeoDoubleParamsTag, &[R_M, R_M, -90.0, 0.0, 1.0][..])
            .unwrap();
        img.write_data(&data).unwrap();
    }
    let site = SiteFrame::from_deg(-89.97, 0.0, R_M);
    let geo = |detail: Option<DetailSpec>| {
        TerrainSpec::Geotiff(GeoTiffSpec {
            path: path.clone(),
            extent_m: 1500.0,
            spacing_m: None,
            height_scale: None,
            height_offset_m: None,
            detail,
        })
    };
    let tile_spec = |max: f64| DetailSpec {
        extent_m: 400.0,
        crater_max_diameter_m: max,
        boulder_max_diameter_m: max,
        rock_abundance: 0.2,
        ..small_detail(12)
    };
    let plain = build(&geo(None), &site).unwrap_or_else(|e| panic!("{e}"));
    let a = build(&geo(Some(tile_spec(100.0))), &site).unwrap();
    assert_eq!(a.grid(), plain.grid());
    let base_spacing = plain.grid().unwrap().spacing_m();
    let tile = a.detail_grid().unwrap();
    let ratio = base_spacing / tile.spacing_m();
    println!(
        "DTM spacing {base_spacing} m, tile spacing {} m",
        tile.spacing_m()
    );
    assert!((ratio - ratio.round()).abs() < 1e-9 && tile.spacing_m() <= 0.5);
    assert!(
        (3.0 * base_spacing - 30.0).abs() < 0.5,
        "pixel {base_spacing}"
    );
    let (e0, e1, n0, _) = tile.bounds_m();
    for (e, n) in [(e0 - 0.5, n0 - 0.5), (e1 + 3.0, 0.0), (0.0, n0 - 7.0)] {
        assert_eq!(a.elevation_m(e, n), plain.elevation_m(e, n));
    }
    // Asking for 100 m or for exactly the DTM's 3 pixels draws the same features.
    let cap = 3.0 * base_spacing;
    let c = build(&geo(Some(tile_spec(cap))), &site).unwrap();
    assert_eq!(a.detail_grid(), c.detail_grid());
    let sa = build(&smooth_with(tile_spec(100.0)), &site).unwrap();
    let sb = build(&smooth_with(tile_spec(cap)), &site).unwrap();
    assert_ne!(sa.detail_grid(), sb.detail_grid());
    std::fs::remove_dir_all(&dir).ok();
}

/// The base's bicubic refinement (Catmull-Rom, Keys' `a = -1/2`) goes through every node
/// and reproduces quadratic surfaces exactly away from the edge (third-order accurate).
#[test]
fn catmull_rom_refinement_interpolates_nodes_and_reproduces_quadratics() {
    let q =
        |e: f64, n: f64| 3.0 + 0.2 * e - 0.1 * n + 0.003 * e * e - 0.002 * e * n + 0.001 * n * n;
    let (side, s) = (41usize, 2.5);
    let h: Vec<f64> = (0..side * side)
        .map(|k| q(-50.0 + s * (k % side) as f64, -50.0 + s * (k / side) as f64))
        .collect();
    let g = oils_emulator::world::terrain::Grid::new(side, side, -50.0, -50.0, s, h).unwrap();
    for k in 0..500 {
        let x = k as f64;
        let (e, n) = (40.0 * (0.37 * x).sin(), 40.0 * (0.61 * x).cos());
        let got = detail::catmull_rom_m(&g, e, n);
        assert!(
            (got - q(e, n)).abs() < 1e-9,
            "({e}, {n}): {got} vs {}",
            q(e, n)
        );
    }
    for (i, j) in [(0, 0), (3, 7), (40, 40), (40, 0), (17, 23)] {
        let (e, n) = (-50.0 + s * i as f64, -50.0 + s * j as f64);
        assert_eq!(detail::catmull_rom_m(&g, e, n), g.at(i, j));
    }
}

/// Over a base whose spacing is just above the one asked for, the whole fraction is much
/// finer (0.51 m base, 0.5 m asked: 0.255 m): the node limit is checked on what is built.
#[test]
fn a_finer_aligned_spacing_still_respects_the_node_limit() {
    let base = SyntheticSpec {
        extent_m: 1500.0,
        spacing_m: 0.51,
        crater_min_diameter_m: 20.0,
        ..SyntheticSpec::default()
    };
    let fits = DetailSpec {
        extent_m: 600.0,
        ..small_detail(1)
    };
    let t = build(
        &TerrainSpec::Synthetic(SyntheticSpec {
            detail: Some(fits),
            ..base.clone()
        }),
        &site(),
    )
    .unwrap();
    assert!((t.detail_grid().unwrap().spacing_m() - 0.255).abs() < 1e-12);
    // 1400 m asked at 0.5 m passes validation (2801^2 < 8.4 M nodes) but 0.255 m is not.
    let too_fine = DetailSpec {
        extent_m: 1400.0,
        ..small_detail(1)
    };
    too_fine.validate().unwrap();
    let err = build(
        &TerrainSpec::Synthetic(SyntheticSpec {
            detail: Some(too_fine),
            ..base
        }),
        &site(),
    )
    .expect_err("too many nodes");
    assert!(matches!(err, TerrainError::GridTooLarge { .. }), "{err:?}");
}
