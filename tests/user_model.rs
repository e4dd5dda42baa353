//! The user's own propulsion model, from the command line (issue #35): the excitation
//! as a file, training on recorded data, validation on recorded runs.

mod common;
use common::*;
use std::path::Path;

fn small_config() -> String {
    format!("{}/tests/data/train-small.toml", env!("CARGO_MANIFEST_DIR"))
}

fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The model file without its provenance lines (which name the source of the data).
fn without_provenance(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .filter(|l| !l.contains("\"reference\"") && !l.contains("\"reference_param_hash\""))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn excitation_through_hifi_then_train_data_gives_the_built_in_model() {
    let dir = scratch("user-model-data");
    let cfg = small_config();
    let ex = dir.join("ex.csv");
    let out = run_oils(&["excitation", "--out", arg(&ex), "--config", &cfg]);
    assert!(out.status.success(), "{}", text(&out));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ex.json")).unwrap()).unwrap();
    assert_eq!(meta["sample_time_ns"], 10_000_000);
    assert_eq!(meta["rows"], 10_500);
    let duration = meta["duration_s"].as_f64().unwrap().to_string();
    // The profile is an ordinary profile: one row per sample time.
    let profile = std::fs::read_to_string(&ex).unwrap();
    assert_eq!(profile.lines().count(), 10_501);
    assert!(profile.starts_with("t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,"));

    // The user's model: here hifi, run open loop by `oils hifi`.
    let data = dir.join("data.csv");
    let out = run_oils(&[
        "hifi",
        "--profile",
        arg(&ex),
        "--out",
        arg(&data),
        "--duration-s",
        &duration,
    ]);
    assert!(out.status.success(), "{}", text(&out));

    let (m_data, m_hifi) = (dir.join("m-data.json"), dir.join("m-hifi.json"));
    let (d_data, d_hifi) = (dir.join("ds-data"), dir.join("ds-hifi"));
    let out = run_oils(&[
        "train",
        "--data",
        arg(&data),
        "--config",
        &cfg,
        "--model",
        arg(&m_data),
        "--out",
        arg(&dir.join("t-data")),
        "--quiet",
        "--export-dataset",
        arg(&d_data),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("10501 rows every 0.01 s, 10500 samples"),
        "{}",
        text(&out)
    );
    let out = run_oils(&[
        "train",
        "--config",
        &cfg,
        "--model",
        arg(&m_hifi),
        "--out",
        arg(&dir.join("t-hifi")),
        "--quiet",
        "--no-holdout",
        "--export-dataset",
        arg(&d_hifi),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    // The same samples, bit for bit (the CSV's numbers are shortest round-trip
    // decimals), and so the same model file but for where the data came from.
    assert_eq!(
        std::fs::read(d_data.join("samples.csv")).unwrap(),
        std::fs::read(d_hifi.join("samples.csv")).unwrap()
    );
    assert_eq!(without_provenance(&m_data), without_provenance(&m_hifi));
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&m_data).unwrap()).unwrap();
    assert_eq!(model["provenance"]["reference"], "data");

    // Judged on the recording itself.
    let report = dir.join("v.json");
    let out = run_oils(&[
        "validate",
        "--model",
        arg(&m_data),
        "--data",
        arg(&data),
        "--out",
        arg(&dir.join("v")),
        "--report",
        arg(&report),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let r = common::report(&report);
    assert_eq!(r["truth"], "data");
    assert_eq!(r["cases"][0]["name"], "data-data");
}

#[test]
fn bad_recorded_data_is_refused_with_file_line_and_column() {
    let dir = scratch("user-model-bad");
    let cfg = small_config();
    let header = "t_s,cmd1_n,cmd2_n,cmd3_n,cmd4_n,on1,on2,on3,on4,thrust1_n,thrust2_n,thrust3_n,thrust4_n,gas_pressure_pa,ejected_fuel_kg,ejected_ox_kg";
    let row = |t: &str, p: &str| format!("{t},500,500,500,500,1,1,1,1,0,0,0,0,{p},0,0\n");
    let cases = [
        (
            format!("{header}\n{}{}", row("0", "2e7"), row("0.01", "inf")),
            "line 3, column 14 (`gas_pressure_pa`): `inf` is not a finite number",
        ),
        (
            format!(
                "{}\n{}{}",
                header.replace(",ejected_ox_kg", ""),
                row("0", "1"),
                row("0.01", "1")
            ),
            "line 1: missing column `ejected_ox_kg`",
        ),
        (
            format!(
                "{header}\n{}{}{}",
                row("0", "1"),
                row("0.01", "1"),
                row("0.01", "1")
            ),
            "line 4, column 1 (`t_s`): 0.01 s is not after the previous row's 0.01 s",
        ),
        (
            format!(
                "{header}\n{}{}{}",
                row("0", "1"),
                row("0.01", "1"),
                row("0.05", "1")
            ),
            "line 4: a gap: 0.01 s to 0.05 s",
        ),
        (
            format!("{header}\n{}{}", row("0", "1"), row("0.004", "1")),
            "sample time 0.01 s is not a whole multiple of the file's step 0.004 s",
        ),
    ];
    for (i, (body, want)) in cases.iter().enumerate() {
        let path = dir.join(format!("bad{i}.csv"));
        std::fs::write(&path, body).unwrap();
        let out = run_oils(&[
            "train",
            "--data",
            arg(&path),
            "--config",
            &cfg,
            "--out",
            arg(&dir.join("t")),
            "--quiet",
        ]);
        assert!(!out.status.success(), "case {i} was accepted");
        let shown = text(&out);
        assert!(
            shown.contains(&format!("bad{i}.csv: {want}")) || shown.contains(want),
            "case {i}: {shown}"
        );
        assert!(
            shown.contains(&format!("bad{i}.csv")),
            "case {i} names no file: {shown}"
        );
        assert!(!shown.contains("panicked"), "{shown}");
    }
}
