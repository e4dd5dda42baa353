//! `oils map`: the onboard terrain map for terrain-relative navigation, rendered offline
//! from a scenario's terrain by the camera's photometry under the scenario's sun, and
//! written with the camera's calibration as one file the reference GNC loads before
//! the descent (`--gnc-map`). The flight software never reads the emulator's terrain:
//! this file is all it knows of the ground (`docs/gnc.md`, "Terrain-relative
//! navigation").

use anyhow::{bail, Context, Result};
use oils_emulator::plant::ground::Ground;
use oils_emulator::run_config::load_scenario;
use oils_emulator::sensors::camera::ortho::{render_level, Reflectance};
use oils_emulator::sensors::camera::shadow::{ShadowMap, ShadowMapConfig};
use oils_emulator::world::sun::Sun;
use oils_emulator::world::terrain::SiteFrame;
use oils_onboard_stub::gnc::terrain_map::{MapFrame, MapLevel, TerrainMap};
use oils_onboard_stub::gnc::terrain_nav::CameraModel;
use std::path::PathBuf;
use std::time::Instant;

/// The default levels' spacings, m.
pub const DEFAULT_SPACINGS_M: [f64; 9] = [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0];

/// Arguments of `oils map`.
#[derive(Debug, clap::Args)]
pub struct MapArgs {
    /// The scenario whose terrain, sun and camera the map is for (a name such as
    /// `pinpoint`, or a scenario TOML).
    #[arg(long, default_value = "pinpoint")]
    pub scenario: String,
    /// The map file to write (`.oilsmap`).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Cell spacings of the levels, m, finest first (each `--cells` a side about the
    /// site: 0.5 m covers 512 m, 128 m covers 131 km; the coarse ones are for the
    /// first fix, searched over 1.5 km).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0.5,1,2,4,8,16,32,64,128"
    )]
    pub spacings_m: Vec<f64>,
    /// Cells per side of every level.
    #[arg(long, default_value_t = 1024)]
    pub cells: u32,
    /// Render the map under another sun than the scenario's, `AZ,EL` in degrees
    /// (azimuth from north through east): a map made for another time of day.
    #[arg(
        long,
        value_name = "AZ,EL",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub sun_az_el: Option<Vec<f64>>,
    /// A wrong map, for testing the gates: within `R` m of map `(E, N)` the map shows
    /// what lies `(DE, DN)` m away, `E,N,R,DE,DN` (the `false-fix` failure scenario).
    #[arg(
        long,
        value_name = "E,N,R,DE,DN",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub shift_feature: Option<Vec<f64>>,
}

/// Runs `oils map`.
pub fn run(args: &MapArgs) -> Result<()> {
    if args.spacings_m.is_empty()
        || args.spacings_m.iter().any(|s| !(s.is_finite() && *s > 0.0))
        || args.spacings_m.windows(2).any(|w| w[1] <= w[0])
    {
        bail!("--spacings-m: positive spacings, finest first, each coarser than the one before");
    }
    if !(16..=8192).contains(&args.cells) {
        bail!("--cells {}: 16 to 8192 cells a side", args.cells);
    }
    if let Some(s) = &args.shift_feature {
        if s.len() != 5 || s.iter().any(|v| !v.is_finite()) || s[2] <= 0.0 {
            bail!("--shift-feature: five finite numbers E,N,R,DE,DN with R > 0");
        }
    }
    let sc = load_scenario(&args.scenario).context("--scenario")?;
    let (lat, lon, radius) = (
        sc.site.latitude_deg,
        sc.site.longitude_deg,
        sc.moon.radius_m,
    );
    let site = SiteFrame::from_deg(lat, lon, radius);
    let ground = Ground::new(&sc.terrain, lat, lon, radius).context("the scenario's terrain")?;
    let terrain = match &ground {
        Ground::Terrain { terrain, .. } => Some(terrain.clone()),
        Ground::Sphere { .. } => {
            eprintln!("oils map: the scenario's ground is the bare sphere: the map has no features to navigate by");
            None
        }
    };
    let sun = Sun::new(&sc.sun, &site).context("the scenario's sun")?;
    let (mut az, mut el) = sun.azimuth_elevation_deg(0);
    let mut sun_site = sun.sun_dir_site(0);
    if let Some(v) = &args.sun_az_el {
        if v.len() != 2 || !v[0].is_finite() || !(v[1] > 0.0 && v[1] <= 90.0) {
            bail!("--sun-az-el: AZ,EL in degrees with 0 < EL <= 90");
        }
        (az, el) = (v[0], v[1]);
        sun_site = oils_emulator::world::sun::dir_of_az_el(az, el);
    }
    let sun_mcmf = site.mcmf_dir_from_site(&sun_site);
    let started = Instant::now();
    let shadow = ShadowMap::build(&ground, &sun_mcmf, &ShadowMapConfig::default())
        .context("the shadow map")?;
    eprintln!(
        "oils map: shadow map in {:.1} s (sun azimuth {az:.2} deg, elevation {el:.2} deg)",
        started.elapsed().as_secs_f64()
    );
    let cam = &sc.sensors.camera;
    let refl = Reflectance {
        normal_albedo: cam.normal_albedo,
        shadow_floor_iof: cam.shadow_floor_iof,
    };
    let finest = terrain.as_ref().map_or(args.spacings_m[0], |t| {
        t.detail_grid()
            .or(t.grid())
            .map_or(args.spacings_m[0], |g| g.spacing_m())
    });
    let mut levels = Vec::with_capacity(args.spacings_m.len());
    for (k, &s) in args.spacings_m.iter().enumerate() {
        let t0 = Instant::now();
        let mut l = render_level(
            terrain.as_deref(),
            Some(&shadow),
            &sun_site,
            refl,
            s,
            args.cells,
            finest,
        );
        if let Some(v) = &args.shift_feature {
            shift_feature(&mut l.iof, l.e0_m, l.n0_m, s, l.width as usize, v);
        }
        eprintln!(
            "oils map: level {k}: {s} m, {} x {} cells ({:.0} m a side) in {:.1} s",
            l.width,
            l.height,
            s * l.width as f64,
            t0.elapsed().as_secs_f64()
        );
        levels.push(MapLevel {
            spacing_m: l.spacing_m,
            e0_m: l.e0_m,
            n0_m: l.n0_m,
            width: l.width,
            height: l.height,
            iof: l.iof,
            height_m: l.height_m,
        });
    }
    let map = TerrainMap {
        frame: MapFrame::new(lat, lon, radius),
        sun_azimuth_deg: az,
        sun_elevation_deg: el,
        camera: CameraModel {
            width_px: cam.width_px,
            height_px: cam.height_px,
            fov_deg: cam.fov_deg,
            k1: cam.k1,
            k2: cam.k2,
            boresight_body: cam.boresight_body,
            image_right_body: cam.image_right_body,
            position_body_m: cam.position_body_m,
            full_scale_dn: u16::try_from((1u32 << cam.bits.min(16)) - 1).unwrap_or(u16::MAX),
        },
        levels,
    };
    map.write(&args.out)?;
    let bytes = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    println!(
        "map {} ({} levels, {:.1} MB, {:.1} s; camera {} x {})",
        args.out.display(),
        map.levels.len(),
        bytes as f64 / 1e6,
        started.elapsed().as_secs_f64(),
        cam.width_px,
        cam.height_px
    );
    Ok(())
}

/// Within radius `v[2]` of map `(v[0], v[1])`, the cells show what lies `(v[3], v[4])`
/// away (nearest cell of the same level; outside the level, unchanged).
fn shift_feature(iof: &mut [f32], e0: f64, n0: f64, s: f64, n: usize, v: &[f64]) {
    let src = iof.to_vec();
    let (de, dn) = ((v[3] / s).round() as i64, (v[4] / s).round() as i64);
    for i in 0..n {
        for j in 0..n {
            let (e, nn) = (e0 + j as f64 * s, n0 + i as f64 * s);
            if (e - v[0]).hypot(nn - v[1]) > v[2] {
                continue;
            }
            let (si, sj) = (i as i64 + dn, j as i64 + de);
            if si >= 0 && sj >= 0 && (si as usize) < n && (sj as usize) < n {
                iof[i * n + j] = src[si as usize * n + sj as usize];
            }
        }
    }
}
