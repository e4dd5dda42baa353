//! Protocol v4's frames through whole runs, with the test card on (a 1024 x 1024 u16
//! frame, 2 MiB, at 1 Hz):
//! * the same digest in process and across two processes over real iceoryx2, every frame
//!   the telemetry announced read by the stub from its service and checked against its
//!   announcement's length and XXH3-64 before the flight software saw it (none missed);
//! * the log's announcements carry the hash of the test card's closed-form pattern for
//!   their `seq`, at the mid-exposure time of validity;
//! * the digest covers the frames: a card of another size gives another digest, the
//!   physics unchanged;
//! * `oils replay` renders every frame again and ends with the recorded digest.

mod common;
use common::*;
use oils_emulator::sensors::test_card;

/// The default descent, ideal propulsion, with the test card on (`height` rows).
fn config(height: u32) -> String {
    format!(
        "link = \"inproc\"\npropulsion = \"ideal\"\n\n[scenario.sensors.test_card]\nenabled = true\nperiod_ms = 1000.0\nexposure_ms = 20.0\nwidth = 1024\nheight = {height}\n"
    )
}

#[test]
fn test_card_frames_across_processes_checked_on_arrival_and_replayed() {
    let cfg = config(1024);
    let LoggedRun {
        report: inproc,
        log,
        header,
        rows,
    } = fly_logged("frames-inproc", &cfg, &[]);
    assert_eq!(inproc["outcome"], "landed", "{inproc}");
    let digest = inproc["digest"].as_str().unwrap().to_string();

    // Every announcement in the log: one per second of flight, seq counting from 0, the
    // hash of the closed-form pattern, valid mid-exposure (10 ms before the second).
    let (count, seq, hash, t_ns, bytes) = (
        column(&header, "frame_count"),
        column(&header, "frame_seq[0]"),
        column(&header, "frame_hash[0]"),
        column(&header, "frame_t_ns[0]"),
        column(&header, "frame_bytes[0]"),
    );
    let flags = column(&header, "telemetry.header.flags");
    let mut announced_to_fsw = 0u64;
    let mut next_seq = 0u64;
    let mut frame = vec![0u8; 1024 * 1024 * 2];
    for row in &rows {
        match row[count].as_str() {
            "0" => continue,
            "1" => {}
            other => panic!("frame_count {other}"),
        }
        let s: u64 = row[seq].parse().unwrap();
        assert_eq!(s, next_seq, "frames in order, none lost");
        next_seq += 1;
        assert_eq!(row[bytes], (1024 * 1024 * 2).to_string());
        assert_eq!(
            row[t_ns].parse::<i64>().unwrap(),
            (s as i64 + 1) * 1_000_000_000 - 10_000_000
        );
        test_card::pattern(1024, 1024, s, &mut frame);
        assert_eq!(
            row[hash].parse::<u64>().unwrap(),
            oils_shared::frame_hash(&frame),
            "frame {s}'s hash"
        );
        let end = row[flags].parse::<u32>().unwrap() & oils_shared::TLM_FLAG_END_OF_RUN != 0;
        if !end {
            announced_to_fsw += 1;
        }
    }
    let sim_s = inproc["sim_time_s"].as_f64().unwrap();
    assert_eq!(next_seq, sim_s.floor() as u64, "one frame a second");
    assert!(next_seq > 100, "{next_seq} frames");

    // Across processes: the same digest, and every frame announced to the flight software
    // read from its service and checked by the stub (a mismatch fails the run).
    let r = report_across_processes("frames-iceoryx2", &cfg);
    assert_eq!(r["digest"].as_str().unwrap(), digest);
    assert_eq!(r["onboard_process"]["frames_checked"], announced_to_fsw);
    assert_eq!(r["onboard_process"]["frames_missed"], 0);

    // Record == replay: the frames rendered again, their hashes the recorded ones.
    let out = run_oils(&["replay", log.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(text(&out).contains(&digest), "{}", text(&out));
}

#[test]
fn the_digest_covers_the_frames_and_nothing_else_moves() {
    let a = fly_logged("frames-1024", &config(1024), &[]);
    let b = fly_logged("frames-1023", &config(1023), &[]);
    let (header, rows_a, rows_b) = (&a.header, &a.rows, &b.rows);
    let (a, b) = (&a.report, &b.report);
    assert_ne!(a["digest"], b["digest"], "another frame, another digest");
    // The physics and the flight software are the same: only the announcements differ.
    let frame_cols: Vec<usize> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| h.starts_with("frame_"))
        .map(|(i, _)| i)
        .collect();
    let wall_clock = |h: &str| {
        h.starts_with("timing.")
            || h.ends_with("compute_ns")
            || h.contains("group_compute_ns")
            || h.ends_with("cycle_slips")
            || h.ends_with("run_id")
    };
    assert_eq!(rows_a.len(), rows_b.len());
    let mut differing = 0;
    for (ra, rb) in rows_a.iter().zip(rows_b.iter()) {
        for (i, h) in header.iter().enumerate() {
            if frame_cols.contains(&i) {
                differing += usize::from(ra[i] != rb[i]);
            } else if !wall_clock(h) {
                assert_eq!(ra[i], rb[i], "{h} moved");
            }
        }
    }
    assert!(differing > 0);
}

#[test]
fn a_frame_device_faster_than_the_cycle_is_refused_before_tick_0() {
    let dir = scratch("frames-too-fast");
    let file = dir.join("run.toml");
    std::fs::write(
        &file,
        "link = \"inproc\"\npropulsion = \"ideal\"\nfsw_period_ms = 20\n\n[scenario.sensors.test_card]\nenabled = true\nperiod_ms = 10.0\n",
    )
    .unwrap();
    let out = run_oils(&["run", "--config", file.to_str().unwrap(), "--no-log"]);
    assert!(!out.status.success());
    let t = text(&out);
    assert!(
        t.contains("sensors.test_card.period_ms") && t.contains("flight-software cycle"),
        "{t}"
    );
}
