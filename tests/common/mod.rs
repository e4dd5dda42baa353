//! Helpers for the end-to-end tests: they run the real `oils` binary, which talks to a
//! real onboard-stub process over real iceoryx2 shared memory.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `oils` binary cargo built for these tests.
pub fn oils() -> Command {
    Command::new(env!("CARGO_BIN_EXE_oils"))
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("oils-e2e-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// Runs `oils` with `args`, returns its output.
pub fn run_oils(args: &[&str]) -> Output {
    oils().args(args).output().expect("spawning oils")
}

/// Parses a JSON report.
pub fn report(path: &Path) -> serde_json::Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("report {}: {e}", path.display()));
    serde_json::from_str(&text).expect("report is JSON")
}

/// Text of both output streams, for assertion messages.
pub fn text(o: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A unique run id for tests that start the two processes by hand. Tests of one binary
/// run in parallel, so a tag taken twice would let two runs share services (the second
/// stub then fails with `ExceedsMaxSupportedPublishers`, depending on timing): a reused
/// tag fails here, every time.
pub fn run_id(tag: u64) -> String {
    static TAKEN: std::sync::Mutex<Vec<u64>> = std::sync::Mutex::new(Vec::new());
    let mut taken = TAKEN.lock().unwrap_or_else(|e| e.into_inner());
    assert!(
        !taken.contains(&tag),
        "run_id tag {tag:#x} is used twice in this test binary"
    );
    taken.push(tag);
    format!("{:016x}", (std::process::id() as u64) << 20 | tag)
}

/// Flies one run whose flight software is a client started by hand: `oils run --no-stub`
/// with `run_args` on run `run_id`, and `client` (which opens the run's services itself).
/// Returns the outputs of `oils run` and of the client.
pub fn fly_with_client(run_args: &[&str], run_id: &str, mut client: Command) -> (Output, Output) {
    use std::process::Stdio;
    let emulator = oils()
        .args(["run", "--no-stub", "--run-id", run_id])
        .args(run_args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawning oils run");
    let client_out = client
        .stdin(Stdio::null())
        .output()
        .expect("spawning the client");
    let emulator_out = emulator.wait_with_output().expect("waiting for oils run");
    (emulator_out, client_out)
}

/// The committed terminal-descent scenario.
pub fn terminal_descent_scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("emulator/config/scenarios/terminal-descent.toml")
}

/// Checks a report's touchdown against the scenario's `[touchdown]` limits.
pub fn assert_soft_touchdown(r: &serde_json::Value, scenario: &Path) {
    let scenario = oils_emulator::run_config::load_scenario(scenario.to_str().unwrap())
        .expect("scenario loads");
    let tilt_limit_deg = scenario.landing_limits().tilt_deg;
    let limits = scenario.touchdown;
    assert_eq!(r["outcome"], "landed", "{r}");
    let td = &r["touchdown"];
    assert!(
        td["vertical_speed_mps"].as_f64().unwrap() <= limits.vertical_speed_mps,
        "{td}"
    );
    assert!(
        td["horizontal_speed_mps"].as_f64().unwrap() <= limits.horizontal_speed_mps,
        "{td}"
    );
    assert!(td["tilt_deg"].as_f64().unwrap() <= tilt_limit_deg, "{td}");
    assert!(
        (td["tilt_limit_deg"].as_f64().unwrap() - tilt_limit_deg).abs() < 1e-9,
        "the report names the limit it judged against: {td}"
    );
}

/// A frozen digest of `tests/data/frozen-digests.toml` (`key` = propulsion model, or
/// `ideal_sensors`).
pub fn frozen_digest(key: &str) -> String {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/frozen-digests.toml"),
    )
    .unwrap();
    let table: toml::Table = toml::from_str(&text).unwrap();
    table[key].as_str().unwrap().to_string()
}

/// Runs `oils run --config FILE --link iceoryx2` on the run configuration `config_toml`
/// (across two processes) and returns its report.
pub fn report_across_processes(name: &str, config_toml: &str) -> serde_json::Value {
    let dir = scratch(name);
    let file = dir.join("run.toml");
    std::fs::write(&file, config_toml).unwrap();
    let rep = dir.join("report.json");
    let out = run_oils(&[
        "run",
        "--config",
        file.to_str().unwrap(),
        "--link",
        "iceoryx2",
        "--report",
        rep.to_str().unwrap(),
        "--no-log",
    ]);
    assert!(out.status.success(), "{}", text(&out));
    report(&rep)
}

/// The standard error of a running child, read line by line on a thread so a test can
/// wait for a line (`oils run --no-stub` prints "flight software joined" once the stub it
/// waits for has joined) and still read everything at the end.
pub struct StderrWatch {
    lines: std::sync::mpsc::Receiver<String>,
    seen: String,
}

impl StderrWatch {
    /// Takes `child`'s piped standard error.
    pub fn take(child: &mut std::process::Child) -> Self {
        let err = child.stderr.take().expect("stderr piped");
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(err).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self {
            lines,
            seen: String::new(),
        }
    }

    /// Waits for a line containing `needle`. A hang guard only (`secs`): it panics with
    /// what was printed if the line never comes or the stream ends first.
    pub fn wait_for(&mut self, needle: &str, secs: u64) {
        let until = std::time::Instant::now() + std::time::Duration::from_secs(secs);
        loop {
            let left = until.saturating_duration_since(std::time::Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    self.seen.push_str(&line);
                    self.seen.push('\n');
                    if line.contains(needle) {
                        return;
                    }
                }
                Err(_) => panic!("no line with `{needle}` within {secs} s:\n{}", self.seen),
            }
        }
    }

    /// Everything printed, once the stream has ended (the child has exited).
    pub fn rest(mut self) -> String {
        while let Ok(line) = self.lines.recv() {
            self.seen.push_str(&line);
            self.seen.push('\n');
        }
        self.seen
    }
}

/// What `oils run --no-stub` prints once the flight software it waits for has joined.
pub const JOINED: &str = "flight software joined";

/// The index of CSV column `name` in `header`.
pub fn column(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name}"))
}

/// A run flown in process with a log, and its CSV export.
pub struct LoggedRun {
    /// The run's report.
    pub report: serde_json::Value,
    /// The run's log.
    pub log: PathBuf,
    /// The CSV export's column names.
    pub header: Vec<String>,
    /// The CSV export's rows.
    pub rows: Vec<Vec<String>>,
}

/// Flies `config_toml` in process with a log (and `extra` `oils run` arguments, such as
/// `--fault SPEC`); returns the report and the CSV export.
pub fn fly_logged(name: &str, config_toml: &str, extra: &[&str]) -> LoggedRun {
    let dir = scratch(name);
    let file = dir.join("run.toml");
    std::fs::write(&file, config_toml).unwrap();
    let (log, rep, csv) = (
        dir.join("run.oilslog"),
        dir.join("report.json"),
        dir.join("run.csv"),
    );
    let mut args = vec![
        "run",
        "--config",
        file.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let out = run_oils(&args);
    assert!(out.status.success(), "{}", text(&out));
    let out = run_oils(&[
        "export",
        log.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let body = std::fs::read_to_string(&csv).unwrap();
    let mut lines = body.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    LoggedRun {
        report: report(&rep),
        log,
        header,
        rows,
    }
}
