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

/// The frames announced in a CSV export: `(t_s, device, seq, flags, hash)`.
fn announcements(run: &LoggedRun) -> Vec<(f64, u32, u64, u32, u64)> {
    let col = |n: &str| column(&run.header, n);
    let count = col("frame_count");
    let mut out = Vec::new();
    for row in &run.rows {
        let n: usize = row[count].parse().unwrap();
        for k in 0..n {
            let get = |name: &str| row[col(&format!("{name}[{k}]"))].clone();
            out.push((
                get("frame_t_ns").parse::<f64>().unwrap() * 1e-9,
                get("frame_device").parse().unwrap(),
                get("frame_seq").parse().unwrap(),
                get("frame_flags").parse().unwrap(),
                get("frame_hash").parse().unwrap(),
            ));
        }
    }
    out
}

/// The fault's `(fired, cleared)` times in a report, seconds.
fn fault_window(report: &serde_json::Value, kind: &str) -> (f64, f64) {
    let f = report["faults"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["kind"] == kind)
        .unwrap_or_else(|| panic!("no {kind} in {report}"));
    (
        f["t_s"].as_f64().unwrap(),
        f["cleared_t_s"].as_f64().unwrap_or(f64::INFINITY),
    )
}

#[test]
fn faults_on_the_camera_and_the_lidar_act_on_their_frames() {
    use oils_shared::{
        frame_hash, FRAME_DEVICE_CAMERA as CAM, FRAME_DEVICE_LIDAR as LID, FRAME_FLAG_OUTAGE,
        FRAME_FLAG_SATURATED,
    };
    let faults = [
        "sensor-dead-quadrant:lidar,quadrant=2@alt=1500",
        "sensor-blinding:camera,level=2@alt=1000,for=3",
        "sensor-frozen:camera@alt=500,for=3",
        "sensor-dropout:lidar@alt=500,for=3",
        "sensor-inhibit:camera@alt=200,for=2",
    ];
    let mut extra = Vec::new();
    for f in &faults {
        extra.extend(["--fault", f]);
    }
    let run = fly_logged("eyes-faults", &config(), &extra);
    assert_eq!(run.report["outcome"], "landed", "{}", run.report);
    let frames = announcements(&run);
    let during = |kind: &str, device: u32| {
        let (a, b) = fault_window(&run.report, kind);
        let inside: Vec<_> = frames
            .iter()
            .filter(|f| f.1 == device && f.0 > a && f.0 <= b)
            .copied()
            .collect();
        let before = frames
            .iter()
            .rfind(|f| f.1 == device && f.0 <= a)
            .copied()
            .unwrap();
        (inside, before)
    };

    // Blinding: each frame in the window saturates; none just before does.
    let (inside, before) = during("sensor-blinding", CAM);
    assert_eq!(inside.len(), 3, "{inside:?}");
    assert!(inside.iter().all(|f| f.3 & FRAME_FLAG_SATURATED != 0));
    assert_eq!(before.3 & FRAME_FLAG_SATURATED, 0);

    // Frozen: the last frame before repeats, byte for byte (same hash), counted on.
    let (inside, before) = during("sensor-frozen", CAM);
    assert_eq!(inside.len(), 3);
    for (i, f) in inside.iter().enumerate() {
        assert_eq!(f.4, before.4, "frame {i} of the frozen window");
        assert_eq!(f.2, before.2 + 1 + i as u64);
    }

    // Dropout: no lidar frame at all, and the counter resumes where it stopped.
    let (inside, before) = during("sensor-dropout", LID);
    assert!(inside.is_empty(), "{inside:?}");
    let after = frames
        .iter()
        .find(|f| f.1 == LID && f.0 > before.0 + 1.5)
        .unwrap();
    assert_eq!(after.2, before.2 + 1);

    // Inhibited: blank frames flagged as an outage.
    let (inside, _) = during("sensor-inhibit", CAM);
    assert_eq!(inside.len(), 2);
    let blank = frame_hash(&vec![0u8; 128 * 128 * 2]);
    assert!(inside
        .iter()
        .all(|f| f.3 & FRAME_FLAG_OUTAGE != 0 && f.4 == blank));

    // Dead quadrant: in the lidar frame at about 200 m (returns everywhere) the top
    // right quarter reads "no return", the rest does not.
    let (_, at_200_m) = during("sensor-inhibit", LID);
    let dir = scratch("eyes-faults-frames");
    let out = run_oils(&[
        "export",
        run.log.to_str().unwrap(),
        "--frames",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let png = dir.join(format!("lidar-{:06}.png", at_200_m.2));
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size()];
    r.next_frame(&mut buf).unwrap();
    let level =
        |x: usize, y: usize| u16::from_be_bytes([buf[2 * (y * 32 + x)], buf[2 * (y * 32 + x) + 1]]);
    for y in 0..32 {
        for x in 0..32 {
            let dead = x >= 16 && y < 16;
            assert_eq!(level(x, y) == 0, dead, "({x}, {y}): {}", level(x, y));
        }
    }
}
