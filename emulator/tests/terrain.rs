//! Terrain geometry against closed forms: the site frame, the map projection, bilinear
//! interpolation, normals and slopes of planes, ray casts on planes and spheres, and the
//! seeded synthetic surface (determinism, crater statistics, slope).

use nalgebra::{Matrix3, Vector3};
use oils_emulator::world::terrain::synthetic::{self, crater_profile_m, EJECTA_REACH_RADII};
use oils_emulator::world::terrain::{
    build, BoulderSpec, Grid, SiteFrame, SyntheticSpec, Terrain, TerrainCache, TerrainError,
    TerrainSpec,
};
use std::sync::Arc;

const R_M: f64 = 1_737_400.0;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// A grid of `f(e, n)` on `[-half, half]^2` at `spacing`.
fn grid_of(half: f64, spacing: f64, f: impl Fn(f64, f64) -> f64) -> Grid {
    let side = (2.0 * half / spacing).round() as usize + 1;
    let mut h = Vec::with_capacity(side * side);
    for j in 0..side {
        for i in 0..side {
            h.push(f(-half + spacing * i as f64, -half + spacing * j as f64));
        }
    }
    Grid::new(side, side, -half, -half, spacing, h).unwrap()
}

fn sites() -> [SiteFrame; 4] {
    [
        SiteFrame::from_deg(-69.373, 32.319, R_M), // Chandrayaan-3
        SiteFrame::from_deg(0.0, 0.0, R_M),
        SiteFrame::from_deg(89.9, -170.0, R_M),
        SiteFrame::from_deg(-20.5, 200.0, R_M),
    ]
}

#[test]
fn site_frame_round_trips_maps_the_site_to_origin_and_up_is_radial() {
    for f in sites() {
        let rot = f.rot_site_from_mcmf();
        assert!((rot * rot.transpose() - Matrix3::identity()).norm() < 1e-15);
        assert!(close(rot.determinant(), 1.0, 1e-15));
        assert!(f.site_from_mcmf(&f.origin_mcmf()).norm() < 1e-9);
        let up_mcmf = f.mcmf_dir_from_site(&Vector3::z());
        assert!((up_mcmf - f.origin_mcmf() / R_M).norm() < 1e-15);
        // East is horizontal in mcmf (no z) and points toward increasing longitude.
        let east = f.mcmf_dir_from_site(&Vector3::x());
        assert!(east.z.abs() < 1e-15);
        // 1 m east moves the longitude by 1 / (R cos(lat)); north, the latitude by 1 / R.
        let (_, lon0) = f.lat_lon_of_site(&Vector3::zeros());
        let (_, lon1) = f.lat_lon_of_site(&Vector3::new(1.0, 0.0, 0.0));
        let want = 1.0 / (R_M * f.lat_rad.cos());
        assert!(
            close(lon1 - lon0, want, 1e-6 * want),
            "{} vs {want}",
            lon1 - lon0
        );
        let (lat1, _) = f.lat_lon_of_site(&Vector3::new(0.0, 1.0, 0.0));
        assert!(close(lat1 - f.lat_rad, 1.0 / R_M, 1e-12));
        for p in [
            Vector3::new(123.4, -567.8, 910.1),
            Vector3::new(-3e4, 2e4, -150.0),
        ] {
            let back = f.site_from_mcmf(&f.mcmf_from_site(&p));
            assert!((back - p).norm() < 1e-8, "{back} vs {p}");
            let d = f.site_dir_from_mcmf(&f.mcmf_dir_from_site(&p));
            assert!((d - p).norm() < 1e-9);
        }
        let (lat, lon) = f.lat_lon_of_site(&Vector3::zeros());
        assert!(close(lat, f.lat_rad, 1e-12));
        let p = f.site_of_lat_lon(lat, lon);
        assert!(p.norm() < 1e-8);
    }
}

#[test]
fn map_projection_keeps_distance_from_the_site_and_round_trips() {
    let t = Terrain::smooth(R_M).unwrap();
    let m = t.map();
    for (e, n, h) in [(0.0, 0.0, 5.0), (1500.0, -700.0, -20.0), (-3e4, 4e4, 300.0)] {
        let p = m.site_of_map(e, n, h);
        let back = m.map_of_site(&p);
        assert!(
            close(back.e_m, e, 1e-8) && close(back.n_m, n, 1e-8),
            "{back:?}"
        );
        assert!(close(back.height_m, h, 1e-8));
        // Azimuthal equidistant: the angle at the centre times R is hypot(e, n).
        let c = p + Vector3::new(0.0, 0.0, R_M);
        let angle = c.xy().norm().atan2(c.z);
        assert!(close(angle * R_M, e.hypot(n), 1e-7));
        assert!(close(t.height_above_surface_m(&p), h, 1e-8));
    }
    // Radial up at (e, n) is the unit vector from the centre through the point.
    let u = m.up(2500.0, -1200.0);
    let c = m.site_of_map(2500.0, -1200.0, 0.0) + Vector3::new(0.0, 0.0, R_M);
    assert!((u - c / c.norm()).norm() < 1e-15);
    // Derivatives of up against central differences.
    let (du_de, du_dn) = m.up_derivatives(2500.0, -1200.0);
    let fd_e = (m.up(2500.5, -1200.0) - m.up(2499.5, -1200.0)) / 1.0;
    let fd_n = (m.up(2500.0, -1199.5) - m.up(2500.0, -1200.5)) / 1.0;
    assert!((du_de - fd_e).norm() < 1e-15 && (du_dn - fd_n).norm() < 1e-15);
}

#[test]
fn bilinear_is_exact_on_bilinear_data_and_clamps_outside() {
    let f = |e: f64, n: f64| 3.0 + 0.25 * e - 0.125 * n + 0.001 * e * n;
    let t = Terrain::new(Some(grid_of(100.0, 10.0, f)), f64::INFINITY).unwrap();
    for (e, n) in [
        (0.0, 0.0),
        (12.3, -45.6),
        (-99.9, 99.9),
        (100.0, -100.0),
        (33.3, 7.77),
    ] {
        assert!(close(t.elevation_m(e, n), f(e, n), 1e-12), "({e}, {n})");
    }
    // Outside: the edge value continues.
    assert!(close(t.elevation_m(250.0, 30.0), f(100.0, 30.0), 1e-12));
    assert!(close(
        t.elevation_m(-300.0, -300.0),
        f(-100.0, -100.0),
        1e-12
    ));
    // Smooth terrain is zero everywhere.
    let s = Terrain::smooth(R_M).unwrap();
    assert_eq!(s.elevation_m(1e4, -2e4), 0.0);
}

#[test]
fn normal_and_slope_of_a_tilted_plane() {
    let (a, b): (f64, f64) = (0.3, -0.2);
    let t = Terrain::new(
        Some(grid_of(200.0, 8.0, |e, n| a * e + b * n + 1.0)),
        f64::INFINITY,
    )
    .unwrap();
    let want = Vector3::new(-a, -b, 1.0).normalize();
    let slope = a.hypot(b).atan().to_degrees();
    for (e, n) in [(0.0, 0.0), (51.0, -77.0), (-150.5, 3.25)] {
        assert!((t.normal_site(e, n) - want).norm() < 1e-12);
        assert!(close(t.slope_deg(e, n), slope, 1e-10));
    }
    // On a sphere: the same plane's normal at the site is the flat one.
    let c = Terrain::new(Some(grid_of(200.0, 8.0, |e, n| a * e + b * n)), R_M).unwrap();
    assert!((c.normal_site(0.0, 0.0) - want).norm() < 1e-12);
    assert!(close(c.slope_deg(0.0, 0.0), slope, 1e-9));
    // The smooth sphere's normal is up, with zero slope.
    let s = Terrain::smooth(R_M).unwrap();
    assert!((s.normal_site(3000.0, -4000.0) - s.map().up(3000.0, -4000.0)).norm() < 1e-12);
    assert!(s.slope_deg(3000.0, -4000.0) < 1e-9);
}

#[test]
fn ray_on_a_tilted_plane_has_the_closed_form_range() {
    let (a, b, c0) = (0.15, 0.1, -2.0);
    let t = Terrain::new(
        Some(grid_of(2000.0, 10.0, |e, n| a * e + b * n + c0)),
        f64::INFINITY,
    )
    .unwrap();
    let rays = [
        (Vector3::new(0.0, 0.0, 100.0), Vector3::new(0.0, 0.0, -1.0)),
        (
            Vector3::new(10.0, -20.0, 300.0),
            Vector3::new(0.3, 0.2, -1.0),
        ),
        (
            Vector3::new(-500.0, 100.0, 50.0),
            Vector3::new(1.0, 0.0, -0.05),
        ),
        (Vector3::new(0.0, 0.0, 40.0), Vector3::new(0.7, 0.7, -0.1)),
    ];
    for (o, d) in rays {
        let u = d.normalize();
        let want = (a * o.x + b * o.y + c0 - o.z) / (u.z - a * u.x - b * u.y);
        let hit = t.ray_cast(&o, &d, 5000.0).unwrap_or_else(|| {
            panic!(
                "ray {:?} {:?} misses the plane at {want}",
                o.as_slice(),
                d.as_slice()
            )
        });
        assert!(close(hit.range_m, want, 1e-6), "{} vs {want}", hit.range_m);
        let p = o + u * want;
        assert!((hit.point_site - p).norm() < 2e-6);
        let nrm = Vector3::new(-a, -b, 1.0).normalize();
        assert!((hit.normal_site - nrm).norm() < 1e-12);
        let inc = (-u.dot(&nrm)).acos().to_degrees();
        assert!(close(hit.incidence_deg, inc, 1e-9));
        // Short of the plane: no hit.
        assert!(t.ray_cast(&o, &d, want - 0.01).is_none());
    }
}

/// The first intersection of a ray with the sphere about (0, 0, -R) of radius `r`.
fn sphere_range(o: &Vector3<f64>, u: &Vector3<f64>, r: f64) -> Option<f64> {
    let c = o + Vector3::new(0.0, 0.0, R_M);
    let b = c.dot(u);
    let disc = b * b - (c.norm_squared() - r * r);
    (disc >= 0.0).then(|| -b - disc.sqrt())
}

#[test]
fn ray_on_a_sphere_has_the_closed_form_range() {
    let smooth = Terrain::smooth(R_M).unwrap();
    // A flat DEM (h = 0 everywhere) on the finite sphere: the same sphere.
    let flat_dem = Terrain::new(Some(grid_of(30_000.0, 100.0, |_, _| 0.0)), R_M).unwrap();
    // A constant DEM, h = 25 m: a sphere of R + 25.
    let raised = Terrain::new(Some(grid_of(30_000.0, 100.0, |_, _| 25.0)), R_M).unwrap();
    let rays = [
        (Vector3::new(0.0, 0.0, 2000.0), Vector3::new(0.0, 0.0, -1.0)),
        (
            Vector3::new(100.0, 200.0, 2000.0),
            Vector3::new(0.5, -0.3, -1.0),
        ),
        (
            Vector3::new(-1000.0, 0.0, 300.0),
            Vector3::new(1.0, 0.2, -0.02),
        ),
    ];
    for (o, d) in rays {
        let u = d.normalize();
        for (t, r) in [(&smooth, R_M), (&flat_dem, R_M), (&raised, R_M + 25.0)] {
            let want = sphere_range(&o, &u, r).expect("the ray meets the sphere");
            let hit = t.ray_cast(&o, &d, 50_000.0).expect("hits");
            assert!(close(hit.range_m, want, 1e-6), "{} vs {want}", hit.range_m);
            let radial = (hit.point_site + Vector3::new(0.0, 0.0, R_M)).normalize();
            assert!((hit.normal_site - radial).norm() < 1e-9);
        }
    }
    // Horizontal from 100 m: the horizon is past, the ray leaves the sphere.
    let up = smooth.ray_cast(&Vector3::new(0.0, 0.0, 100.0), &Vector3::x(), 1e5);
    assert!(up.is_none());
}

#[test]
fn ray_does_not_tunnel_through_a_thin_rim() {
    // A one-node-wide ridge 10 m high on flat ground, spacing 2 m.
    let t = Terrain::new(
        Some(grid_of(
            500.0,
            2.0,
            |e, _| if e == 100.0 { 10.0 } else { 0.0 },
        )),
        f64::INFINITY,
    )
    .unwrap();
    // Nearly horizontal at 6 m: hits the ridge's near face, where h = 10 (1 - |e-100|/2).
    let o = Vector3::new(-400.0, 3.0, 6.0);
    let hit = t
        .ray_cast(&o, &Vector3::new(1.0, 0.0, -1e-4), 2000.0)
        .expect("hits the rim");
    let u = Vector3::new(1.0, 0.0, -1e-4).normalize();
    // Solve 6 + t uz = 10 (1 - (100 - (-400 + t ux)) / 2) for t.
    let want = (6.0 - 10.0 + 5.0 * (100.0 + 400.0)) / (5.0 * u.x - u.z);
    assert!(close(hit.range_m, want, 1e-6), "{} vs {want}", hit.range_m);
    // Up a grazing 0.5 deg ray that clears the ridge top by 0.5 m: no hit before 1 km.
    let over = t.ray_cast(&Vector3::new(-400.0, 0.0, 10.5), &Vector3::x(), 1000.0);
    assert!(over.is_none());
}

#[test]
fn ray_casts_agree_with_dense_sampling_on_a_cratered_surface() {
    let spec = SyntheticSpec {
        extent_m: 1000.0,
        spacing_m: 2.0,
        crater_min_diameter_m: 8.0,
        crater_max_diameter_m: 120.0,
        crater_density: 3.0,
        ..SyntheticSpec::default()
    };
    let t = build(
        &TerrainSpec::Synthetic(spec),
        &SiteFrame::from_deg(-69.373, 32.319, R_M),
    )
    .unwrap();
    for k in 0..24 {
        let az = k as f64 * 0.27;
        let dep = 0.02 + 0.04 * k as f64; // from grazing to steep
        let o = Vector3::new(-200.0 * az.cos(), -200.0 * az.sin(), 30.0);
        let d = Vector3::new(az.cos(), az.sin(), -dep);
        let u = d.normalize();
        let hit = t.ray_cast(&o, &d, 800.0);
        // Dense reference: the first sign change in 2 cm steps.
        let mut reference = None;
        let mut s = 0.0;
        while s <= 800.0 {
            if t.height_above_surface_m(&(o + u * s)) <= 0.0 {
                reference = Some(s);
                break;
            }
            s += 0.02;
        }
        match (hit, reference) {
            (Some(h), Some(r)) => assert!(
                h.range_m <= r + 1e-6 && h.range_m > r - 0.02 - 1e-6,
                "ray {k}: {} vs reference {r}",
                h.range_m
            ),
            (None, None) => {}
            (h, r) => panic!("ray {k}: cast {h:?} vs reference {r:?}"),
        }
    }
}

#[test]
fn ray_edge_cases() {
    let t = Terrain::smooth(R_M).unwrap();
    let o = Vector3::new(0.0, 0.0, 50.0);
    assert!(t.ray_cast(&o, &Vector3::z(), 1e4).is_none(), "upward");
    assert!(
        t.ray_cast(&o, &-Vector3::z(), 49.0).is_none(),
        "out of range"
    );
    assert!(
        t.ray_cast(&o, &Vector3::zeros(), 1e4).is_none(),
        "zero direction"
    );
    assert!(t
        .ray_cast(&o, &Vector3::new(f64::NAN, 0.0, -1.0), 1e4)
        .is_none());
    assert!(t
        .ray_cast(&Vector3::new(0.0, f64::INFINITY, 1.0), &-Vector3::z(), 1e4)
        .is_none());
    assert!(t.ray_cast(&o, &-Vector3::z(), f64::NAN).is_none());
    let under = t
        .ray_cast(&Vector3::new(0.0, 0.0, -1.0), &Vector3::z(), 10.0)
        .unwrap();
    assert_eq!(under.range_m, 0.0);
}

fn small_synthetic(seed: u64) -> SyntheticSpec {
    SyntheticSpec {
        seed,
        extent_m: 800.0,
        spacing_m: 2.0,
        crater_min_diameter_m: 6.0,
        crater_max_diameter_m: 100.0,
        boulders: Some(BoulderSpec {
            rock_abundance: 0.1,
            min_diameter_m: 1.0,
            max_diameter_m: 10.0,
        }),
        ..SyntheticSpec::default()
    }
}

#[test]
fn synthetic_surface_is_identical_for_a_seed_and_differs_across_seeds() {
    let site = SiteFrame::from_deg(-69.373, 32.319, R_M);
    let a = build(&TerrainSpec::Synthetic(small_synthetic(7)), &site).unwrap();
    let b = build(&TerrainSpec::Synthetic(small_synthetic(7)), &site).unwrap();
    let c = build(&TerrainSpec::Synthetic(small_synthetic(8)), &site).unwrap();
    let bits = |t: &Terrain| -> Vec<u64> {
        t.grid()
            .unwrap()
            .samples()
            .iter()
            .map(|h| h.to_bits())
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
    assert_ne!(bits(&a), bits(&c));
    // Boulders draw from their own stream: the craters do not move without them.
    let mut no_boulders = small_synthetic(7);
    no_boulders.boulders = None;
    assert_eq!(
        synthetic::craters(&no_boulders),
        synthetic::craters(&small_synthetic(7))
    );
    let plain = build(&TerrainSpec::Synthetic(no_boulders), &site).unwrap();
    let extra = a
        .grid()
        .unwrap()
        .samples()
        .iter()
        .zip(plain.grid().unwrap().samples());
    assert!(
        extra.clone().all(|(x, y)| x >= y),
        "boulders only add height"
    );
    assert!(
        extra.clone().any(|(x, y)| x > y),
        "some boulder is on the grid"
    );
}

#[test]
fn crater_counts_follow_the_size_frequency_distribution() {
    let spec = SyntheticSpec {
        seed: 3,
        extent_m: 4000.0,
        crater_min_diameter_m: 10.0,
        crater_max_diameter_m: 400.0,
        ..SyntheticSpec::default()
    };
    let craters = synthetic::craters(&spec);
    let half = synthetic::crater_half_side_m(&spec);
    let area = 4.0 * half * half;
    let c = synthetic::EQUILIBRIUM_C_PER_M2;
    for d in [10.0, 20.0, 40.0, 80.0, 160.0] {
        let n = craters.iter().filter(|k| k.diameter_m >= d).count() as f64;
        let want = c * area * (d.powf(-2.0) - 400f64.powf(-2.0));
        assert!(
            (n - want).abs() <= 4.0 * want.sqrt() + 1.0,
            "N(>{d} m) = {n}, SFD says {want:.1}"
        );
    }
    assert!(craters
        .iter()
        .all(|k| k.e_m.abs() <= half && k.n_m.abs() <= half));
}

#[test]
fn crater_profile_has_the_fresh_shape() {
    let s = SyntheticSpec::default();
    let d = 100.0;
    assert!(
        close(crater_profile_m(&s, d, 0.0), (0.04 - 0.2) * d, 1e-12),
        "floor"
    );
    assert!(
        close(crater_profile_m(&s, d, 50.0 - 1e-9), 0.04 * d, 1e-6),
        "rim inside"
    );
    assert!(
        close(crater_profile_m(&s, d, 50.0), 0.04 * d, 1e-12),
        "rim crest"
    );
    assert!(crater_profile_m(&s, d, 75.0) < 0.04 * d * 0.3);
    assert_eq!(crater_profile_m(&s, d, 0.5 * d * EJECTA_REACH_RADII), 0.0);
}

#[test]
fn regional_slope_tilts_the_grid_downhill_toward_its_azimuth() {
    let spec = SyntheticSpec {
        extent_m: 400.0,
        spacing_m: 4.0,
        crater_density: 0.0,
        regional_slope_deg: 8.0,
        slope_azimuth_deg: 90.0, // downhill toward east
        ..SyntheticSpec::default()
    };
    let t = build(
        &TerrainSpec::Synthetic(spec),
        &SiteFrame::from_deg(10.0, 20.0, R_M),
    )
    .unwrap();
    // On the sphere the map gradient is scaled by R / (R + h): 1e-6 here.
    let slope = t.slope_deg(13.0, -21.0);
    assert!(close(slope, 8.0, 1e-4), "{slope}");
    let drop = t.elevation_m(100.0, 0.0) - t.elevation_m(0.0, 0.0);
    assert!(close(drop, -100.0 * 8f64.to_radians().tan(), 1e-9));
}

#[test]
fn spec_parses_from_toml_validates_and_hashes() {
    #[derive(serde::Deserialize)]
    struct Doc {
        terrain: TerrainSpec,
    }
    let doc: Doc = toml::from_str(
        "[terrain]\nkind = \"synthetic\"\nseed = 42\nspacing_m = 2.0\nextent_m = 1000.0\n\
         [terrain.boulders]\nrock_abundance = 0.08\n",
    )
    .unwrap();
    let TerrainSpec::Synthetic(s) = &doc.terrain else {
        panic!("synthetic expected")
    };
    assert_eq!((s.seed, s.spacing_m), (42, 2.0));
    assert_eq!(s.boulders.as_ref().unwrap().rock_abundance, 0.08);
    doc.terrain.validate().unwrap();

    let smooth: Doc = toml::from_str("[terrain]\nkind = \"smooth\"\n").unwrap();
    assert_eq!(smooth.terrain, TerrainSpec::default());
    let geo: Doc = toml::from_str("[terrain]\nkind = \"geotiff\"\npath = \"dem.tif\"\n").unwrap();
    assert!(matches!(geo.terrain, TerrainSpec::Geotiff(ref g) if g.extent_m == 10_000.0));
    assert!(toml::from_str::<Doc>("[terrain]\nkind = \"synthetic\"\nsede = 1\n").is_err());
    assert!(toml::from_str::<Doc>("[terrain]\nkind = \"fractal\"\n").is_err());

    let bad = |f: fn(&mut SyntheticSpec)| {
        let mut s = SyntheticSpec::default();
        f(&mut s);
        TerrainSpec::Synthetic(s).validate().unwrap_err()
    };
    let e = bad(|s| s.spacing_m = -1.0);
    assert!(
        matches!(
            e,
            TerrainError::InvalidSpec {
                field: "spacing_m",
                ..
            }
        ),
        "{e}"
    );
    let e = bad(|s| s.extent_m = f64::NAN);
    assert!(
        matches!(
            e,
            TerrainError::InvalidSpec {
                field: "extent_m",
                ..
            }
        ),
        "{e}"
    );
    assert!(matches!(
        bad(|s| s.spacing_m = 0.01),
        TerrainError::GridTooLarge { .. }
    ));
    assert!(matches!(
        bad(|s| s.crater_max_diameter_m = 1.0),
        TerrainError::InvalidSpec {
            field: "crater_max_diameter_m",
            ..
        }
    ));
    assert!(matches!(
        bad(|s| s.regional_slope_deg = 75.0),
        TerrainError::InvalidSpec {
            field: "regional_slope_deg",
            ..
        }
    ));

    let a = TerrainSpec::Synthetic(small_synthetic(1));
    assert_eq!(
        a.spec_hash(),
        TerrainSpec::Synthetic(small_synthetic(1)).spec_hash()
    );
    assert_ne!(
        a.spec_hash(),
        TerrainSpec::Synthetic(small_synthetic(2)).spec_hash()
    );
    assert_ne!(a.spec_hash(), TerrainSpec::default().spec_hash());
}

#[test]
fn cache_builds_once_per_spec_and_site_and_shares_the_terrain() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Terrain>();
    send_sync::<TerrainCache>();
    let cache = TerrainCache::new();
    let site = SiteFrame::from_deg(-69.373, 32.319, R_M);
    let spec = TerrainSpec::Synthetic(small_synthetic(5));
    let a = cache.get_or_build(&spec, &site).unwrap();
    let b = cache.get_or_build(&spec, &site).unwrap();
    assert!(Arc::ptr_eq(&a, &b));
    let other = SiteFrame::from_deg(-69.0, 32.319, R_M);
    let c = cache.get_or_build(&spec, &other).unwrap();
    assert!(!Arc::ptr_eq(&a, &c));
    assert_eq!(cache.len(), 2);
    let bad = TerrainSpec::Synthetic(SyntheticSpec {
        spacing_m: 0.0,
        ..SyntheticSpec::default()
    });
    assert!(cache.get_or_build(&bad, &site).is_err());
    assert_eq!(cache.len(), 2);
    assert!(matches!(
        build(
            &TerrainSpec::default(),
            &SiteFrame::from_deg(95.0, 0.0, R_M)
        ),
        Err(TerrainError::InvalidSite(_))
    ));
}
