//! The run report: the JSON written with `--report PATH` and the compact table printed
//! at the end of every run.

use crate::run_config::RunConfig;
use crate::scheduler::{Mode, Outcome, RunSummary};
use crate::timing::Percentiles;
use oils_shared::fsw::FswFailure;
use oils_shared::link::WaitStrategy;
use oils_shared::realtime::RealtimeStatus;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Everything a run reports. Field names are the interface checks rely on.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Run id, hex.
    pub run_id: String,
    /// Pacing mode.
    pub mode: Mode,
    /// Realtime speed factor.
    pub speed: f64,
    /// Step, milliseconds.
    pub dt_ms: f64,
    /// Seed of every random stream.
    pub seed: u64,
    /// Propulsion model.
    pub propulsion: String,
    /// Flight software that flew: `gnc`, `playback`, `c` or `external` (a client
    /// started outside the bench).
    pub fsw: String,
    /// Link: `iceoryx2` or `inproc`.
    pub link: String,
    /// Wait strategy of the emulator (`none` in process).
    pub wait: String,
    /// Protocol version.
    pub protocol_version: u32,
    /// Log file, if any.
    pub log: Option<String>,
    /// The whole run configuration: `oils run --config-from REPORT.json` repeats the run.
    pub config: RunConfig,
    /// Things the run noticed that do not fail it (a peer that never notifies, a flight
    /// software that re-attached, ...).
    pub warnings: Vec<String>,
    /// With `--allow-reattach`: how often a new flight-software process took the run over.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reattachments: Option<u64>,
    /// The C library flown (`fsw = "c:PATH"`): its path and the BLAKE3 hash of the file
    /// loaded, so a repeat of the run can tell whether it flies the same code.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fsw_library: Option<FswLibrary>,
    /// The step the flight software reported failed, with the status it returned (a C
    /// step's nonzero return).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fsw_failure: Option<FswFailure>,
    /// How the onboard process started for the run ended (`oils run` spawning its stub).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub onboard_process: Option<OnboardProcess>,
    /// What the stepping threads obtained before tick 0 (scheduling class and priority,
    /// memory lock, pinning), read back from the kernel.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub realtime: Option<RealtimeReport>,
    /// The run's figures.
    #[serde(flatten)]
    pub summary: RunSummary,
}

impl RunReport {
    /// The report of a finished run.
    pub fn new(
        cfg: &RunConfig,
        run_id: u64,
        wait: Option<WaitStrategy>,
        log: Option<std::path::PathBuf>,
        summary: RunSummary,
    ) -> Self {
        Self {
            run_id: format!("{run_id:016x}"),
            mode: cfg.mode,
            speed: cfg.speed,
            dt_ms: cfg.dt_ms as f64,
            seed: cfg.seed,
            propulsion: cfg.propulsion.as_str().into(),
            fsw: cfg.fsw.kind_name().into(),
            link: cfg.link.as_str().into(),
            wait: wait.map_or("none", |w| w.as_str()).into(),
            protocol_version: oils_shared::PROTOCOL_VERSION,
            log: log.map(|p| p.display().to_string()),
            config: cfg.clone(),
            warnings: Vec::new(),
            reattachments: None,
            fsw_library: None,
            fsw_failure: None,
            onboard_process: None,
            realtime: None,
            summary,
        }
    }

    /// The report of a run that ended `aborted` before its loop could report: its flight
    /// software never joined, or never returned from step `steps`. No packet was
    /// exchanged after that step; the digest is empty.
    pub fn aborted_early(
        cfg: &RunConfig,
        run_id: u64,
        wait: Option<WaitStrategy>,
        steps: u64,
        error: String,
    ) -> Self {
        let summary = RunSummary {
            digest: String::new(),
            steps,
            plant_steps: steps * (cfg.fsw_period_ns() / cfg.dt_ns().max(1)),
            overruns: Vec::new(),
            outcome: Outcome::Aborted,
            error: Some(error),
            touchdown: None,
            sim_time_s: steps as f64 * cfg.fsw_period_ns() as f64 * 1e-9,
            propellant_used_kg: 0.0,
            rejected_commands: 0,
            rejected_values: 0,
            timing: Default::default(),
            threshold_violations: Vec::new(),
            log_records: 0,
            faults: Vec::new(),
            propulsion_diagnostics: None,
            sensors_dropped: None,
            fsw_report: None,
        };
        Self::new(cfg, run_id, wait, None, summary)
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }

    /// The compact table printed at the end of a run.
    pub fn table(&self) -> String {
        let s = &self.summary;
        let mut out = String::new();
        // What the telemetry carries and what the reference GNC navigates from, when
        // they are not the defaults (nav; the ideal navigation source).
        let mut fsw = self.fsw.clone();
        if self.config.fsw == oils_shared::fsw::FswSpec::Gnc
            && self.config.gnc.navigation == oils_shared::fsw::GncNavigation::Sensors
        {
            fsw.push_str(" (navigating on its own filter)");
        }
        let telemetry = match self.config.telemetry {
            crate::run_config::TelemetrySource::Nav => String::new(),
            t => format!("  telemetry {}", t.as_str()),
        };
        let _ = writeln!(
            out,
            "oils run {}  link {}  mode {:?}  dt {} ms  propulsion {}{telemetry}  fsw {fsw}  wait {}  seed {}",
            self.run_id,
            self.link,
            self.mode,
            self.dt_ms,
            self.propulsion,
            self.wait,
            self.seed
        );
        let outcome = format!("{:?}", s.outcome).to_uppercase();
        match &s.touchdown {
            Some(td) => {
                let why = match td.reason {
                    Some(r @ crate::plant::CrashReason::Slid) => format!(
                        " ({}: {:.2} m, up to {:.2} m/s)",
                        r.as_str(),
                        td.slide_m,
                        td.slide_speed_m_s
                    ),
                    Some(r) => format!(" ({})", r.as_str()),
                    None => String::new(),
                };
                let _ = writeln!(
                    out,
                    "outcome     {outcome}{why}: contact at t = {:.1} s, vertical {:.2} m/s, horizontal {:.2} m/s, slope {:.1} deg; ended t = {:.1} s, tilt {:.2} deg, propellant used {:.1} kg",
                    td.t_s, td.vertical_speed_mps, td.horizontal_speed_mps, td.slope_deg, td.end_t_s, td.tilt_deg, td.propellant_used_kg
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "outcome     {outcome} at t = {:.1} s, propellant used {:.1} kg",
                    s.sim_time_s, s.propellant_used_kg
                );
            }
        }
        if let Some(e) = &s.error {
            let _ = writeln!(out, "error       {e}");
        }
        let t = &s.timing;
        let _ = writeln!(
            out,
            "steps       {}  wall {:.3} s  realtime factor {:.1}x",
            s.steps, t.wall_s, t.realtime_factor
        );
        if s.plant_steps != s.steps {
            let _ = writeln!(
                out,
                "rates       {} flight-software cycles, {} plant steps",
                s.steps, s.plant_steps
            );
        }
        if s.overruns.iter().any(|o| o.count > 0) {
            let _ = write!(out, "overruns   ");
            for o in &s.overruns {
                let _ = write!(
                    out,
                    " {} {} ({} ms)",
                    o.group,
                    o.count,
                    o.period_ns as f64 * 1e-6
                );
            }
            let _ = writeln!(out);
        }
        let _ = writeln!(
            out,
            "timing (us)        p50       p99     p99.9       max     count"
        );
        let row = |out: &mut String, name: &str, p: &Percentiles| {
            if p.count == 0 {
                let _ = writeln!(
                    out,
                    "  {name:<13} {:>9} {:>9} {:>9} {:>9} {:>9}",
                    "-", "-", "-", "-", 0
                );
            } else {
                let us = |v: u64| v as f64 / 1000.0;
                let _ = writeln!(
                    out,
                    "  {name:<13} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9}",
                    us(p.p50),
                    us(p.p99),
                    us(p.p999),
                    us(p.max),
                    p.count
                );
            }
        };
        row(&mut out, "wake error", &t.wake_error_ns);
        row(&mut out, "round trip", &t.round_trip_ns);
        row(&mut out, "stub compute", &t.stub_compute_ns);
        row(&mut out, "transport", &t.transport_ns);
        let _ = writeln!(
            out,
            "deadline misses {}  late commands {}  rejected commands {} ({} values)",
            t.deadline_misses, t.late_commands, s.rejected_commands, s.rejected_values
        );
        for v in &s.threshold_violations {
            let _ = writeln!(out, "THRESHOLD   {v}");
        }
        for w in &self.warnings {
            let _ = writeln!(out, "WARNING     {w}");
        }
        if let Some(rt) = &self.realtime {
            let _ = write!(out, "realtime    emulator {}", rt.emulator.summary());
            if let Some(onboard) = &rt.onboard {
                let _ = write!(out, "; stub {}", onboard.summary());
            }
            let _ = writeln!(out);
        }
        if let Some(lib) = &self.fsw_library {
            let _ = writeln!(out, "fsw library {} (blake3 {})", lib.path, lib.blake3);
        }
        if let Some(p) = &self.onboard_process {
            let _ = writeln!(out, "onboard     pid {} {}", p.pid, p.ended);
        }
        for f in &s.faults {
            let cleared = f
                .cleared_t_s
                .map(|t| format!(", cleared at t = {t:.2} s"))
                .unwrap_or_default();
            let _ = writeln!(
                out,
                "fault       {} fired at t = {:.2} s (step {}){cleared}",
                f.spec, f.t_s, f.step
            );
        }
        if let Some(d) = &s.propulsion_diagnostics {
            diagnostics_lines(&mut out, d);
        }
        if let Some(f) = &s.fsw_report {
            fsw_report_lines(&mut out, f);
        }
        let _ = writeln!(out, "digest      {}", s.digest);
        if let Some(log) = &self.log {
            // The size the file has on disk now (the table is printed once the log is
            // closed); a file that cannot be read back shows no size.
            let size = std::fs::metadata(log)
                .map(|m| format!(", {}", human_bytes(m.len())))
                .unwrap_or_default();
            let _ = writeln!(out, "log         {log} ({} records{size})", s.log_records);
        }
        out
    }
}

/// Bytes in decimal units (`198.9 MB`), as `ls -lh --si` and file managers show them.
pub fn human_bytes(n: u64) -> String {
    const UNITS: [&str; 4] = ["kB", "MB", "GB", "TB"];
    if n < 1000 {
        return format!("{n} B");
    }
    let mut v = n as f64 / 1000.0;
    let mut unit = 0;
    while v >= 999.95 && unit + 1 < UNITS.len() {
        v /= 1000.0;
        unit += 1;
    }
    format!("{v:.1} {}", UNITS[unit])
}

/// A C flight-software library as flown.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FswLibrary {
    /// The path it was loaded from.
    pub path: String,
    /// BLAKE3 of the file's bytes when it was loaded, 64 hex digits.
    pub blake3: String,
}

/// What the stepping threads of a run obtained before tick 0.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct RealtimeReport {
    /// The emulator's stepping thread (in process: the flight software's too).
    pub emulator: RealtimeStatus,
    /// The onboard stub's, as the stub `oils run` spawned wrote it in its outcome
    /// (`None`: in process, a stub started by hand, or one that died before writing it).
    pub onboard: Option<RealtimeStatus>,
}

/// How the onboard process started for a run ended.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct OnboardProcess {
    /// Its process id.
    pub pid: u32,
    /// How it ended: `exited with status 0`, `killed by SIGSEGV (signal 11)`, ...
    pub ended: String,
    /// The last lines it wrote to its standard error.
    pub stderr_tail: Vec<String>,
    /// Frames (protocol v4) it read from their services and handed to its flight
    /// software, each checked against its announcement's length and XXH3-64 hash, as its
    /// outcome file says (absent: it wrote none, or the run had no frames).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_checked: Option<u64>,
    /// Frames announced that it did not find on their services.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_missed: Option<u64>,
}

/// The propulsion diagnostics in a few table lines.
fn diagnostics_lines(out: &mut String, d: &crate::propulsion::PropulsionDiagnostics) {
    if let Some(n) = d.out_of_envelope_steps {
        let _ = writeln!(
            out,
            "surrogate   {n} steps outside the training envelope (inputs clamped)"
        );
    }
    if let Some(g) = &d.surrogate_guards {
        let _ = writeln!(
            out,
            "guards      surrogate: {} steps with commands clamped to the on-range, {} with a non-finite prediction (previous value kept), {} with a prediction clamped to be physical, {} beyond its physical bound",
            g.clamped_commands, g.non_finite_predictions, g.clamped_predictions, g.bounded_predictions
        );
    }
    if let Some(n) = d.hifi_non_finite_rollbacks {
        let _ = writeln!(out, "quarantine  hifi: {n} non-finite steps rolled back");
    }
    if let Some(s) = &d.shadow {
        let thrust_max = s.thrust_n.iter().map(|t| t.max_abs).fold(0.0, f64::max);
        let thrust_rms = (s.thrust_n.iter().map(|t| t.rms * t.rms).sum::<f64>()
            / s.thrust_n.len() as f64)
            .sqrt();
        let _ = writeln!(
            out,
            "shadow      surrogate - hifi over {} steps: thrust max {:.2} N rms {:.2} N; gas max {:.3} bar rms {:.3} bar",
            s.steps,
            thrust_max,
            thrust_rms,
            s.gas_pressure_pa.max_abs * 1e-5,
            s.gas_pressure_pa.rms * 1e-5
        );
        let _ = writeln!(
            out,
            "            fuel max {:.3} kg, ox max {:.3} kg, total mass max {:.3} kg rms {:.3} kg",
            s.ejected_fuel_kg.max_abs,
            s.ejected_ox_kg.max_abs,
            s.total_mass_kg.max_abs,
            s.total_mass_kg.rms
        );
    }
}

/// The run did not pass.
#[derive(Debug, thiserror::Error)]
pub enum RunFailed {
    /// The report could not be written.
    #[error("writing report {path}")]
    ReportFile {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The run ended badly or broke a threshold.
    #[error("run failed: {0}")]
    Verdict(String),
}

/// Writes `bytes` to `path`, a new file created 0600 (a report holds the run's whole
/// configuration: share it on purpose).
pub fn write_private(path: &std::path::Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)?;
    f.write_all(bytes)
}

/// Checks, before a run starts, that a file can be written in `dir` (created if
/// missing): a read-only or unusable directory for `--report` or `--plots` then fails at
/// once, not after the whole run.
pub fn check_writable_dir(dir: &std::path::Path) -> Result<(), RunFailed> {
    let fail = |source| RunFailed::ReportFile {
        path: dir.display().to_string(),
        source,
    };
    let dir = if dir.as_os_str().is_empty() {
        std::path::Path::new(".")
    } else {
        dir
    };
    std::fs::create_dir_all(dir).map_err(fail)?;
    let probe = dir.join(format!(".oils-write-check-{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .map_err(fail)?;
    std::fs::remove_file(&probe).map_err(fail)
}

/// Prints the table, writes the JSON report if asked, and turns a bad run (aborted,
/// crashed, or a broken timing threshold) into an error, so the process exits non-zero.
pub fn finish_run(
    report: &RunReport,
    json_path: Option<&std::path::Path>,
) -> Result<(), RunFailed> {
    print!("{}", report.table());
    if let Some(path) = json_path {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|source| RunFailed::ReportFile {
                path: path.display().to_string(),
                source,
            })?;
        }
        write_private(path, (report.to_json() + "\n").as_bytes()).map_err(|source| {
            RunFailed::ReportFile {
                path: path.display().to_string(),
                source,
            }
        })?;
    }
    let s = &report.summary;
    let mut why = Vec::new();
    match s.outcome {
        crate::scheduler::Outcome::Aborted => {
            why.push(format!("aborted: {}", s.error.clone().unwrap_or_default()))
        }
        crate::scheduler::Outcome::Crashed => {
            why.push("touched down outside the limits".to_string())
        }
        _ => {}
    }
    for v in &s.threshold_violations {
        why.push(format!("threshold broken: {v}"));
    }
    if why.is_empty() {
        Ok(())
    } else {
        Err(RunFailed::Verdict(why.join("; ")))
    }
}

/// The flight software's own report, as table lines: navigation error at the end and
/// consistency, devices in use, boots, rate-group compute times.
fn fsw_report_lines(out: &mut String, f: &crate::fsw_monitor::FswSelfReport) {
    use oils_shared::{
        NAV_FLAG_LASER_LOST, NAV_FLAG_LASER_USED, NAV_FLAG_RF_USED, NAV_FLAG_STAR_TRACKER_USED,
        NAV_FLAG_VELOCIMETER_USED,
    };
    if let Some(e) = &f.nav_error {
        let source = if f.from_sensors { "sensors" } else { "bench" };
        let _ = writeln!(
            out,
            "navigation  from {source}: error at t = {:.1} s {:.1} m (radial {:.2} m, horizontal {:.1} m), velocity {:.3} m/s, height {:.2} m; own sigma {:.1} m; max {:.1} m",
            e.t_s,
            e.position_m,
            e.radial_m,
            e.horizontal_m,
            e.velocity_m_s,
            e.altitude_m,
            e.sigma_position_m,
            f.nav_error_max_position_m
        );
        if let (Some(w), Some(n)) = (f.nav_within_3_sigma, f.nav_nees_mean) {
            let _ = writeln!(
                out,
                "            within 3 sigma {:.1} % of cycles, mean NEES {:.2} (3 when consistent)",
                w * 100.0,
                n
            );
        }
        if f.from_sensors {
            let mut used = Vec::new();
            for (bit, name) in [
                (NAV_FLAG_STAR_TRACKER_USED, "star tracker"),
                (NAV_FLAG_LASER_USED, "laser altimeter"),
                (NAV_FLAG_RF_USED, "RF altimeter"),
                (NAV_FLAG_VELOCIMETER_USED, "velocimeter"),
            ] {
                if f.nav_flags & bit != 0 {
                    used.push(name);
                }
            }
            let lost = if f.nav_flags & NAV_FLAG_LASER_LOST != 0 {
                "; LASER ALTIMETER DECLARED LOST by the flight software"
            } else {
                ""
            };
            let _ = writeln!(
                out,
                "            in use at the end: {}{lost}",
                used.join(", ")
            );
            if let Some(t) = f.terrain_first_fix_s {
                let _ = writeln!(
                    out,
                    "            terrain navigation: first fix at t = {t:.1} s"
                );
            }
            if let Some(t) = f.terrain_lost_s {
                let _ = writeln!(
                    out,
                    "            TERRAIN NAVIGATION LOST by the flight software from t = {t:.1} s ({} cycles flagged): it flew on its inertial and altimeter estimate",
                    f.terrain_lost_cycles
                );
            }
        }
    }
    if f.boot_count > 1 {
        let _ = writeln!(
            out,
            "fsw         {} boots ({} computer resets)",
            f.boot_count,
            f.boot_count - 1
        );
    }
    // The reference GNC's groups (docs/gnc.md); another flight software's are numbered.
    const NAMES: [&str; 4] = ["navigation", "guidance", "control", "terrain"];
    for (name, g) in NAMES.iter().zip(f.group_compute_ns.iter()) {
        let _ = writeln!(
            out,
            "rate group  {name}: compute p50 {:.2} us, p99 {:.2} us, max {:.2} us ({} runs)",
            g.p50 as f64 / 1000.0,
            g.p99 as f64 / 1000.0,
            g.max as f64 / 1000.0,
            g.count
        );
    }
    if f.cycle_slips > 0 {
        let _ = writeln!(
            out,
            "CYCLE SLIPS {} (a rate group overran its period)",
            f.cycle_slips
        );
    }
}

#[cfg(test)]
mod size_tests {
    #[test]
    fn sizes_read_in_decimal_units() {
        use super::human_bytes;
        assert_eq!(human_bytes(999), "999 B");
        assert_eq!(human_bytes(198_945_972), "198.9 MB");
        assert_eq!(human_bytes(19_999_999), "20.0 MB");
        assert_eq!(human_bytes(999_960), "1.0 MB");
        assert_eq!(human_bytes(2_500_000_000), "2.5 GB");
    }
}
