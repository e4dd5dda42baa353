//! The MCAP log and the run's figures, through the real `oils` binary (in-process link,
//! so a run takes a fraction of a second): `oils export LOG --mcap`, `oils run
//! --log-format mcap`, `oils replay RUN.mcap`, `oils plot`, read back with the `mcap`
//! crate's own reader.

mod common;

use common::{oils, report, run_oils, scratch, text};
use oils_emulator::recorder::{read_log, Log};
use oils_lab::mcap_log::topic;
use std::collections::BTreeMap;
use std::path::Path;

/// A short run (60 s of the default descent, 6001 records) with a binary log.
fn short_run(dir: &Path, extra: &[&str]) -> Log {
    let log = dir.join("run.oilslog");
    let mut args = vec![
        "run",
        "--link",
        "inproc",
        "--duration",
        "60",
        "--run-id",
        "00000000000000a5",
        "--log",
        log.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = run_oils(&args);
    assert!(o.status.success(), "{}", text(&o));
    read_log(&log).unwrap()
}

/// `oils export DIR/run.oilslog --mcap DIR/run.mcap`; the MCAP's path.
fn export_mcap(dir: &Path) -> std::path::PathBuf {
    let out = dir.join("run.mcap");
    let o = run_oils(&[
        "export",
        dir.join("run.oilslog").to_str().unwrap(),
        "--mcap",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    out
}

struct Msg {
    log_time: u64,
    sequence: u32,
    json: serde_json::Value,
}

/// Every message of an MCAP file by topic, with each channel's schema name and
/// encodings, read with the crate's reader (chunk CRCs checked).
fn read_mcap(path: &Path) -> (BTreeMap<String, Vec<Msg>>, BTreeMap<String, [String; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let mut msgs: BTreeMap<String, Vec<Msg>> = BTreeMap::new();
    let mut channels = BTreeMap::new();
    for m in
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::ValidateChunkCrcs.into())
            .unwrap()
    {
        let m = m.unwrap();
        let schema = m
            .channel
            .schema
            .as_ref()
            .expect("every channel has a schema");
        channels.insert(
            m.channel.topic.clone(),
            [
                schema.name.clone(),
                schema.encoding.clone(),
                m.channel.message_encoding.clone(),
            ],
        );
        msgs.entry(m.channel.topic.clone()).or_default().push(Msg {
            log_time: m.log_time,
            sequence: m.sequence,
            json: serde_json::from_slice(&m.data).expect("every message is JSON"),
        });
    }
    (msgs, channels)
}

/// A byte in the middle of the body of the MCAP file's middle chunk (op 0x06), found by
/// walking its top-level records: the middle of the file may fall on a message index,
/// which a reader is free not to use.
fn middle_of_a_chunk(mcap: &[u8]) -> usize {
    let mut chunks = Vec::new();
    let mut at = 8; // past the magic
    while at + 9 <= mcap.len() {
        let len = u64::from_le_bytes(mcap[at + 1..at + 9].try_into().unwrap()) as usize;
        if mcap[at] == 0x06 {
            chunks.push((at + 9, len));
        }
        at += 9 + len;
    }
    let (body, len) = chunks[chunks.len() / 2];
    body + len / 2
}

fn f(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// Equal, as read through `serde_json::Value`: its default float parser is best-effort
/// (may be one ulp off), so one ulp is allowed here; the exact comparison is
/// `mcap_reads_back_bit_for_bit` below, through the oils reader, which parses each
/// number's text exactly.
fn same(a: f64, b: f64) -> bool {
    a == b || (a.is_nan() && b.is_nan()) || (a.to_bits().abs_diff(b.to_bits()) <= 1)
}

fn exactly(a: f64, b: f64) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}

#[test]
fn exported_mcap_holds_every_step_of_the_binary_log() {
    let dir = scratch("mcap-export");
    let log = short_run(&dir, &["--propulsion", "hifi"]);
    let n = log.records.len();
    assert!(n > 6000, "{n} records");
    let out = export_mcap(dir.as_path());
    let (msgs, channels) = read_mcap(&out);

    let expected = [
        (topic::TELEMETRY, "oils.Telemetry"),
        (topic::COMMAND, "oils.Command"),
        (topic::TRUTH, "oils.TrueState"),
        (topic::PROPULSION, "oils.Propulsion"),
        (topic::TIMING, "oils.StepTiming"),
        (topic::TF, "foxglove.FrameTransforms"),
        (topic::POSE, "foxglove.PoseInFrame"),
        (topic::EVENTS, "foxglove.Log"),
        (topic::SCENE, "foxglove.SceneUpdate"),
    ];
    for (t, schema) in expected {
        let c = channels.get(t).unwrap_or_else(|| panic!("no channel {t}"));
        assert_eq!(c, &[schema.to_string(), "jsonschema".into(), "json".into()]);
    }
    for t in topic::PER_STEP {
        let m = &msgs[t];
        assert_eq!(m.len(), n, "{t}: one message per record");
        for (k, (msg, rec)) in m.iter().zip(&log.records).enumerate() {
            assert_eq!(msg.log_time, rec.telemetry.header.t_ns as u64, "{t} #{k}");
            assert_eq!(msg.sequence as usize, k, "{t}");
        }
        assert!(m.windows(2).all(|w| w[0].log_time < w[1].log_time), "{t}");
    }

    for (k, r) in log.records.iter().enumerate() {
        let tlm = &msgs[topic::TELEMETRY][k].json;
        let t = &r.telemetry;
        assert_eq!(tlm["header"]["step"].as_u64(), Some(t.header.step));
        assert_eq!(tlm["header"]["run_id"], "00000000000000a5");
        assert!(same(f(&tlm["altitude_m"]), t.altitude_m), "step {k}");
        for i in 0..3 {
            assert!(same(f(&tlm["nav"]["pos_mci_m"][i]), t.nav.pos_mci_m[i]));
            assert!(same(f(&tlm["nav"]["vel_mci_m_s"][i]), t.nav.vel_mci_m_s[i]));
        }
        let cmd = &msgs[topic::COMMAND][k].json;
        assert_eq!(cmd["record_flags"].as_u64(), Some(u64::from(r.flags)));
        for e in 0..4 {
            assert!(same(f(&cmd["thrust_cmd_n"][e]), r.command.thrust_cmd_n[e]));
            assert!(same(
                f(&cmd["applied"]["thrust_cmd_n"][e]),
                r.applied.engines.thrust_cmd_n[e]
            ));
        }
        let truth = &msgs[topic::TRUTH][k].json;
        assert!(same(f(&truth["mass_kg"]), r.truth.mass_kg), "step {k}");
        assert!(same(f(&truth["altitude_m"]), r.truth.altitude_m));
        for i in 0..4 {
            assert!(same(
                f(&truth["q_mci_from_body"][i]),
                r.truth.q_mci_from_body[i]
            ));
        }
        let p = &msgs[topic::PROPULSION][k].json;
        let tp = &r.truth.propulsion;
        for e in 0..4 {
            assert!(same(f(&p["thrust_n"][e]), tp.thrust_n[e]), "step {k}");
            assert!(same(
                f(&p["chamber_pressure_pa"][e]),
                tp.chamber_pressure_pa[e]
            ));
            assert!(same(
                f(&p["fuel_valve_position"][e]),
                r.truth.internals.valve_position[e][0]
            ));
        }
        assert!(same(f(&p["gas_pressure_pa"]), tp.gas_pressure_pa));
        assert!(same(
            f(&p["regulator_outlet_pa"]),
            r.truth.internals.regulator_outlet_pa
        ));
        let tf = &msgs[topic::TF][k].json["transforms"][1];
        assert_eq!(tf["parent_frame_id"], "moon");
        assert_eq!(tf["child_frame_id"], "lander");
        assert!(same(f(&tf["translation"]["x"]), r.truth.pos_mci_m[0]));
        assert!(same(f(&tf["rotation"]["w"]), r.truth.q_mci_from_body[0]));
        let timing = &msgs[topic::TIMING][k].json;
        if r.flags & oils_emulator::recorder::REC_COMMAND_RECEIVED != 0 {
            assert_eq!(
                timing["stub_compute_ns"].as_u64(),
                Some(r.command.stub_compute_ns)
            );
            // In process: the call is the round trip, there is no transport.
            let rt = r
                .timing
                .round_trip_ns
                .expect("a received command has a round trip");
            assert_eq!(timing["round_trip_ns"].as_u64(), Some(rt));
            assert!(rt >= r.command.stub_compute_ns);
            assert!(timing["transport_ns"].is_null());
        }
        assert!(
            timing["wake_error_ns"].is_null(),
            "lockstep has no wake error"
        );
    }
    // Bit for bit through the oils reader: every record equal to the binary log's.
    let back = oils_lab::mcap_log::read_mcap(&out).unwrap();
    assert_eq!(back.header_json, log.header_json);
    assert_eq!(back.records.len(), n);
    for (k, (a, b)) in log.records.iter().zip(&back.records).enumerate() {
        assert_eq!(a.flags, b.flags, "step {k}");
        assert_eq!(a.telemetry, b.telemetry, "step {k}");
        assert_eq!(a.command, b.command, "step {k}");
        let (va, vb) = (a.truth_values(), b.truth_values());
        assert!(
            va.iter().zip(&vb).all(|(x, y)| exactly(*x, *y)),
            "step {k}: {va:?} != {vb:?}"
        );
    }

    // The run was cut by --duration: a start and an end-of-run event, nothing else.
    let events: Vec<&str> = msgs[topic::EVENTS]
        .iter()
        .map(|m| m.json["name"].as_str().unwrap())
        .collect();
    assert_eq!(events, ["start", "end_of_run"]);
    assert_eq!(
        msgs[topic::EVENTS][1].log_time,
        log.records[n - 1].telemetry.header.t_ns as u64
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_same_run_gives_the_same_mcap_and_replays_from_it() {
    let root = scratch("mcap-same");
    let mut files = Vec::new();
    let mut digests = Vec::new();
    for name in ["a", "b"] {
        let dir = root.join(name);
        std::fs::create_dir_all(&dir).unwrap();
        // Same relative log path: the header (the configuration) must match too.
        let o = oils()
            .current_dir(&dir)
            .args([
                "run",
                "--link",
                "inproc",
                "--duration",
                "40",
                "--run-id",
                "00000000000000b7",
                "--log-format",
                "mcap",
                "--log",
                "run.mcap",
                "--report",
                "report.json",
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        files.push(std::fs::read(dir.join("run.mcap")).unwrap());
        digests.push(report(&dir.join("report.json"))["digest"].clone());
    }
    assert!(files[0].len() > 100_000, "{} bytes", files[0].len());
    assert_eq!(digests[0], digests[1]);
    // Two runs differ only where the log holds wall-clock measurements (the stub's
    // compute time and its rate groups' compute times and slips, as the digest leaves
    // them out, and the step's round trip, wake error and transport): every message
    // equal once those are removed.
    let strip = |path: &Path| -> Vec<(String, u64, serde_json::Value)> {
        let (msgs, _) = read_mcap(path);
        let mut out = Vec::new();
        for (topic, list) in msgs {
            for mut m in list {
                if let Some(o) = m.json.as_object_mut() {
                    for wall_clock in [
                        "stub_compute_ns",
                        "round_trip_ns",
                        "wake_error_ns",
                        "transport_ns",
                    ] {
                        o.remove(wall_clock);
                    }
                    // The flight software's own wall-clock figures (FswReport).
                    if let Some(f) = o.get_mut("fsw").and_then(|f| f.as_object_mut()) {
                        f.remove("group_compute_ns");
                        f.remove("cycle_slips");
                    }
                }
                out.push((topic.clone(), m.log_time, m.json));
            }
        }
        out
    };
    let (a, b) = (
        strip(&root.join("a/run.mcap")),
        strip(&root.join("b/run.mcap")),
    );
    assert_eq!(a.len(), b.len());
    assert!(a == b, "two runs gave different MCAP messages");

    // The same records give the same bytes: export one run's MCAP twice.
    let dir = root.join("a");
    for out in ["x1.mcap", "x2.mcap"] {
        let o = oils()
            .current_dir(&dir)
            .args(["export", "run.mcap", "--mcap", out])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
    }
    let x1 = std::fs::read(dir.join("x1.mcap")).unwrap();
    assert!(x1 == std::fs::read(dir.join("x2.mcap")).unwrap());
    // And MCAP -> Log -> MCAP loses nothing: the re-export equals the run's own file.
    assert!(x1 == files[0], "re-exported MCAP differs from the run's");

    // Record == replay, from the MCAP: every telemetry re-computed equals the logged one.
    let o = oils()
        .current_dir(&dir)
        .args(["replay", "run.mcap", "--report", "replay.json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(report(&dir.join("replay.json"))["digest"], digests[0]);

    // A damaged chunk is refused, not read as data.
    let mut bad = files[0].clone();
    let mid = middle_of_a_chunk(&bad);
    bad[mid] ^= 0x55;
    std::fs::write(dir.join("bad.mcap"), &bad).unwrap();
    let o = run_oils(&[
        "export",
        dir.join("bad.mcap").to_str().unwrap(),
        "--csv",
        dir.join("bad.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("bad.mcap is not an oils log"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(&root).ok();
}

/// Every message of a whole run (hifi, a fault firing and clearing, so every event kind
/// but touchdown and misses shows) against its own channel's schema, with the lab's
/// validator: a field added to a message and not to its schema, or to the schema and
/// not the message, fails here. The schemas require every property and allow no other.
#[test]
fn every_message_of_a_run_fits_its_channels_schema() {
    let dir = scratch("mcap-schema");
    let log = dir.join("run.mcap");
    let o = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--propulsion",
        "hifi",
        "--duration",
        "20",
        "--fault",
        "engine-off:2@t=5,for=2",
        "--log-format",
        "mcap",
        "--log",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let bytes = std::fs::read(&log).unwrap();
    let mut checked: BTreeMap<String, usize> = BTreeMap::new();
    let mut schemas: BTreeMap<u16, serde_json::Value> = BTreeMap::new();
    for m in
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::ValidateChunkCrcs.into())
            .unwrap()
    {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().expect("a schema");
        let schema = schemas
            .entry(schema.id)
            .or_insert_with(|| serde_json::from_slice(&schema.data).expect("the schema is JSON"));
        let msg: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        if let Err(e) = oils_lab::json_schema::validate(schema, &msg) {
            panic!("{} #{}: {e}\n{msg}", m.channel.topic, m.sequence);
        }
        *checked.entry(m.channel.topic.clone()).or_default() += 1;
    }
    assert_eq!(checked.len(), 10, "{checked:?}");
    assert!(checked[topic::DEVICES] > 2000, "{checked:?}");
    assert!(checked[topic::TRUTH] > 2000, "{checked:?}");
    assert_eq!(checked[topic::SCENE], 1);
    assert_eq!(
        checked[topic::EVENTS],
        4,
        "start, fault fired, cleared, end of run"
    );
    std::fs::remove_dir_all(&dir).ok();
}

fn pngs(dir: &Path) -> Vec<(String, u64)> {
    let mut out: Vec<(String, u64)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            assert_eq!(&bytes[1..4], b"PNG", "{}", p.display());
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                bytes.len() as u64,
            )
        })
        .collect();
    out.sort();
    out
}

#[test]
fn oils_plot_draws_a_run_from_either_log() {
    let dir = scratch("mcap-plot");
    short_run(&dir, &["--plots", dir.join("at-end").to_str().unwrap()]);
    let log = dir.join("run.oilslog");
    let mcap = dir.join("run.mcap");
    let o = run_oils(&[
        "export",
        log.to_str().unwrap(),
        "--mcap",
        mcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    for (input, out) in [(&log, "from-log"), (&mcap, "from-mcap")] {
        let out = dir.join(out);
        let o = run_oils(&[
            "plot",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let figures = pngs(&out);
        assert!(figures.len() >= 6, "{figures:?}");
        assert!(figures.iter().all(|(_, len)| *len > 10_000), "{figures:?}");
    }
    let at_end = pngs(&dir.join("at-end"));
    assert_eq!(
        at_end.iter().map(|f| &f.0).collect::<Vec<_>>(),
        pngs(&dir.join("from-log"))
            .iter()
            .map(|f| &f.0)
            .collect::<Vec<_>>()
    );
    // --plots needs the log.
    let o = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--no-log",
        "--plots",
        "x",
        "--duration",
        "1",
    ]);
    assert!(!o.status.success());
    std::fs::remove_dir_all(&dir).ok();
}

/// Every message path `/topic.field[i]` the layout plots or shows.
fn layout_paths(v: &serde_json::Value, out: &mut Vec<String>) {
    match v {
        serde_json::Value::String(s) if s.starts_with("/oils/") => out.push(s.clone()),
        serde_json::Value::Array(xs) => xs.iter().for_each(|x| layout_paths(x, out)),
        serde_json::Value::Object(m) => m.values().for_each(|x| layout_paths(x, out)),
        _ => {}
    }
}

#[test]
fn the_foxglove_layout_names_only_topics_and_fields_the_mcap_has() {
    let dir = scratch("mcap-layout");
    short_run(&dir, &["--propulsion", "ideal"]);
    let out = export_mcap(dir.as_path());
    let (msgs, _) = read_mcap(&out);
    let layout: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/docs/foxglove-layout.json"
        ))
        .unwrap(),
    )
    .expect("the layout is JSON");
    let mut paths = Vec::new();
    layout_paths(&layout, &mut paths);
    assert!(paths.len() >= 20, "{paths:?}");
    for p in &paths {
        let (topic, field) = p.split_once('.').unwrap_or((p.as_str(), ""));
        let first = &msgs
            .get(topic)
            .unwrap_or_else(|| panic!("layout path {p}: no channel {topic}"))[0]
            .json;
        if field.is_empty() {
            continue;
        }
        // `name[i]`: the field must exist (its value may be null) and hold element i.
        let (name, index) = match field.split_once('[') {
            Some((n, i)) => (n, Some(i.trim_end_matches(']').parse::<usize>().unwrap())),
            None => (field, None),
        };
        let value = first
            .get(name)
            .unwrap_or_else(|| panic!("layout path {p}: {topic} has no field {name}: {first}"));
        if let Some(i) = index {
            assert!(
                value.get(i).is_some(),
                "layout path {p}: no element {i} in {value}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
