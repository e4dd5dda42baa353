//! FMU import (issue #35): the bench's hifi model, packed by `oils export-fmu --hifi`
//! and imported with `--truth fmu:` / `--propulsion fmu:`, gives what the built-in hifi
//! gives (the round trip that checks import and export together); and a variable
//! mapping that does not fit the FMU is refused, naming the variable or the step.

mod common;
use common::*;
use std::path::{Path, PathBuf};

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

/// hifi packed as an FMU of FMI version `v`.
fn hifi_fmu(dir: &Path, v: &str) -> PathBuf {
    let fmu = dir.join(format!("hifi-fmi{v}.fmu"));
    let out = run_oils(&[
        "export-fmu",
        "--hifi",
        "--fmi-version",
        v,
        "--out",
        arg(&fmu),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    fmu
}

/// Trains with the small configuration on `truth` (None: the built-in hifi); returns
/// the model file and the exported dataset folder.
fn train(dir: &Path, name: &str, truth: Option<&str>) -> (PathBuf, PathBuf) {
    let (model, data) = (
        dir.join(format!("{name}.json")),
        dir.join(format!("ds-{name}")),
    );
    let cfg = small_config();
    let out_dir = dir.join(format!("t-{name}"));
    let mut args = vec![
        "train",
        "--config",
        &cfg,
        "--model",
        arg(&model),
        "--out",
        arg(&out_dir),
        "--quiet",
        "--no-holdout",
        "--export-dataset",
        arg(&data),
    ];
    if let Some(t) = truth {
        args.extend(["--truth", t]);
    }
    let out = run_oils(&args);
    assert!(out.status.success(), "{}", text(&out));
    (model, data)
}

#[test]
fn hifi_exported_then_imported_trains_the_built_in_samples_and_model() {
    let dir = scratch("fmu-import-train");
    let (m_hifi, d_hifi) = train(&dir, "hifi", None);
    for v in ["3", "2"] {
        let fmu = hifi_fmu(&dir, v);
        let truth = format!("fmu:{}", fmu.display());
        let (m_fmu, d_fmu) = train(&dir, &format!("fmu{v}"), Some(&truth));
        // The same samples, bit for bit (shortest round-trip decimals), and so the same
        // model file but for where the data came from.
        assert_eq!(
            std::fs::read(d_fmu.join("samples.csv")).unwrap(),
            std::fs::read(d_hifi.join("samples.csv")).unwrap(),
            "FMI {v}"
        );
        assert_eq!(
            without_provenance(&m_fmu),
            without_provenance(&m_hifi),
            "FMI {v}"
        );
        let model: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&m_fmu).unwrap()).unwrap();
        assert_eq!(model["provenance"]["reference"], truth.as_str());
    }
}

#[test]
fn a_run_flown_on_the_exported_hifi_fmu_has_the_hifi_digest_and_repeats_from_its_report() {
    let dir = scratch("fmu-import-run");
    let fmu = hifi_fmu(&dir, "3");
    let digest = |propulsion: &str, report: &Path| {
        let out = run_oils(&[
            "run",
            "--propulsion",
            propulsion,
            "--link",
            "inproc",
            "--duration",
            "120",
            "--no-log",
            "--report",
            arg(report),
        ]);
        assert!(out.status.success(), "{}", text(&out));
        common::report(report)["digest"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let (r_hifi, r_fmu) = (dir.join("hifi.json"), dir.join("fmu.json"));
    let hifi = digest("hifi", &r_hifi);
    let with_fmu = digest(&format!("fmu:{}", fmu.display()), &r_fmu);
    assert_eq!(with_fmu, hifi);
    let r = common::report(&r_fmu);
    assert_eq!(r["propulsion"], "fmu");
    assert_eq!(r["config"]["propulsion_fmu"], arg(&fmu));
    // The report rebuilds the run: the same FMU, the same digest.
    let again = dir.join("again.json");
    let out = run_oils(&[
        "run",
        "--config-from",
        arg(&r_fmu),
        "--no-log",
        "--report",
        arg(&again),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    assert_eq!(common::report(&again)["digest"], hifi.as_str());
}

#[test]
fn a_mapping_that_does_not_fit_the_fmu_is_refused_by_name() {
    let dir = scratch("fmu-import-errors");
    let fmu = hifi_fmu(&dir, "3");
    let mapping = |name: &str, step: &str, cmd: [&str; 4], on: [&str; 4]| {
        let p = dir.join(format!("{name}.toml"));
        let list = |v: [&str; 4]| {
            v.iter()
                .map(|s| format!("\"{s}\""))
                .collect::<Vec<_>>()
                .join(", ")
        };
        std::fs::write(
            &p,
            format!(
                "fmu = \"{}\"\n{step}\n[inputs]\nthrust_cmd_n = [{}]\non = [{}]\n[outputs]\nthrust_n = [\"thrust1_n\", \"thrust2_n\", \"thrust3_n\", \"thrust4_n\"]\ngas_pressure_pa = \"gas_pressure_pa\"\nejected_fuel_kg = \"ejected_fuel_kg\"\nejected_ox_kg = \"ejected_ox_kg\"\n",
                fmu.file_name().unwrap().to_str().unwrap(),
                list(cmd),
                list(on)
            ),
        )
        .unwrap();
        p
    };
    let cmd = ["cmd1_n", "cmd2_n", "cmd3_n", "cmd4_n"];
    let on = ["on1", "on2", "on3", "on4"];
    let good = mapping("good", "step_s = 0.01", cmd, on);
    let cases = [
        (
            mapping("missing", "", ["cmd1_n", "cmd2_n", "cmd3_n", "cmd9_n"], on),
            vec!["no variable `cmd9_n`", "inputs.thrust_cmd_n[3]"],
        ),
        (
            mapping("mistyped", "", ["on1", "cmd2_n", "cmd3_n", "cmd4_n"], on),
            vec![
                "`on1`",
                "inputs.thrust_cmd_n[0]",
                "of type Boolean",
                "a Float64",
            ],
        ),
        (
            mapping("causality", "", cmd, ["on1", "on2", "thrust3_n", "on4"]),
            vec!["`thrust3_n`", "inputs.on[2]", "causality output"],
        ),
        (
            mapping("step", "step_s = 0.003", cmd, on),
            vec![
                "step 0.003 s",
                "step_s of the variable mapping",
                "the surrogate's sample time 0.01 s",
            ],
        ),
    ];
    let cfg = small_config();
    for (path, words) in &cases {
        let truth = format!("fmu:{}", path.display());
        for command in ["train", "validate"] {
            let out_dir = dir.join(format!("out-{command}"));
            let mut args = vec![command, "--truth", &truth, "--out", arg(&out_dir)];
            if command == "train" {
                args.extend(["--config", &cfg, "--quiet", "--no-holdout"]);
            }
            let out = run_oils(&args);
            let t = text(&out);
            assert!(!out.status.success(), "{command} {}: {t}", path.display());
            for w in words {
                assert!(
                    t.contains(w),
                    "{command} {}: `{w}` not in: {t}",
                    path.display()
                );
            }
        }
    }
    // The plant step is named in a run's error.
    let out = run_oils(&[
        "run",
        "--propulsion",
        &format!("fmu:{}", good.display()),
        "--link",
        "inproc",
        "--dt-ms",
        "3",
        "--no-log",
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out).contains("does not fit the plant step 0.003 s"),
        "{}",
        text(&out)
    );
    // The same mapping with names that fit works, through the mapping file.
    let out = run_oils(&[
        "validate",
        "--truth",
        &format!("fmu:{}", good.display()),
        "--only",
        "sine-400",
        "--out",
        arg(&dir.join("v-good")),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    // Not an FMU at all.
    let bogus = dir.join("bogus.fmu");
    std::fs::write(&bogus, "not a zip").unwrap();
    let out = run_oils(&[
        "validate",
        "--truth",
        &format!("fmu:{}", bogus.display()),
        "--out",
        arg(&dir.join("v-bogus")),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out).contains("not a readable FMU archive"),
        "{}",
        text(&out)
    );
}
