//! Writes the navigation camera's frames (and the flash lidar's range images) over the
//! default synthetic surface (10 km wide), at 5 km, 1 km, 100 m and 10 m above it, as 8-bit PNGs,
//! and prints each frame's render time (wall clock: this is a tool, not the loop).
//!
//! `cargo run --release -p oils-emulator --example camera_frames -- DIR [half]`
//! (`half`: the camera's PNGs binned 2 x 2 to 512 x 512, as committed in `docs/img/`).
//!
//! Geometry (assumed, as a terminal descent's): the boresight 15 deg off nadir towards
//! north, the sun 12 deg above the horizon at azimuth 100 deg, the camera over the
//! point 15 deg up-track of the site.

use nalgebra::Vector3;
use oils_emulator::plant::ground::Ground;
use oils_emulator::sensors::camera::{looking_along, still_truth, ShadowMap, ShadowMapConfig};
use oils_emulator::sensors::{Camera, CameraConfig, Lidar, LidarConfig};
use oils_emulator::world::terrain::{SiteFrame, SyntheticSpec, TerrainSpec};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

const R_M: f64 = 1_737_400.0;

/// CPU time of this thread so far, ns (Linux `/proc/thread-self/schedstat`; 0 elsewhere):
/// the cost on one core, apart from waiting for it on a loaded machine.
fn thread_cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

fn write_png(path: &Path, w: u32, h: u32, gray: &[u8]) -> Result<(), Box<dyn std::error::Error>> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut enc = png::Encoder::new(file, w, h);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()?.write_image_data(gray)?;
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "frames".into()));
    let half = std::env::args().nth(2).as_deref() == Some("half");
    std::fs::create_dir_all(&dir)?;
    let (lat, lon) = (-69.373, 32.319);
    let site = SiteFrame::from_deg(lat, lon, R_M);
    // The default synthetic surface, widened from 4 km to 10 km so the 5 km view (4.1 km
    // across) stays on it.
    let spec = TerrainSpec::Synthetic(SyntheticSpec {
        extent_m: 10_000.0,
        ..SyntheticSpec::default()
    });
    let ground = Ground::new(&spec, lat, lon, R_M)?;
    let Ground::Terrain { terrain, .. } = &ground else {
        unreachable!()
    };
    let [east, north, up] = site.axes_mcmf();
    let (el, az) = (12f64.to_radians(), 100f64.to_radians());
    let sun = site.mcmf_dir_from_site(&Vector3::new(
        el.cos() * az.sin(),
        el.cos() * az.cos(),
        el.sin(),
    ));
    let tilt = 15f64.to_radians();
    let q = looking_along(&(-up * tilt.cos() + north * tilt.sin()), &east);
    let t0 = Instant::now();
    let map = Arc::new(ShadowMap::build(
        &ground,
        &sun,
        &ShadowMapConfig::default(),
    )?);
    println!(
        "shadow map: {:.0} ms, {} MB",
        t0.elapsed().as_secs_f64() * 1e3,
        map.bytes() >> 20
    );
    let cfg = CameraConfig {
        enabled: true,
        ..CameraConfig::default()
    };
    let mut cam = Camera::new(&cfg, 1)?;
    cam.set_shadow_map(Some(map));
    let mut frame = vec![0u8; cam.frame_bytes()];
    let mut lidar = Lidar::new(
        &LidarConfig {
            enabled: true,
            ..LidarConfig::default()
        },
        1,
    )?;
    let mut range = vec![0u8; lidar.frame_bytes()];
    for (name, h) in [
        ("5km", 5000.0),
        ("1km", 1000.0),
        ("100m", 100.0),
        ("10m", 10.0),
    ] {
        let (e, n) = (-h * tilt.tan(), 0.0);
        let p = site.mcmf_from_site(&terrain.map().site_of_map(
            e,
            n,
            terrain.elevation_m(e, n) + h,
        ));
        let truth = still_truth(&ground, &p, &q, 0);
        let t = Instant::now();
        let cpu = thread_cpu_ns();
        let meta = cam.render(&truth, &sun, &mut frame)?;
        let cpu_ms = (thread_cpu_ns() - cpu) as f64 * 1e-6;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let stats = cam.last_stats();
        println!(
            "camera {name}: {ms:.0} ms wall, {cpu_ms:.0} ms CPU, {} nodes, {} fallback px, {} sky, {} saturated",
            stats.nodes, stats.fallback_pixels, stats.sky_pixels, meta.saturated_pixels
        );
        // 12 bits to 8 with a square-root stretch, so dark ground shows.
        let max = cam.detector().max_dn as f64;
        let gray: Vec<u8> = frame
            .chunks_exact(2)
            .map(|b| ((u16::from_le_bytes([b[0], b[1]]) as f64 / max).sqrt() * 255.0).round() as u8)
            .collect();
        if half {
            let (w, h) = (meta.width as usize / 2, meta.height as usize / 2);
            let full_w = meta.width as usize;
            let binned: Vec<u8> = (0..w * h)
                .map(|k| {
                    let (x, y) = (2 * (k % w), 2 * (k / w));
                    let sum: u32 = [0, 1, full_w, full_w + 1]
                        .iter()
                        .map(|d| gray[y * full_w + x + d] as u32)
                        .sum();
                    ((sum + 2) / 4) as u8
                })
                .collect();
            write_png(
                &dir.join(format!("camera-{name}.png")),
                w as u32,
                h as u32,
                &binned,
            )?;
        } else {
            write_png(
                &dir.join(format!("camera-{name}.png")),
                meta.width,
                meta.height,
                &gray,
            )?;
        }
        let cpu = thread_cpu_ns();
        let lmeta = lidar.render(&truth, &mut range)?;
        let lms = (thread_cpu_ns() - cpu) as f64 * 1e-6;
        let ranges: Vec<f32> = range
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let (lo, hi) = ranges
            .iter()
            .filter(|r| **r > 0.0)
            .fold((f32::MAX, 0f32), |(lo, hi), r| (lo.min(*r), hi.max(*r)));
        let (lo, hi) = if hi > 0.0 { (lo, hi) } else { (0.0, 0.0) };
        println!(
            "lidar {name}: {lms:.1} ms, {} no-return, range {lo:.2}..{hi:.2} m",
            lmeta.empty_pixels
        );
        let gray: Vec<u8> = ranges
            .iter()
            .map(|r| {
                if *r > 0.0 {
                    (255.0 * (hi - r) / (hi - lo).max(1e-6)) as u8
                } else {
                    0
                }
            })
            .collect();
        write_png(
            &dir.join(format!("lidar-{name}.png")),
            lmeta.width,
            lmeta.height,
            &gray,
        )?;
    }
    Ok(())
}
