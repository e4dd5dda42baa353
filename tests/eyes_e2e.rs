//! The navigation camera and the flash lidar in whole runs (small frames, so the test is
//! quick; the pinpoint scenario flies them at full size):
//! * the same digest in process and across two processes over real iceoryx2, every frame
//!   checked by the stub against its announcement (none missed);
//! * `oils export LOG --frames DIR` renders each frame again through a replay and writes
//!   it as a 16-bit PNG named after its device, one per announcement, of the announced
//!   size.

mod common;
use common::*;

/// The default descent, ideal propulsion, a 128 x 128 camera and a 32 x 32 lidar, both
/// at 1 Hz below 3 km.
fn config() -> String {
    "link = \"inproc\"\npropulsion = \"ideal\"\n\n\
     [scenario.sensors.camera]\nenabled = true\nperiod_ms = 1000.0\nwidth_px = 128\nheight_px = 128\non_below_altitude_m = 3000.0\n\n\
     [scenario.sensors.lidar]\nenabled = true\nperiod_ms = 1000.0\nwidth_px = 32\nheight_px = 32\non_below_altitude_m = 3000.0\n"
        .to_string()
}

fn png_size(path: &std::path::Path) -> (u32, u32, png::BitDepth) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let r = dec.read_info().unwrap();
    let info = r.info();
    (info.width, info.height, info.bit_depth)
}

#[test]
fn camera_and_lidar_frames_cross_processes_and_export_as_png() {
    let cfg = config();
    let dir = scratch("eyes-inproc");
    let file = dir.join("run.toml");
    std::fs::write(&file, &cfg).unwrap();
    let (log, rep) = (dir.join("run.oilslog"), dir.join("report.json"));
    let out = run_oils(&[
        "run",
        "--config",
        file.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let inproc = report(&rep);
    assert_eq!(inproc["outcome"], "landed", "{inproc}");
    let digest = inproc["digest"].as_str().unwrap().to_string();

    let r = report_across_processes("eyes-iceoryx2", &cfg);
    assert_eq!(r["digest"].as_str().unwrap(), digest);
    assert_eq!(r["onboard_process"]["frames_missed"], 0);
    let checked = r["onboard_process"]["frames_checked"].as_u64().unwrap();

    let frames = dir.join("frames");
    let out = run_oils(&[
        "export",
        log.to_str().unwrap(),
        "--frames",
        frames.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let mut names: Vec<String> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    let camera: Vec<&String> = names.iter().filter(|n| n.starts_with("camera-")).collect();
    let lidar: Vec<&String> = names.iter().filter(|n| n.starts_with("lidar-")).collect();
    let sim_s = inproc["sim_time_s"].as_f64().unwrap() as u64;
    // One frame a second of each device (blank ones above 3 km included).
    assert_eq!(camera.len() as u64, sim_s, "{names:?}");
    assert_eq!(lidar.len() as u64, sim_s);
    assert_eq!(camera.len() + lidar.len(), names.len());
    // The stub saw each but those announced by the end-of-run telemetry.
    assert!(checked + 2 >= names.len() as u64 && checked <= names.len() as u64);
    assert_eq!(
        png_size(&frames.join(camera[camera.len() - 1])),
        (128, 128, png::BitDepth::Sixteen)
    );
    assert_eq!(
        png_size(&frames.join(lidar[lidar.len() - 1])),
        (32, 32, png::BitDepth::Sixteen)
    );
}
