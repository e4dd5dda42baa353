//! The onboard stub as `oils run` spawns it: started as a child process (this same
//! executable, `oils stub ...`), its standard error passed through while the last lines
//! are kept, and, once the run is over, reaped and told as a sentence ("killed by
//! SIGSEGV (signal 11)") with the outcome the stub wrote (`oils stub --outcome`), for the
//! run report.

use anyhow::{Context, Result};
use oils_emulator::report::OnboardProcess;
use oils_emulator::run_config::RunConfig;
use oils_emulator::session::StubLaunch;
use oils_shared::fsw::FswFailure;
use oils_shared::realtime::RealtimeStatus;
use std::collections::VecDeque;
use std::io::{BufRead, Write};
use std::os::unix::process::ExitStatusExt;
use std::path::PathBuf;
use std::process::{Child, Command as Process, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Lines of the stub's standard error a report keeps.
const TAIL_LINES: usize = 20;

/// How long the stub may take to exit once the run is over before it is killed.
const EXIT_GRACE: Duration = Duration::from_secs(3);

/// A stub spawned for a run.
pub struct SpawnedStub {
    child: Child,
    tail: Arc<Mutex<VecDeque<String>>>,
    forwarder: Option<JoinHandle<()>>,
    outcome: PathBuf,
}

/// How a spawned stub ended.
#[derive(Debug, Clone)]
pub struct StubEnd {
    /// Its process id.
    pub pid: u32,
    /// How it ended, as a sentence: `exited with status 1`, `killed by SIGSEGV (signal 11)`.
    pub ended: String,
    /// It exited with status 0.
    pub clean: bool,
    /// It was still running after the run and had to be killed.
    pub killed_after_run: bool,
    /// The step its flight software reported failed, from its outcome file.
    pub fsw_failure: Option<FswFailure>,
    /// The last lines of its standard error.
    pub stderr_tail: Vec<String>,
    /// What its stepping thread obtained (scheduling, memory lock, pinning), from its
    /// outcome file.
    pub realtime: Option<RealtimeStatus>,
    /// Frames it checked and handed over, and frames it missed, from its outcome file
    /// (both `None` for a run without frames).
    pub frames: Option<(u64, u64)>,
}

impl StubEnd {
    /// For the run report.
    pub fn process(&self) -> OnboardProcess {
        OnboardProcess {
            pid: self.pid,
            ended: self.ended.clone(),
            stderr_tail: self.stderr_tail.clone(),
            frames_checked: self.frames.map(|f| f.0),
            frames_missed: self.frames.map(|f| f.1),
        }
    }

    /// The last line it wrote that says something (its error), if any.
    pub fn last_words(&self) -> Option<&str> {
        self.stderr_tail
            .iter()
            .rev()
            .map(|l| l.trim())
            .find(|l| !l.is_empty())
    }
}

/// Starts `oils stub` for this run. `c_blake3`: the hash of the C library the run
/// records, which the stub must find in the file it loads.
pub fn spawn(
    cfg: &RunConfig,
    launch: &StubLaunch,
    c_blake3: Option<&str>,
    outcome: PathBuf,
) -> Result<SpawnedStub> {
    let exe = std::env::current_exe().context("locating the oils executable")?;
    let mut p = Process::new(exe);
    p.arg("stub")
        .arg("--run-id")
        .arg(format!("{:016x}", launch.run_id))
        .arg("--wait")
        .arg(launch.wait.as_str())
        .arg("--fsw")
        .arg(cfg.fsw.to_string())
        // The stub's patience with a live but silent emulator: a realtime run slowed
        // down by a speed factor has long periods, so never sooner than three of them (at
        // most 185 s: a period is at most 60 s). A dead emulator the stub notices within
        // about 0.1 s whatever this is (it watches the emulator's process).
        .arg("--timeout-ms")
        .arg((5000 + 3 * (cfg.dt_ms as f64 / cfg.speed) as u64).to_string())
        .arg("--outcome")
        .arg(&outcome)
        .stdin(Stdio::null())
        .stderr(Stdio::piped());
    if let Some(profile) = &cfg.profile {
        p.arg("--profile")
            .arg(profile)
            .arg("--max-thrust-n")
            .arg(cfg.scenario.propulsion.max_thrust_n.to_string());
    }
    // The reference GNC flies to the scenario's site (exact: Rust prints the shortest
    // representation that reads back to the same f64).
    p.arg(format!(
        "--site={},{}",
        cfg.scenario.site.latitude_deg, cfg.scenario.site.longitude_deg
    ));
    p.arg("--gnc-nav")
        .arg(cfg.gnc.navigation.as_str())
        .arg("--gnc-attitude")
        .arg(cfg.gnc.attitude.as_str());
    if let Some(map) = &cfg.gnc.map {
        p.arg("--gnc-map").arg(map);
    }
    if cfg.gnc.hazard_avoidance {
        p.arg("--gnc-hda");
    }
    if let Some(params) = &cfg.fsw_params {
        p.arg("--fsw-params").arg(params);
    }
    if let Some(hash) = c_blake3 {
        p.arg("--fsw-blake3").arg(hash);
    }
    if cfg.realtime_memory() {
        p.arg("--lock-memory");
    }
    if let Some(cpu) = cfg.stub_cpu() {
        p.arg("--cpu").arg(cpu.to_string());
    }
    let _ = std::fs::remove_file(&outcome);
    let mut child = p.spawn().context("spawning the onboard stub")?;
    let tail = Arc::new(Mutex::new(VecDeque::with_capacity(TAIL_LINES)));
    let forwarder = child.stderr.take().map(|stderr| {
        let tail = Arc::clone(&tail);
        std::thread::spawn(move || forward(stderr, &tail))
    });
    Ok(SpawnedStub {
        child,
        tail,
        forwarder,
        outcome,
    })
}

/// Copies the stub's standard error to ours line by line, keeping the last lines.
fn forward(stderr: std::process::ChildStderr, tail: &Mutex<VecDeque<String>>) {
    let mut ours = std::io::stderr();
    for line in std::io::BufReader::new(stderr).lines() {
        let Ok(line) = line else { break };
        let _ = writeln!(ours, "{line}");
        if let Ok(mut t) = tail.lock() {
            if t.len() == TAIL_LINES {
                t.pop_front();
            }
            t.push_back(line);
        }
    }
}

impl SpawnedStub {
    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Waits for it to exit (it has had the end-of-run telemetry, or died), killing it
    /// after [`EXIT_GRACE`]; says how it ended.
    pub fn reap(mut self) -> StubEnd {
        let pid = self.child.id();
        let until = Instant::now() + EXIT_GRACE;
        let (ended, clean, killed_after_run) = loop {
            match self.child.try_wait() {
                Ok(Some(status)) => break (describe(status), status.success(), false),
                Ok(None) if Instant::now() < until => std::thread::sleep(Duration::from_millis(5)),
                Ok(None) => {
                    let _ = self.child.kill();
                    let _ = self.child.wait();
                    break (
                        format!(
                            "was still running {} s after the run (stuck in its flight software?) and was killed",
                            EXIT_GRACE.as_secs()
                        ),
                        false,
                        true,
                    );
                }
                Err(e) => break (format!("could not be waited for: {e}"), false, false),
            }
        };
        // Its standard error closed with it: the tail is complete.
        if let Some(f) = self.forwarder.take() {
            let _ = f.join();
        }
        let stderr_tail = self
            .tail
            .lock()
            .map(|t| t.iter().cloned().collect())
            .unwrap_or_default();
        let outcome = std::fs::read_to_string(&self.outcome)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
        let field = |name: &str| outcome.as_ref().map(|v| v[name].clone());
        let fsw_failure = field("fsw_failure").and_then(|v| serde_json::from_value(v).ok());
        let realtime = field("realtime").and_then(|v| serde_json::from_value(v).ok());
        let count = |name: &str| field(name).and_then(|v| v.as_u64());
        let frames = count("frames")
            .zip(count("frames_missed"))
            .filter(|(n, missed)| n + missed > 0);
        let _ = std::fs::remove_file(&self.outcome);
        StubEnd {
            pid,
            ended,
            clean,
            killed_after_run,
            fsw_failure,
            stderr_tail,
            realtime,
            frames,
        }
    }
}

/// An exit status as a sentence.
fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exited with status {code}"),
        (None, Some(sig)) => {
            let core = if status.core_dumped() {
                ", core dumped"
            } else {
                ""
            };
            format!("killed by {} (signal {sig}{core})", signal_name(sig))
        }
        (None, None) => format!("ended ({status})"),
    }
}

/// The name of a signal number.
fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGSEGV => "SIGSEGV",
        libc::SIGBUS => "SIGBUS",
        libc::SIGFPE => "SIGFPE",
        libc::SIGILL => "SIGILL",
        libc::SIGABRT => "SIGABRT",
        libc::SIGKILL => "SIGKILL",
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        libc::SIGHUP => "SIGHUP",
        libc::SIGPIPE => "SIGPIPE",
        libc::SIGTRAP => "SIGTRAP",
        libc::SIGSYS => "SIGSYS",
        libc::SIGXCPU => "SIGXCPU",
        libc::SIGXFSZ => "SIGXFSZ",
        _ => "a signal",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statuses_read_as_sentences() {
        assert_eq!(describe(ExitStatus::from_raw(0)), "exited with status 0");
        assert_eq!(
            describe(ExitStatus::from_raw(3 << 8)),
            "exited with status 3"
        );
        assert_eq!(
            describe(ExitStatus::from_raw(libc::SIGSEGV)),
            "killed by SIGSEGV (signal 11)"
        );
        assert_eq!(
            describe(ExitStatus::from_raw(libc::SIGSEGV | 0x80)),
            "killed by SIGSEGV (signal 11, core dumped)"
        );
    }
}
