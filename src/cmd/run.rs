//! `oils run`: flags (and `--config FILE.toml` / `--config-from REPORT.json`) become a
//! `RunConfig`; the emulator runs here; over iceoryx2 the onboard stub is spawned as a
//! separate OS process (this same executable, `oils stub ...`).

use anyhow::{bail, Context, Result};
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::run_config::{load_scenario, LinkKind, RunConfig, WaitKind};
use oils_emulator::scheduler::{MissPolicy, Mode};
use oils_emulator::session::{self, Extras, Onboard, SessionError, StubLaunch};
use oils_lab::mcap_log::McapOpener;
use oils_onboard_stub::fsw::FswSpec;
use oils_shared::service::RunServices;
use std::path::PathBuf;
use std::process::{Child, Command as Process, Stdio};
use std::time::{Duration, Instant};

/// Arguments of a bench run. Every flag is optional: what is not given comes from
/// `--config` / `--config-from`, else from `RunConfig::default()`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RunArgs {
    /// Run configuration TOML (any subset of fields; template: `oils run --print-config`).
    #[arg(long, value_name = "TOML", conflicts_with = "config_from")]
    pub config: Option<PathBuf>,
    /// Repeat an earlier run: its JSON report (the `config` key) or a configuration JSON.
    #[arg(long, value_name = "JSON")]
    pub config_from: Option<PathBuf>,
    /// Print the run configuration these flags give, as TOML, and exit.
    #[arg(long)]
    pub print_config: bool,
    /// iceoryx2: the flight software in a separate process over shared memory (the
    /// bench, with timing); inproc: called in the emulator's thread (same digest, fast).
    /// [default: iceoryx2]
    #[arg(long, value_name = "LINK")]
    pub link: Option<LinkKind>,
    /// lockstep: wait for each command (deterministic); realtime: pace against the
    /// clock. [default: lockstep]
    #[arg(long, value_name = "MODE")]
    pub mode: Option<Mode>,
    /// Realtime speed factor (2 = twice real time). [default: 1]
    #[arg(long)]
    pub speed: Option<f64>,
    /// Step in milliseconds (1-100). [default: 10]
    #[arg(long)]
    pub dt_ms: Option<u64>,
    /// Longest simulated time, seconds; the run ends `completed` if still flying.
    /// [default: 2000]
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Propulsion model: surrogate (the learned model of the seed paper), hifi
    /// (physics, the truth model), ideal (first-order lag) or shadow (hifi drives, the
    /// surrogate runs beside it). [default: surrogate]
    #[arg(long, value_name = "MODEL")]
    pub propulsion: Option<PropulsionKind>,
    /// Hifi parameter TOML for hifi|shadow (any subset of emulator/config/hifi.toml).
    #[arg(long, value_name = "TOML")]
    pub hifi_params: Option<PathBuf>,
    /// Surrogate model file for surrogate|shadow (default: the committed model).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Flight software: gnc, playback (with --profile), c:PATH (a shared library with
    /// the C ABI), external (a client you start; same as --no-stub). [default: gnc]
    #[arg(long, value_name = "FSW")]
    pub fsw: Option<FswSpec>,
    /// Thrust-command profile CSV for `--fsw playback`.
    #[arg(long, value_name = "CSV")]
    pub profile: Option<PathBuf>,
    /// Parameter file handed to a C flight software's init (`--fsw c:PATH`).
    #[arg(long, value_name = "FILE")]
    pub fsw_params: Option<PathBuf>,
    /// Seed of every random stream (navigation noise, ...). [default: 0]
    #[arg(long)]
    pub seed: Option<u64>,
    /// Seeded navigation noise on the telemetry: on or off. [default: on]
    #[arg(long, value_name = "ON|OFF", value_parser = ["on", "off"])]
    pub nav_noise: Option<String>,
    /// Scenario: a name (default) or a TOML file overriding any default (template:
    /// emulator/config/scenario.toml). Navigation noise stays as --nav-noise says.
    #[arg(long, value_name = "NAME|TOML")]
    pub scenario: Option<String>,
    /// Write the JSON report here.
    #[arg(long, value_name = "JSON")]
    pub report: Option<PathBuf>,
    /// Log file (default: oils-out/<run id>.oilslog).
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Do not write a log.
    #[arg(long, conflicts_with = "log")]
    pub no_log: bool,
    /// Log format: oilslog (binary records) or mcap (opens in Foxglove). [default: oilslog]
    #[arg(long, value_name = "FORMAT")]
    pub log_format: Option<oils_emulator::recorder::LogFormat>,
    /// At the end of the run, draw its figures (PNG) from its log into DIR.
    #[arg(long, value_name = "DIR", conflicts_with = "no_log")]
    pub plots: Option<PathBuf>,
    /// How the emulator waits for commands over iceoryx2: busy, event or hybrid
    /// (default: busy in lockstep, hybrid in realtime).
    #[arg(long, value_name = "WAIT")]
    pub wait: Option<WaitKind>,
    /// Realtime deadline-miss policy: hold, zero or abort:N. [default: hold]
    #[arg(long, value_name = "POLICY")]
    pub miss_policy: Option<MissPolicy>,
    /// Realtime: a command must arrive within this fraction of a period. [default: 0.5]
    #[arg(long)]
    pub deadline_frac: Option<f64>,
    /// Realtime: spin this many microseconds before each step start. [default: 200]
    #[arg(long)]
    pub wake_spin_us: Option<u64>,
    /// The flight software is declared dead after this long without a command,
    /// milliseconds. [default: 2000]
    #[arg(long)]
    pub link_timeout_ms: Option<u64>,
    /// How long to wait for the flight software to connect, milliseconds.
    /// [default: 10000]
    #[arg(long)]
    pub startup_timeout_ms: Option<u64>,
    /// Run the emulator (and the stub it spawns) under SCHED_FIFO at this priority
    /// (1-99) with memory locked. Needs root or CAP_SYS_NICE.
    #[arg(long)]
    pub rt_priority: Option<i32>,
    /// Run id (hex); default: a fresh one. It names the run's iceoryx2 services.
    #[arg(long)]
    pub run_id: Option<String>,
    /// Fail the run if the p99 wake error exceeds this, microseconds.
    #[arg(long)]
    pub max_wake_p99_us: Option<f64>,
    /// Fail the run if the p99 round trip exceeds this, microseconds.
    #[arg(long)]
    pub max_round_trip_p99_us: Option<f64>,
    /// Fail the run if the p99 transport exceeds this, microseconds.
    #[arg(long)]
    pub max_transport_p99_us: Option<f64>,
    /// Fail the run if there are more deadline misses than this.
    #[arg(long)]
    pub max_deadline_misses: Option<u64>,
    /// Inject a fault (repeatable): KIND[:TARGET][,P=V...]@TRIGGER[,for=S], e.g.
    /// engine-off:2@t=400 (README "Faults"). Added to the configuration's faults.
    #[arg(long = "fault", value_name = "SPEC")]
    pub faults: Vec<oils_emulator::faults::FaultSpec>,
    /// iceoryx2: let a new flight-software process take the run over when commands come
    /// from another process than the one that joined (a restarted stub); each take-over
    /// is reported. Default: such a command aborts the run.
    #[arg(long)]
    pub allow_reattach: bool,
    /// Do not spawn a stub: wait for flight software started by hand on the run's
    /// services (prints them); the report says `fsw: external`.
    #[arg(long)]
    pub no_stub: bool,
}

impl RunArgs {
    /// The run configuration: defaults, then the file, then every flag given.
    pub fn to_config(&self) -> Result<RunConfig> {
        let mut cfg = match (&self.config, &self.config_from) {
            (Some(path), _) => RunConfig::load_toml(path)?,
            (None, Some(path)) => RunConfig::load_from_report(path)?,
            (None, None) => RunConfig::default(),
        };
        macro_rules! set {
            ($($flag:ident => $field:ident),* $(,)?) => {
                $(if let Some(v) = &self.$flag { cfg.$field = v.clone(); })*
            };
        }
        set!(link => link, mode => mode, speed => speed, dt_ms => dt_ms,
             duration => duration_s, propulsion => propulsion, fsw => fsw, seed => seed,
             miss_policy => miss_policy, deadline_frac => deadline_frac,
             wake_spin_us => wake_spin_us, link_timeout_ms => link_timeout_ms,
             startup_timeout_ms => startup_timeout_ms);
        if let Some(p) = &self.model {
            cfg.model = Some(p.clone());
        }
        if let Some(p) = &self.profile {
            cfg.profile = Some(p.clone());
        }
        if let Some(p) = &self.fsw_params {
            cfg.fsw_params = Some(p.clone());
        }
        if let Some(w) = self.wait {
            cfg.wait = Some(w);
        }
        if let Some(p) = self.rt_priority {
            cfg.rt_priority = Some(p);
        }
        if let Some(path) = &self.hifi_params {
            cfg.hifi = Some(HifiParams::load(path).context("--hifi-params")?);
        }
        if let Some(s) = &self.scenario {
            // The noise switch is a run setting (--nav-noise), not the scenario file's.
            let noise = cfg.scenario.nav_noise.enabled;
            cfg.scenario = load_scenario(s).context("--scenario")?;
            cfg.scenario.nav_noise.enabled = noise;
        }
        if let Some(n) = &self.nav_noise {
            cfg.scenario.nav_noise.enabled = n == "on";
        }
        let t = &mut cfg.thresholds;
        if self.max_wake_p99_us.is_some() {
            t.max_wake_p99_us = self.max_wake_p99_us;
        }
        if self.max_round_trip_p99_us.is_some() {
            t.max_round_trip_p99_us = self.max_round_trip_p99_us;
        }
        if self.max_transport_p99_us.is_some() {
            t.max_transport_p99_us = self.max_transport_p99_us;
        }
        if self.max_deadline_misses.is_some() {
            t.max_deadline_misses = self.max_deadline_misses;
        }
        if self.no_log {
            cfg.log.enabled = false;
        }
        if let Some(p) = &self.log {
            cfg.log.enabled = true;
            cfg.log.path = Some(p.clone());
        }
        if let Some(f) = self.log_format {
            cfg.log.format = f;
        }
        if self.no_stub {
            cfg.fsw = FswSpec::External;
        }
        if self.allow_reattach {
            cfg.allow_reattach = true;
        }
        cfg.faults.extend(self.faults.iter().cloned());
        cfg.validate()?;
        Ok(cfg)
    }

    fn run_id(&self) -> Result<Option<u64>> {
        self.run_id
            .as_ref()
            .map(|s| {
                u64::from_str_radix(s.trim_start_matches("0x"), 16)
                    .with_context(|| format!("--run-id {s}: not a hex number"))
            })
            .transpose()
    }
}

/// The `oils run` flag that sets a run-configuration field (`dt_ms` is `--dt-ms`).
pub fn flag_of(field: &str) -> String {
    let name = field.strip_prefix("thresholds.").unwrap_or(field);
    match name {
        "duration_s" => "--duration".into(),
        "faults" => "--fault".into(),
        _ => format!("--{}", name.replace('_', "-")),
    }
}

/// Runs `oils run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let cfg = args.to_config()?;
    if args.print_config {
        print!("{}", cfg.to_toml());
        return Ok(());
    }
    if args.plots.is_some() && !cfg.log.enabled {
        bail!("--plots draws from the run's log: the configuration disables it (log.enabled)");
    }
    let run_id = args.run_id()?;
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let run_id = run_id.unwrap_or_else(session::fresh_run_id);
    let extras = || Extras {
        sinks: Some(&McapOpener),
        ..Default::default()
    };
    let mut child: Option<Child> = None;
    let mut stub_status = None;
    let report = match cfg.link {
        LinkKind::Inproc => {
            let fsw = oils_lab::onboard::flight_software(&cfg, run_id)
                .context("building the flight software")?;
            session::run(&cfg, run_id, &stop, Onboard::InProcess(fsw), extras())
        }
        LinkKind::Iceoryx2 => {
            let mut launch = |launch: &StubLaunch| {
                if cfg.fsw == FswSpec::External {
                    print_services(launch);
                    return Ok(());
                }
                child = Some(
                    spawn_stub(&cfg, launch).map_err(|e| SessionError::Launch(format!("{e:#}")))?,
                );
                Ok(())
            };
            let result = session::run(&cfg, run_id, &stop, Onboard::Peer(&mut launch), extras());
            stub_status = child.take().map(reap_stub);
            result
        }
    }
    .context("bench run")?;
    if let Some(dir) = &args.plots {
        super::plot::after_run(&report, dir)?;
    }
    oils_emulator::report::finish_run(&report, args.report.as_deref())?;
    if let Some(Err(e)) = stub_status {
        bail!("onboard stub: {e}");
    }
    Ok(())
}

/// What a flight software started by hand needs to join the run.
fn print_services(launch: &StubLaunch) {
    eprint!(
        "{}",
        RunServices::new(launch.run_id).client_guide(launch.wait)
    );
    // The emulator has just opened it; a client must use the same one.
    if let Ok(d) = oils_shared::domain::Domain::from_env() {
        eprintln!(
            "  iceoryx2 domain: root {}, prefix {} (set {} alike for your client)",
            d.root().display(),
            d.prefix(),
            oils_shared::domain::ROOT_ENV
        );
    }
}

/// Starts `oils stub` for this run, as a separate OS process.
fn spawn_stub(cfg: &RunConfig, launch: &StubLaunch) -> Result<Child> {
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
        .stdin(Stdio::null());
    if let Some(profile) = &cfg.profile {
        p.arg("--profile")
            .arg(profile)
            .arg("--max-thrust-n")
            .arg(cfg.scenario.propulsion.max_thrust_n.to_string());
    }
    if let Some(params) = &cfg.fsw_params {
        p.arg("--fsw-params").arg(params);
    }
    p.spawn().context("spawning the onboard stub")
}

/// Waits briefly for the stub to exit after the end-of-run telemetry; kills it if not.
fn reap_stub(mut child: Child) -> Result<(), String> {
    let until = Instant::now() + Duration::from_secs(3);
    loop {
        match child.try_wait() {
            Ok(Some(status)) if status.success() => return Ok(()),
            Ok(Some(status)) => return Err(format!("exited with {status}")),
            Ok(None) if Instant::now() < until => std::thread::sleep(Duration::from_millis(5)),
            Ok(None) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err("did not exit after the run; killed".into());
            }
            Err(e) => return Err(e.to_string()),
        }
    }
}

/// Arguments of `oils replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The log of the run to replay.
    pub log: PathBuf,
    /// Write the replay's JSON report here.
    #[arg(long, value_name = "JSON")]
    pub report: Option<PathBuf>,
}

/// Runs `oils replay`: the log's commands through the same plant and loop.
pub fn replay(args: &ReplayArgs) -> Result<()> {
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let log = oils_lab::mcap_log::read_any(&args.log)?;
    let r = session::replay(&args.log, log, &stop)?;
    println!(
        "oils replay: {} records of {} replayed, every telemetry identical",
        r.records,
        args.log.display()
    );
    oils_emulator::report::finish_run(&r.report, args.report.as_deref())?;
    Ok(())
}
