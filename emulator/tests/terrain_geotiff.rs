//! GeoTIFF DEMs written by GDAL (an outside tool) about the Chandrayaan-3 site, checked
//! against the analytic surface they were written from. Run by `tools/terrain-e2e.sh`,
//! which makes the files and sets the environment:
//!   `cargo test --release -p oils-emulator --test terrain_geotiff -- --ignored`
//! Without the environment the test says so and returns (a plain `cargo test` skips it
//! as ignored and never needs GDAL).

use nalgebra::Vector3;
use oils_emulator::world::terrain::geotiff::{FileProjection, GeoDem};
use oils_emulator::world::terrain::{
    build, DetailSpec, GeoTiffSpec, SiteFrame, TerrainError, TerrainSpec,
};
use std::path::PathBuf;

const R_M: f64 = 1_737_400.0;

/// The surface the script wrote, in map metres from the raster's centre.
fn analytic_h(dx: f64, dy: f64) -> f64 {
    100.0 + 0.01 * dx - 0.02 * dy + 1e-5 * dx * dy
}

fn numbers(var: &str) -> Option<Vec<f64>> {
    let s = std::env::var(var).ok()?;
    s.split_whitespace().map(|x| x.parse().ok()).collect()
}

struct Case {
    file: &'static str,
    /// PROJ's map coordinates of the site, and the raster's centre.
    site_xy: (f64, f64),
    centre_xy: (f64, f64),
    /// Height tolerance of the file's own samples (f32 rounding, or int16 counts).
    sample_tol_m: f64,
}

/// Local map points about the site, m (inside both rasters).
fn probe_points() -> Vec<(f64, f64)> {
    let mut v = Vec::new();
    for i in -4..=4 {
        for j in -4..=4 {
            v.push((173.3 * i as f64 + 0.37, 151.9 * j as f64 - 0.21));
        }
    }
    v
}

#[test]
#[ignore = "needs GDAL-made files: run tools/terrain-e2e.sh"]
fn gdal_dems_match_the_analytic_surface_and_proj() {
    let (Some(dir), Some(site), Some(st), Some(eq)) = (
        std::env::var("OILS_TERRAIN_E2E_DIR").ok(),
        numbers("OILS_TERRAIN_E2E_SITE"),
        numbers("OILS_TERRAIN_E2E_STERE"),
        numbers("OILS_TERRAIN_E2E_EQC"),
    ) else {
        eprintln!(
            "terrain_geotiff: OILS_TERRAIN_E2E_* not set; run tools/terrain-e2e.sh (skipped)"
        );
        return;
    };
    let dir = PathBuf::from(dir);
    let frame = SiteFrame::from_deg(site[0], site[1], R_M);
    let cases = [
        Case {
            file: "stere.tif",
            site_xy: (st[0], st[1]),
            centre_xy: (st[2], st[3]),
            sample_tol_m: 1e-4 * 150.0, // f32 ulp at ~150 m is 1.5e-5 m; margin x1000
        },
        Case {
            file: "eqc.tif",
            site_xy: (eq[0], eq[1]),
            centre_xy: (eq[2], eq[3]),
            sample_tol_m: 0.025 + 1e-9, // half an int16 count of 0.05 m
        },
    ];

    for c in &cases {
        let path = dir.join(c.file);
        let dem = GeoDem::open(&path).unwrap_or_else(|e| panic!("{e}"));
        // The site mapping agrees with PROJ's (gdaltransform prints to 1e-6 m).
        let (x, y) = dem
            .projection()
            .forward(frame.lat_rad, frame.lon_rad)
            .expect("site projects");
        assert!(
            (x - c.site_xy.0).abs() < 1e-5 && (y - c.site_xy.1).abs() < 1e-5,
            "{}: site at ({x}, {y}), PROJ says {:?}",
            c.file,
            c.site_xy
        );
        match (c.file, dem.projection()) {
            ("stere.tif", FileProjection::Stereographic { lat0_rad, k0, .. }) => {
                assert_eq!(*lat0_rad, (-90f64).to_radians());
                assert_eq!(*k0, 1.0);
            }
            ("eqc.tif", FileProjection::Equirectangular { lat_ts_rad, .. }) => {
                assert_eq!(*lat_ts_rad, 0.0);
            }
            (f, p) => panic!("{f}: unexpected projection {p:?}"),
        }

        // Heights from the file at each probe's latitude/longitude, and from the
        // resampled terrain at the probe's map point, against the analytic surface.
        let spec = TerrainSpec::Geotiff(GeoTiffSpec {
            path: path.clone(),
            extent_m: 2000.0,
            spacing_m: None,
            height_scale: None,
            height_offset_m: None,
            detail: None,
        });
        let terrain = build(&spec, &frame).unwrap_or_else(|e| panic!("{e}"));
        let grid = terrain.grid().expect("a grid");

        // A detail tile on the DTM: the file's grid is untouched, the tile's nodes include
        // its nodes (a whole fraction of its spacing), and outside the tile the surface is
        // the file's.
        let TerrainSpec::Geotiff(base_spec) = &spec else {
            unreachable!()
        };
        let with_detail = TerrainSpec::Geotiff(GeoTiffSpec {
            detail: Some(DetailSpec {
                extent_m: 400.0,
                ..DetailSpec::default()
            }),
            ..base_spec.clone()
        });
        let detailed = build(&with_detail, &frame).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(detailed.grid(), terrain.grid());
        let tile = detailed.detail_grid().expect("a tile");
        let ratio = grid.spacing_m() / tile.spacing_m();
        assert!((ratio - ratio.round()).abs() < 1e-9 && tile.spacing_m() <= 0.5);
        let (e0, e1, n0, _) = tile.bounds_m();
        for (e, n) in [(e0 - 0.5, n0 - 0.5), (e1 + 3.0, 0.0), (0.0, n0 - 7.0)] {
            assert_eq!(detailed.elevation_m(e, n), terrain.elevation_m(e, n));
        }
        assert_ne!(
            detailed.elevation_m(10.0, 10.0),
            terrain.elevation_m(10.0, 10.0)
        );
        println!(
            "{}: {} x {} nodes at {:.3} m, range {:?} m",
            c.file,
            grid.nx(),
            grid.ny(),
            grid.spacing_m(),
            grid.elevation_range_m()
        );
        let mut worst = (0.0f64, 0.0f64);
        for (e, n) in probe_points() {
            let p = terrain.map().site_of_map(e, n, 0.0);
            let (lat, lon) = frame.lat_lon_of_site(&p);
            let (x, y) = dem.projection().forward(lat, lon).unwrap();
            let want = analytic_h(x - c.centre_xy.0, y - c.centre_xy.1);
            let from_file = dem.elevation_at_lat_lon(lat, lon).expect("covered");
            let from_terrain = terrain.elevation_m(e, n);
            worst.0 = worst.0.max((from_file - want).abs());
            worst.1 = worst.1.max((from_terrain - want).abs());
            assert!(
                (from_file - want).abs() <= c.sample_tol_m,
                "{}: file height at ({e}, {n}) is {from_file}, analytic {want}",
                c.file
            );
            // Resampling adds the bilinear error of the map's rotation against the
            // file's grid (h_ee s^2 / 8 with h_ee ~ 1e-5 /m, s ~ 20 m: ~5e-4 m).
            assert!(
                (from_terrain - want).abs() <= c.sample_tol_m + 2e-3,
                "{}: terrain height at ({e}, {n}) is {from_terrain}, analytic {want}",
                c.file
            );
            // A point 10 m above the surface there is 10 m above it.
            let q = terrain.map().site_of_map(e, n, from_terrain + 10.0);
            assert!((terrain.height_above_surface_m(&q) - 10.0).abs() < 1e-6);
        }
        println!(
            "{}: worst height error: file {:.2e} m, resampled terrain {:.2e} m",
            c.file, worst.0, worst.1
        );
        // Straight down from 500 m above the site: range to the analytic height.
        let h0 = terrain.elevation_m(0.0, 0.0);
        let hit = terrain
            .ray_cast(&Vector3::new(0.0, 0.0, h0 + 500.0), &-Vector3::z(), 1000.0)
            .expect("hits");
        assert!((hit.range_m - 500.0).abs() < 1e-5, "range {}", hit.range_m);
    }

    // No-data: the eqc file's first row starts with five no-data pixels.
    let eqc = GeoDem::open(&dir.join("eqc.tif")).unwrap();
    assert_eq!(eqc.elevation_at_pixel(2.0, 0.0), None);
    let below = eqc.elevation_at_pixel(2.0, 1.0).expect("row 1 is valid");
    assert_eq!(eqc.elevation_at_pixel(2.0, 0.5), Some(below));

    // A scale and offset given in the spec override the file's: 0.1 m per count and no
    // offset make every height 2 (h - 90).
    let scaled = GeoDem::open_with(&dir.join("eqc.tif"), Some(0.1), Some(0.0)).unwrap();
    for (c, r) in [(10.0, 10.0), (80.5, 33.25), (150.0, 159.0)] {
        let h = eqc.elevation_at_pixel(c, r).unwrap();
        let h2 = scaled.elevation_at_pixel(c, r).unwrap();
        assert!((h2 - 2.0 * (h - 90.0)).abs() < 1e-9, "{h2} vs {h}");
    }

    // Files the reader refuses, each naming the file.
    for (file, want) in [
        ("stere-zstd.tif", "compress"),
        ("no-georef.tif", "georeference"),
    ] {
        let path = dir.join(file);
        let err = GeoDem::open(&path).expect_err(file);
        let msg = err.to_string();
        println!("{file}: {msg}");
        assert!(msg.contains(file), "{msg}");
        assert!(msg.to_lowercase().contains(want), "{msg}");
        if file == "no-georef.tif" {
            assert!(
                matches!(err, TerrainError::MissingGeoreference { .. }),
                "{err:?}"
            );
        }
    }

    // A site outside the raster.
    let far = SiteFrame::from_deg(-60.0, 32.319, R_M);
    let spec = TerrainSpec::Geotiff(GeoTiffSpec {
        path: dir.join("stere.tif"),
        extent_m: 1000.0,
        spacing_m: None,
        height_scale: None,
        height_offset_m: None,
        detail: None,
    });
    let err = build(&spec, &far).expect_err("outside");
    assert!(
        matches!(err, TerrainError::SiteNotCovered { .. }),
        "{err:?}"
    );
    println!("outside: {err}");
}
