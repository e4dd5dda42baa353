//! The flash lidar against analytic intersections (`docs/sensors.md`, "Flash lidar"):
//! a plane, the smooth Moon (a sphere) and a box-shaped boulder; no return beyond the
//! maximum range; bit-identical frames.

mod eyes_common;

use eyes_common::{flat_world, plane, site, R_M};
use nalgebra::Vector3;
use oils_emulator::plant::ground::Ground;
use oils_emulator::sensors::camera::{looking_along, still_truth};
use oils_emulator::sensors::{Lidar, LidarConfig};

fn quiet() -> LidarConfig {
    LidarConfig {
        enabled: true,
        noise: false,
        position_body_m: [0.0; 3],
        ..LidarConfig::default()
    }
}

fn ranges(frame: &[u8]) -> Vec<f32> {
    frame
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// f32 output: the range's own rounding (half an ulp) plus the ray cast's tolerance.
fn close(got: f32, want: f64) -> bool {
    (got as f64 - want).abs() <= want * 2f64.powi(-24) + 2e-6
}

#[test]
fn ranges_on_a_tilted_view_of_a_plane_are_h_over_cos() {
    let ground = plane();
    let s = site();
    let [east, north, up] = s.axes_mcmf();
    let h = 420.0;
    let pos = s.mcmf_from_site(&Vector3::new(3.0, 4.0, h));
    let q = looking_along(&(-up + east * 0.4 + north * 0.1).normalize(), &north);
    let truth = still_truth(&ground, &pos, &q, 0);
    let mut lidar = Lidar::new(&quiet(), 3).unwrap();
    let mut out = vec![0u8; lidar.frame_bytes()];
    let meta = lidar.render(&truth, &mut out).unwrap();
    assert_eq!(meta.empty_pixels, 0);
    let r = ranges(&out);
    for j in 0..128 {
        for i in 0..128 {
            let (_, d) = lidar.pixel_ray_mcmf(&truth, i, j);
            let dz = s.site_dir_from_mcmf(&d).z;
            let want = h / -dz;
            let got = r[(j * 128 + i) as usize];
            assert!(close(got, want), "pixel {i},{j}: {got} vs {want}");
        }
    }
}

#[test]
fn ranges_on_the_smooth_moon_are_the_ray_sphere_roots() {
    let ground = Ground::Sphere { radius_m: R_M };
    let s = site();
    let [east, north, up] = s.axes_mcmf();
    let pos = s.origin_mcmf() + up * 800.0;
    let q = looking_along(&(-up + north * 0.5).normalize(), &east);
    let truth = still_truth(&ground, &pos, &q, 0);
    let cfg = LidarConfig {
        max_range_m: 5000.0,
        ..quiet()
    };
    let mut lidar = Lidar::new(&cfg, 3).unwrap();
    let mut out = vec![0u8; lidar.frame_bytes()];
    lidar.render(&truth, &mut out).unwrap();
    let r = ranges(&out);
    for j in (0..128).step_by(7) {
        for i in (0..128).step_by(5) {
            let (o, d) = lidar.pixel_ray_mcmf(&truth, i, j);
            // |o + t d| = R: t = -b - sqrt(b^2 - c), b = o.d, c = |o|^2 - R^2.
            let b = o.dot(&d);
            let c = (o.norm() - R_M) * (o.norm() + R_M);
            let want = c / (-b + (b * b - c).sqrt());
            let got = r[(j * 128 + i) as usize];
            assert!(close(got, want), "pixel {i},{j}: {got} vs {want}");
        }
    }
}

/// A 4 m x 3 m x 2 m box on a plane, seen from 40 m: rays whose analytic hit on the
/// box's top (z = 2) lies inside it return `(h - 2) / -dz`, rays that meet the plane
/// clear of the box (and of its shadow in the view) return `h / -dz`. The grid's
/// 5 cm bilinear ramp at the box's edges is left out of both sets.
#[test]
fn ranges_over_a_box_boulder_are_the_box_and_the_plane() {
    let (bx, by, bh) = (2.0, 1.5, 2.0);
    let ground = flat_world(60.0, 0.05, |e, n| {
        if e.abs() <= bx + 1e-9 && n.abs() <= by + 1e-9 {
            bh
        } else {
            0.0
        }
    });
    let s = site();
    let [east, north, up] = s.axes_mcmf();
    let h = 40.0;
    let pos = s.mcmf_from_site(&Vector3::new(-1.0, 0.5, h));
    let q = looking_along(&(-up + east * 0.05).normalize(), &north);
    let truth = still_truth(&ground, &pos, &q, 0);
    let mut lidar = Lidar::new(&quiet(), 3).unwrap();
    let mut out = vec![0u8; lidar.frame_bytes()];
    lidar.render(&truth, &mut out).unwrap();
    let r = ranges(&out);
    let o = Vector3::new(-1.0, 0.5, h);
    let (mut top, mut plain) = (0, 0);
    for j in 0..128 {
        for i in 0..128 {
            let (_, d) = lidar.pixel_ray_mcmf(&truth, i, j);
            let d = s.site_dir_from_mcmf(&d);
            let got = r[(j * 128 + i) as usize];
            let t_top = (h - bh) / -d.z;
            let p = o + d * t_top;
            let margin = 0.06;
            if p.x.abs() < bx - margin && p.y.abs() < by - margin {
                assert!(close(got, t_top), "top {i},{j}: {got} vs {t_top}");
                top += 1;
                continue;
            }
            let t0 = h / -d.z;
            let g = o + d * t0;
            // Clear of the box by more than the ramp, and the ray never over it.
            let clear = |x: f64, y: f64| x.abs() > bx + margin || y.abs() > by + margin;
            if clear(g.x, g.y) && clear(p.x, p.y) {
                assert!(close(got, t0), "plane {i},{j}: {got} vs {t0}");
                plain += 1;
            }
        }
    }
    assert!(top > 1000 && plain > 8000, "top {top}, plane {plain}");
}

#[test]
fn beyond_the_maximum_range_there_is_no_return_and_frames_repeat() {
    let ground = plane();
    let s = site();
    let [east, _, up] = s.axes_mcmf();
    let q = looking_along(&-up, &east);
    let far = still_truth(
        &ground,
        &s.mcmf_from_site(&Vector3::new(0.0, 0.0, 1500.0)),
        &q,
        0,
    );
    let mut lidar = Lidar::new(
        &LidarConfig {
            enabled: true,
            ..LidarConfig::default()
        },
        9,
    )
    .unwrap();
    let mut a = vec![0u8; lidar.frame_bytes()];
    let meta = lidar.render(&far, &mut a).unwrap();
    assert_eq!(meta.empty_pixels, 128 * 128);
    assert!(ranges(&a).iter().all(|r| *r == 0.0));
    let near = still_truth(
        &ground,
        &s.mcmf_from_site(&Vector3::new(0.0, 0.0, 300.0)),
        &q,
        400_000_000,
    );
    lidar.render(&near, &mut a).unwrap();
    let mut fresh = Lidar::new(
        &LidarConfig {
            enabled: true,
            ..LidarConfig::default()
        },
        9,
    )
    .unwrap();
    let mut b = vec![0u8; fresh.frame_bytes()];
    fresh.render(&near, &mut b).unwrap();
    assert_eq!(a, b);
    // The noise is there: 5 cm sigma about the plane's range (the receiver 0.6 m below
    // the centre of mass).
    let r = ranges(&a);
    let (o, d) = lidar.pixel_ray_mcmf(&near, 64, 64);
    let want = s.site_from_mcmf(&o).z / -s.site_dir_from_mcmf(&d).z;
    let centre = r[64 * 128 + 64] as f64;
    assert!(
        (centre - want).abs() < 0.3 && !close(centre as f32, want),
        "{centre} vs {want}"
    );
    assert!(lidar.render(&near, &mut b[..10]).is_err());
}
