//! `oils`: the one-command bench. `oils run` (the default) starts the emulator in this
//! process and spawns the onboard stub as a separate OS process (this same executable,
//! `oils stub ...`), so `cargo run --release` needs no other binary built.

mod cmd;

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};
use oils_emulator::session::{run_session, FswArg, RunArgs, SessionError};
use oils_onboard_stub::cli::{run_stub, StubArgs};
use std::path::PathBuf;
use std::process::{Child, Command as Process, Stdio};
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(
    name = "oils",
    version,
    about = "Onboard-in-loop simulation bench for a lunar lander"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Fly a run: emulator here, onboard stub as a child process (the default command).
    Run(Box<RunCmd>),
    /// Turn a run log into CSV.
    Export(ExportArgs),
    /// Drive the high-fidelity propulsion model open loop with a profile, or draw its figures.
    Hifi(cmd::hifi::HifiArgs),
    /// Train the propulsion surrogate (seed paper): excitation, data, Lasso, CV, model file.
    Train(cmd::train::TrainArgs),
    /// Validate the surrogate against the hifi model (paper's cases, bounds, plots, uncertainty).
    Validate(cmd::validate::ValidateArgs),
    /// Run the onboard stub (what `oils run` spawns; also usable by hand).
    #[command(hide = true)]
    Stub(StubArgs),
}

#[derive(clap::Args)]
struct RunCmd {
    #[command(flatten)]
    args: RunArgs,
    /// Do not spawn a stub: wait for one started by hand (prints the command).
    #[arg(long)]
    no_stub: bool,
}

#[derive(clap::Args)]
struct ExportArgs {
    /// The log file (`.oilslog`).
    log: PathBuf,
    /// Write every step as CSV here.
    #[arg(long, required_unless_present = "profile")]
    csv: Option<PathBuf>,
    /// Write the applied commands as a thrust-command profile CSV here (replayable with
    /// `oils run --fsw playback`, `oils hifi`, `oils validate`).
    #[arg(long)]
    profile: Option<PathBuf>,
    /// With --profile: keep one step in N (rows hold until the next).
    #[arg(long, default_value_t = 1)]
    every: usize,
}

/// Errors print as one chain of causes (no backtrace, whatever RUST_BACKTRACE says)
/// and exit with status 1.
fn main() {
    if let Err(e) = real_main() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn real_main() -> anyhow::Result<()> {
    // `cargo run --release` with no arguments: the default scenario, lockstep, spawned stub.
    let cli = if std::env::args_os().len() <= 1 {
        Cli::parse_from(["oils", "run"])
    } else {
        Cli::parse()
    };
    match cli.command {
        Cmd::Run(cmd) => run(*cmd),
        Cmd::Export(a) => export(&a),
        Cmd::Hifi(a) => cmd::hifi::run(&a),
        Cmd::Train(a) => cmd::train::run(&a),
        Cmd::Validate(a) => cmd::validate::run(&a),
        Cmd::Stub(a) => {
            let stop =
                oils_shared::signals::termination_flag().context("installing signal handlers")?;
            run_stub(&a, &stop).with_context(|| format!("onboard stub on run {}", a.run_id))?;
            Ok(())
        }
    }
}

fn run(cmd: RunCmd) -> anyhow::Result<()> {
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let args = cmd.args;
    let mut child: Option<Child> = None;
    let result = run_session(&args, &stop, &mut |run_id, wait| {
        if cmd.no_stub {
            eprintln!("oils: run {run_id:016x} is waiting for an onboard stub; start one with:");
            eprintln!("    cargo run --release -p oils-onboard-stub -- --run-id {run_id:016x}");
            return Ok(());
        }
        child = Some(
            spawn_stub(&args, run_id, wait.as_str())
                .map_err(|e| SessionError::Argument(format!("{e:#}")))?,
        );
        Ok(())
    });
    let stub_status = child.map(reap_stub);
    let report = result.context("bench run")?;
    oils_emulator::report::finish_run(&report, args.report.as_deref())?;
    if let Some(Err(e)) = stub_status {
        bail!("onboard stub: {e}");
    }
    Ok(())
}

/// Starts `oils stub` for this run, as a separate OS process.
fn spawn_stub(args: &RunArgs, run_id: u64, wait: &str) -> anyhow::Result<Child> {
    let exe = std::env::current_exe().context("locating the oils executable")?;
    let mut p = Process::new(exe);
    p.arg("stub")
        .arg("--run-id")
        .arg(format!("{run_id:016x}"))
        .arg("--wait")
        .arg(wait)
        .arg("--fsw")
        .arg(match args.fsw {
            FswArg::Gnc => "gnc",
            FswArg::Playback => "playback",
        })
        // A realtime run slowed down by --speed has long periods: never time out sooner.
        .arg("--timeout-ms")
        .arg((5000 + 3 * (args.dt_ms as f64 / args.speed) as u64).to_string())
        .stdin(Stdio::null());
    if let Some(profile) = &args.profile {
        p.arg("--profile").arg(profile);
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

fn export(a: &ExportArgs) -> anyhow::Result<()> {
    let log = oils_emulator::recorder::read_log(&a.log)?;
    let torn = if log.trailing_bytes > 0 {
        format!(
            " ({} trailing bytes of a torn record ignored)",
            log.trailing_bytes
        )
    } else {
        String::new()
    };
    if let Some(csv) = &a.csv {
        let file =
            std::fs::File::create(csv).with_context(|| format!("creating {}", csv.display()))?;
        let mut out = std::io::BufWriter::new(file);
        oils_emulator::recorder::export_csv(&log, &mut out)
            .with_context(|| format!("writing {}", csv.display()))?;
        eprintln!(
            "oils export: {} records to {}{torn}",
            log.records.len(),
            csv.display()
        );
    }
    if let Some(path) = &a.profile {
        // The engine rating the run used is in the log's header.
        let header: serde_json::Value =
            serde_json::from_str(&log.header_json).context("log header is not JSON")?;
        let max_thrust_n = header["scenario"]["propulsion"]["max_thrust_n"]
            .as_f64()
            .context("log header lacks scenario.propulsion.max_thrust_n")?;
        let profile = oils_emulator::recorder::commands_as_profile(&log, a.every, max_thrust_n)?;
        std::fs::write(path, profile.to_csv())
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!(
            "oils export: {} profile rows to {}{torn}",
            profile.rows().len(),
            path.display()
        );
    }
    Ok(())
}
