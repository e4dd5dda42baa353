//! `oils run`: flags (and `--config FILE.toml` / `--config-from REPORT.json`) become a
//! `RunConfig`; the emulator runs here; over iceoryx2 the onboard stub is spawned as a
//! separate OS process (this same executable, `oils stub ...`).

use super::stub_process::{self, SpawnedStub, StubEnd};
use anyhow::{bail, Context, Result};
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::report::{FswLibrary, RunReport};
use oils_emulator::run_config::{load_scenario, LinkKind, RunConfig, TelemetrySource, WaitKind};
use oils_emulator::scheduler::{MissPolicy, Mode, Outcome};
use oils_emulator::session::{self, Extras, Onboard, SessionError, StubLaunch};
use oils_lab::mcap_log::McapOpener;
use oils_onboard_stub::c_library::file_blake3;
use oils_onboard_stub::fsw::FswSpec;
use oils_onboard_stub::runner::STUCK_EXIT_CODE;
use oils_shared::link::LinkError;
use oils_shared::service::RunServices;
use std::path::PathBuf;
use std::time::Duration;

/// `--propulsion`: a model the core builds, or `fmu:PATH`.
#[derive(Debug, Clone, PartialEq)]
pub struct PropulsionArg {
    /// The model.
    pub kind: PropulsionKind,
    /// The FMU or its mapping (`fmu:PATH`).
    pub fmu: Option<PathBuf>,
}

impl std::str::FromStr for PropulsionArg {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match oils_lab::fmu::import::FmuSource::parse(s) {
            Some(src) => Ok(Self {
                kind: PropulsionKind::Fmu,
                fmu: Some(src.map_err(|e| e.to_string())?.given),
            }),
            None if s == "fmu" => {
                Err("fmu needs its file: fmu:MODEL.fmu or fmu:MAPPING.toml".into())
            }
            None => Ok(Self {
                kind: s.parse()?,
                fmu: None,
            }),
        }
    }
}

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
    /// Plant integration period in milliseconds (1-100), the schedule's base tick.
    /// [default: 10]
    #[arg(long)]
    pub dt_ms: Option<u64>,
    /// Flight-software cycle in milliseconds (a whole multiple of --dt-ms): one
    /// telemetry/command exchange per cycle. [default: the smallest multiple of --dt-ms
    /// of at least 10 ms]
    #[arg(long, value_name = "MS")]
    pub fsw_period_ms: Option<u64>,
    /// Longest simulated time, seconds; the run ends `completed` if still flying.
    /// [default: 2000]
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// What the telemetry carries: nav (the ideal navigation source: true state plus
    /// noise), sensors (the device samples: IMU, star tracker, altimeters, velocimeter)
    /// or both. With sensors or both and no --dt-ms, the plant steps at 5 ms (the IMU's
    /// 200 Hz). [default: nav]
    #[arg(long, value_name = "nav|sensors|both")]
    pub telemetry: Option<oils_emulator::run_config::TelemetrySource>,
    /// What the reference GNC navigates from: bench (the ideal navigation source) or
    /// sensors (its error-state Kalman filter on the device samples, started from the
    /// ground's state vector; needs --telemetry sensors or both). [default: sensors with
    /// --telemetry sensors (the telemetry has no ideal navigation source), else bench]
    #[arg(long, value_name = "bench|sensors")]
    pub gnc_nav: Option<oils_shared::fsw::GncNavigation>,
    /// Terrain navigation data for the reference GNC (`oils map`): it navigates by the
    /// camera's frames against this map (implies --gnc-nav sensors, and --telemetry
    /// sensors unless given; needs the camera on board, as in --scenario pinpoint).
    #[arg(long, value_name = "MAP")]
    pub gnc_map: Option<std::path::PathBuf>,
    /// Hazard detection and avoidance by the reference GNC at the hover, from the flash
    /// lidar: on or off [default: off] (needs sensor navigation and the lidar on board).
    #[arg(long, value_name = "on|off", value_parser = ["on", "off"])]
    pub gnc_hda: Option<String>,
    /// What the reference GNC turns the vehicle with: torque (the ideal torque actuator)
    /// or thrusters (the eight attitude thrusters, pulse-width modulated).
    /// [default: torque]
    #[arg(long, value_name = "torque|thrusters")]
    pub gnc_attitude: Option<oils_shared::fsw::GncAttitude>,
    /// Propulsion model: surrogate (the learned model of the seed paper), hifi
    /// (physics, the truth model), ideal (first-order lag) or shadow (hifi drives, the
    /// surrogate runs beside it). [default: surrogate]
    /// fmu:PATH: the user's FMU (FMI 2.0/3.0 co-simulation) or its variable-mapping
    /// TOML (docs/fmu.md) as the truth in the loop.
    #[arg(long, value_name = "MODEL")]
    pub propulsion: Option<PropulsionArg>,
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
    /// Scenario: a name (default, terminal-descent), a TOML file overriding any default
    /// (template: emulator/config/scenario.toml), or a failure scenario flown on the
    /// GNC's own navigation: rim-jump, imu-reset, hot-engines, altimeter-inhibited
    /// (docs/gnc.md). Navigation noise stays as --nav-noise says.
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
    /// (1-99), memory locked (as in every realtime run). Needs root or CAP_SYS_NICE:
    /// refused, the run fails.
    #[arg(long)]
    pub rt_priority: Option<i32>,
    /// Pin the stepping threads to cores: `EMULATOR[,STUB]`, the emulator's stepping
    /// thread on the first CPU, the spawned stub's on the second (`--cpus 0,1`; one CPU:
    /// the stub is not pinned). Each must be online and allowed to this process; a pin
    /// the kernel refuses is a warning in the report.
    #[arg(long, value_name = "EMU[,STUB]")]
    pub cpus: Option<CpuList>,
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
    /// With --link inproc: fly a C library (`--fsw c:PATH`) in this process, without the
    /// stub process's isolation (refused otherwise): a crash of the library ends
    /// `oils run` without a report; a step that never returns is given up, with a
    /// report, after the link timeout.
    #[arg(long)]
    pub allow_inproc_c: bool,
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
             duration => duration_s, fsw => fsw, seed => seed,
             miss_policy => miss_policy, deadline_frac => deadline_frac,
             wake_spin_us => wake_spin_us, link_timeout_ms => link_timeout_ms,
             startup_timeout_ms => startup_timeout_ms);
        if let Some(t) = self.telemetry {
            cfg.set_telemetry(t, self.dt_ms.is_some());
        }
        if let Some(n) = self.gnc_nav {
            cfg.gnc.navigation = n;
        }
        if let Some(a) = self.gnc_attitude {
            cfg.gnc.attitude = a;
        }
        if let Some(p) = &self.propulsion {
            cfg.propulsion = p.kind;
            cfg.propulsion_fmu = p.fmu.clone();
        }
        if let Some(p) = self.fsw_period_ms {
            cfg.fsw_period_ms = Some(p);
        }
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
        if let Some(c) = &self.cpus {
            cfg.cpus = c.0.clone();
        }
        if let Some(path) = &self.hifi_params {
            cfg.hifi = Some(HifiParams::load(path).context("--hifi-params")?);
        }
        if let Some(f) = self
            .scenario
            .as_deref()
            .and_then(oils_emulator::failure_scenarios::failure_scenario)
        {
            // A failure scenario: the default scenario with its devices, navigation and
            // faults (docs/gnc.md, "Failure scenarios").
            f.apply(&mut cfg).context("--scenario")?;
            if let Some(t) = &f.terrain {
                // Its onboard map, made once (the ground segment's work, before the run).
                let path = std::path::Path::new(t.map_file);
                if !path.exists() {
                    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                        std::fs::create_dir_all(dir)
                            .with_context(|| format!("creating {}", dir.display()))?;
                    }
                    eprintln!(
                        "oils run: making the onboard map {} for --scenario {} (once; oils map --scenario pinpoint{})",
                        path.display(),
                        f.name,
                        t.shift_feature.map_or(String::new(), |v| format!(
                            " --shift-feature {}",
                            v.map(|x| x.to_string()).join(",")
                        ))
                    );
                    super::map::run(&super::map::MapArgs {
                        scenario: "pinpoint".into(),
                        out: path.to_path_buf(),
                        spacings_m: super::map::DEFAULT_SPACINGS_M.to_vec(),
                        cells: 1024,
                        sun_az_el: None,
                        shift_feature: t.shift_feature.map(|v| v.to_vec()),
                    })
                    .context("making the scenario's onboard map")?;
                }
            }
            // What the command line says explicitly still wins.
            set!(dt_ms => dt_ms, telemetry => telemetry);
            if let Some(n) = self.gnc_nav {
                cfg.gnc.navigation = n;
            }
        } else if let Some(s) = &self.scenario {
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
        if self.telemetry == Some(TelemetrySource::Sensors)
            && self.gnc_nav.is_none()
            && cfg.fsw == FswSpec::Gnc
        {
            // Sensors only, no ideal navigation source: the reference GNC flies on its own
            // filter (an explicit --gnc-nav bench still asks for the refusal). Decided
            // last, once --fsw and --no-stub have said who flies.
            cfg.gnc.navigation = oils_shared::fsw::GncNavigation::Sensors;
        }
        if let Some(h) = &self.gnc_hda {
            cfg.gnc.hazard_avoidance = h == "on";
        }
        if let Some(map) = &self.gnc_map {
            cfg.gnc.map = Some(map.clone());
            if self.gnc_nav.is_none() {
                cfg.gnc.navigation = oils_shared::fsw::GncNavigation::Sensors;
            }
            if self.telemetry.is_none() && !cfg.telemetry.sensors() {
                cfg.set_telemetry(TelemetrySource::Sensors, self.dt_ms.is_some());
            }
        }
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

/// `--cpus EMU[,STUB]`: one or two CPU numbers (the syntax here; whether they are
/// online, before tick 0).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CpuList(pub Vec<usize>);

impl std::str::FromStr for CpuList {
    type Err = oils_shared::realtime::CpusError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        oils_shared::realtime::parse_cpus(s).map(CpuList)
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
        // The schedule as it will run: the flight-software period resolved, and every
        // period (the propulsion model's too) in a table of its own.
        let mut shown = cfg.clone();
        shown.fsw_period_ms = Some(cfg.fsw_period_ns() / 1_000_000);
        print!("{}", shown.to_toml());
        let propulsion_ns = oils_emulator::propulsion::model_period_ns(&cfg.propulsion_spec())
            .context("reading the propulsion model's period")?;
        println!("\n# The schedule (derived; integer nanoseconds, base tick = plant period):");
        println!("# [schedule]");
        println!("# base_tick_period_ns = {}", cfg.dt_ns());
        println!("# plant_period_ns = {}", cfg.dt_ns());
        println!("# propulsion_period_ns = {propulsion_ns}");
        println!("# fsw_period_ns = {}", cfg.fsw_period_ns());
        println!(
            "\n# Telemetry: {} (ideal navigation {}, devices {})",
            cfg.telemetry.as_str(),
            if cfg.telemetry.ideal_nav() {
                "on"
            } else {
                "off"
            },
            if cfg.telemetry.sensors() { "on" } else { "off" }
        );
        if cfg.fsw == oils_shared::fsw::FswSpec::Gnc {
            println!(
                "# Reference GNC: navigation {}, attitude {}",
                cfg.gnc.navigation, cfg.gnc.attitude
            );
        }
        if cfg.telemetry.sensors() {
            println!("# The sensor set and rates ([scenario.sensors]):");
            for line in cfg.scenario.sensors.summary().lines() {
                println!("# {line}");
            }
        }
        return Ok(());
    }
    if args.plots.is_some() && !cfg.log.enabled {
        bail!("--plots draws from the run's log: the configuration disables it (log.enabled)");
    }
    // Before tick 0: outputs that would overwrite one another (the log replaced by the
    // report: the log's lock covers other runs, not this run's own outputs).
    if let (true, Some(log), Some(report)) = (cfg.log.enabled, &cfg.log.path, &args.report) {
        super::refuse_aliases(&[("--log", log.as_path()), ("--report", report.as_path())])?;
    }
    // Before tick 0: a report or figures that cannot be written fail the run now.
    if let Some(path) = &args.report {
        let dir = path.parent().unwrap_or(std::path::Path::new("."));
        oils_emulator::report::check_writable_dir(dir).context("--report")?;
    }
    if let Some(dir) = &args.plots {
        oils_emulator::report::check_writable_dir(dir).context("--plots")?;
    }
    let fsw_library = match &cfg.fsw {
        FswSpec::CLibrary(path) => Some(FswLibrary {
            path: path.display().to_string(),
            blake3: file_blake3(path)?,
        }),
        _ => None,
    };
    if let Some(lib) = &fsw_library {
        check_against_report(args, lib)?;
        if cfg.link == LinkKind::Inproc && !args.allow_inproc_c {
            bail!(
                "--fsw {} with --link inproc: a C library in this process can take the run down with it \
                 (a crash ends `oils run` with no report, a step that never returns ignores Ctrl-C). \
                 Fly it over iceoryx2 (the default link): the stub process isolates it, and its crash, \
                 failure or hang is reported. Or pass --allow-inproc-c to fly it in this process anyway",
                cfg.fsw
            );
        }
    }
    let run_id = args.run_id()?;
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let run_id = run_id.unwrap_or_else(session::fresh_run_id);
    let mut stub_end = None;
    let result = match cfg.link {
        LinkKind::Inproc => fly_in_process(&cfg, run_id, &stop, fsw_library.as_ref(), args),
        LinkKind::Iceoryx2 => {
            // In the domain's private directory, which the session opens (and checks,
            // and repairs, with a note for the report) before it spawns the stub.
            let outcome = oils_shared::domain::Domain::default_root()
                .join(format!("stub-{run_id:016x}.outcome.json"));
            let mut spawned: Option<SpawnedStub> = None;
            let mut launch = |launch: &StubLaunch| {
                if cfg.fsw == FswSpec::External {
                    print_services(launch);
                    return Ok(None);
                }
                let hash = fsw_library.as_ref().map(|l| l.blake3.as_str());
                let stub = stub_process::spawn(&cfg, launch, hash, outcome.clone())
                    .map_err(|e| SessionError::Launch(format!("{e:#}")))?;
                let pid = stub.pid();
                spawned = Some(stub);
                Ok(Some(pid))
            };
            let by_hand = cfg.fsw == FswSpec::External;
            let mut joined = |peer: &oils_shared::link::PeerPort| {
                if by_hand {
                    eprintln!("oils: run {run_id:016x}: flight software joined ({peer})");
                }
            };
            let result = session::run(
                &cfg,
                run_id,
                &stop,
                Onboard::Peer(&mut launch),
                Extras {
                    sinks: Some(&McapOpener),
                    propulsion: Some(&oils_lab::fmu::import::build_for_run),
                    on_peer_joined: Some(&mut joined),
                    ..Default::default()
                },
            );
            stub_end = spawned.take().map(SpawnedStub::reap);
            result
        }
    };
    let signalled = stop.load(std::sync::atomic::Ordering::Relaxed);
    let mut report = match result {
        Ok(report) => report,
        Err(e) => {
            let never_joined = matches!(
                e,
                SessionError::Link(LinkError::PeerExited { .. } | LinkError::PeerTimeout { .. })
            );
            let why = match &stub_end {
                Some(end) if never_joined => {
                    let mut why = format!(
                        "onboard stub (pid {}) {} before it joined the run",
                        end.pid, end.ended
                    );
                    if let Some(words) = end.last_words() {
                        why.push_str(&format!(": {words}"));
                    }
                    why
                }
                _ => format!("{:#}", anyhow::Error::from(e)),
            };
            if never_joined && args.report.is_some() {
                // The flight software never came up: still a report, of a run aborted
                // before step 0, as asked.
                let mut report = RunReport::aborted_early(
                    &cfg,
                    run_id,
                    Some(cfg.wait_strategy()),
                    0,
                    why.clone(),
                );
                report.fsw_library = fsw_library;
                report.onboard_process = stub_end.as_ref().map(StubEnd::process);
                oils_emulator::report::finish_run(&report, args.report.as_deref())?;
            }
            bail!("bench run: {why}");
        }
    };
    report.fsw_library = fsw_library;
    if let Some(end) = &stub_end {
        tell_stub_end(&mut report, end, signalled);
    }
    if let Some(dir) = &args.plots {
        super::plot::after_run(&report, dir)?;
    }
    oils_emulator::report::finish_run(&report, args.report.as_deref())?;
    if let Some(end) = stub_end.filter(|e| !e.clean) {
        bail!("onboard stub (pid {}) {}", end.pid, end.ended);
    }
    Ok(())
}

/// Puts how the spawned stub ended into the report; when the run was aborted for its
/// sake (not by a signal to us), the error says what happened to it.
fn tell_stub_end(report: &mut RunReport, end: &StubEnd, signalled: bool) {
    report.onboard_process = Some(end.process());
    if let (Some(rt), Some(onboard)) = (&mut report.realtime, &end.realtime) {
        report.warnings.extend(
            onboard
                .warnings
                .iter()
                .map(|w| format!("onboard stub: {w}")),
        );
        rt.onboard = Some(onboard.clone());
    }
    if end.fsw_failure.is_some() {
        report.fsw_failure = end.fsw_failure;
    }
    let s = &mut report.summary;
    if s.outcome != Outcome::Aborted || end.clean || signalled {
        return;
    }
    let step = s.steps;
    let story = match end.fsw_failure {
        Some(f) => format!("{f}; onboard stub (pid {}) {}", end.pid, end.ended),
        None if end.killed_after_run => {
            let core = s.error.clone().unwrap_or_default();
            format!("{core}; onboard stub (pid {}) {}", end.pid, end.ended)
        }
        None => {
            let mut story = format!(
                "onboard stub (pid {}) {} at step {step}",
                end.pid, end.ended
            );
            if let Some(words) = end.last_words() {
                story.push_str(&format!(": {words}"));
            }
            story
        }
    };
    s.error = Some(story);
}

/// `--config-from REPORT` repeats a run: the C library it names must still be the file
/// that run flew (the report's `fsw_library.blake3`), unless `--fsw` names it anew.
fn check_against_report(args: &RunArgs, lib: &FswLibrary) -> Result<()> {
    let (Some(from), None) = (&args.config_from, &args.fsw) else {
        return Ok(());
    };
    let text = std::fs::read_to_string(from)
        .with_context(|| format!("--config-from {}", from.display()))?;
    let Ok(report) = serde_json::from_str::<serde_json::Value>(&text) else {
        return Ok(()); // RunConfig::load_from_report has said what is wrong with it.
    };
    let Ok(then) = serde_json::from_value::<FswLibrary>(report["fsw_library"].clone()) else {
        return Ok(()); // a configuration file, or a report without the hash
    };
    if then.path == lib.path && !then.blake3.eq_ignore_ascii_case(&lib.blake3) {
        bail!(
            "--config-from {}: c:{} has changed since that run (BLAKE3 then {}, now {}): \
             the run would not repeat. Restore the file, or pass --fsw c:{} to fly it as it is now",
            from.display(),
            lib.path,
            then.blake3,
            lib.blake3,
            lib.path
        );
    }
    Ok(())
}

/// Flies the run in this process. A C library (allowed by `--allow-inproc-c`) is
/// built checked against the hash the report records, and watched: a step that does not
/// return within the link timeout (the first within the start-up timeout), or within a
/// second of a termination signal, ends the process with a report (see
/// [`InProcessWatchdog`]).
fn fly_in_process(
    cfg: &RunConfig,
    run_id: u64,
    stop: &std::sync::Arc<std::sync::atomic::AtomicBool>,
    fsw_library: Option<&FswLibrary>,
    args: &RunArgs,
) -> Result<RunReport, SessionError> {
    let rules = oils_shared::profile::ProfileRules::rated(cfg.scenario.propulsion.max_thrust_n);
    let fsw = oils_onboard_stub::build::build_fsw_expecting(
        &cfg.fsw,
        cfg.profile.as_deref().map(|p| (p, &rules)),
        cfg.fsw_params.as_deref(),
        run_id,
        fsw_library.map(|l| l.blake3.as_str()),
        Some(oils_lab::onboard::site_target(&cfg.scenario)),
        cfg.gnc.clone(),
    )
    .map_err(|e| SessionError::Onboard(format!("building the flight software: {e}")))?;
    let extras = |observer| Extras {
        sinks: Some(&McapOpener),
        observer,
        propulsion: Some(&oils_lab::fmu::import::build_for_run),
        on_peer_joined: None,
        untimed: false,
    };
    let Some(lib) = fsw_library else {
        return session::run(cfg, run_id, stop, Onboard::InProcess(fsw), extras(None));
    };
    let watchdog = InProcessWatchdog::start(cfg, run_id, lib, stop, args.report.clone());
    let progress = watchdog.progress();
    let mut observe = |k: u64, _: &oils_emulator::plant::Plant| progress.stepped(k);
    let result = session::run(
        cfg,
        run_id,
        stop,
        Onboard::InProcess(fsw),
        extras(Some(&mut observe)),
    );
    watchdog.finish();
    result
}

/// What `oils run --link inproc` with a C library watches: the steps it completes.
#[derive(Default)]
struct Progress {
    /// Steps completed.
    steps: std::sync::atomic::AtomicU64,
    /// When the last one completed, monotonic nanoseconds.
    at_ns: std::sync::atomic::AtomicU64,
}

impl Progress {
    /// Called after each step (two relaxed stores; no allocation).
    fn stepped(&self, k: u64) {
        use std::sync::atomic::Ordering::Relaxed;
        self.steps.store(k + 1, Relaxed);
        self.at_ns
            .store(oils_shared::clock::monotonic_ns(), Relaxed);
    }
}

/// A thread that ends `oils run` when an in-process C library does not return from its
/// step: it prints why, writes the report asked for (aborted at that step; the log holds
/// every step before it) and exits with status 3, since the stuck thread cannot be
/// stopped otherwise.
struct InProcessWatchdog {
    progress: std::sync::Arc<Progress>,
    done: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl InProcessWatchdog {
    fn start(
        cfg: &RunConfig,
        run_id: u64,
        lib: &FswLibrary,
        stop: &std::sync::Arc<std::sync::atomic::AtomicBool>,
        report: Option<PathBuf>,
    ) -> Self {
        use std::sync::atomic::Ordering::Relaxed;
        let progress = std::sync::Arc::new(Progress::default());
        progress
            .at_ns
            .store(oils_shared::clock::monotonic_ns(), Relaxed);
        let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (p, d, stop) = (progress.clone(), done.clone(), stop.clone());
        let (cfg, lib) = (cfg.clone(), lib.clone());
        let thread = std::thread::spawn(move || {
            let mut signalled_at = None;
            while !d.load(Relaxed) {
                std::thread::sleep(Duration::from_millis(50));
                let now = oils_shared::clock::monotonic_ns();
                let step = p.steps.load(Relaxed);
                let waited_ms = now.saturating_sub(p.at_ns.load(Relaxed)) / 1_000_000;
                let budget_ms = if step == 0 {
                    cfg.startup_timeout_ms
                } else {
                    cfg.link_timeout_ms
                };
                if stop.load(Relaxed) {
                    signalled_at.get_or_insert(now);
                }
                let after_signal_ms = signalled_at.map_or(0, |t| now.saturating_sub(t) / 1_000_000);
                if d.load(Relaxed) || (waited_ms < budget_ms && after_signal_ms < 1000) {
                    continue;
                }
                let why = format!(
                    "the in-process flight software (c:{}) has not returned from step {step} for {waited_ms} ms{}; the run cannot be stopped otherwise (--allow-inproc-c), so `oils run` exits",
                    lib.path,
                    if signalled_at.is_some() { ", after a termination signal" } else { "" }
                );
                if let Some(path) = &report {
                    let mut r = RunReport::aborted_early(&cfg, run_id, None, step, why.clone());
                    r.fsw_library = Some(lib.clone());
                    let _ = oils_emulator::report::finish_run(&r, Some(path));
                }
                eprintln!("error: bench run: {why}");
                // SAFETY: ends the process; the thread stuck in the library cannot be
                // unwound. The log writer has written every record it was handed.
                unsafe { libc::_exit(STUCK_EXIT_CODE) };
            }
        });
        Self {
            progress,
            done,
            thread: Some(thread),
        }
    }

    fn progress(&self) -> std::sync::Arc<Progress> {
        self.progress.clone()
    }

    fn finish(mut self) {
        self.done.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
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
    for w in &log.warnings {
        eprintln!("oils replay: {}: {w}", args.log.display());
    }
    let r = session::replay(&args.log, log, &stop)?;
    println!(
        "oils replay: {} records of {} replayed, every telemetry identical",
        r.records,
        args.log.display()
    );
    if let Some(note) = &r.note {
        println!("oils replay: {note}");
    }
    // The replay held: a verdict on the recorded run (aborted, crashed) is in the table
    // and the report, not the replay's exit status; a report that cannot be written is.
    match oils_emulator::report::finish_run(&r.report, args.report.as_deref()) {
        Err(e @ oils_emulator::report::RunFailed::ReportFile { .. }) => Err(e.into()),
        Err(oils_emulator::report::RunFailed::Verdict(v)) => {
            println!("oils replay: the recorded run: {v}");
            Ok(())
        }
        Ok(()) => Ok(()),
    }
}
