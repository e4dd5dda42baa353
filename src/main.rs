//! `oils`: the one-command bench. `oils run` (the default) starts the emulator in this
//! process and spawns the onboard stub as a separate OS process (this same executable,
//! `oils stub ...`), so `cargo run --release` needs no other binary built.

mod cmd;

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};
use std::path::PathBuf;

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
    /// Fly a run: emulator here, flight software in a child process over iceoryx2 (or
    /// in this process with --link inproc). The default command.
    Run(Box<cmd::run::RunArgs>),
    /// Replay a run's log through the same plant and loop (record == replay).
    Replay(cmd::run::ReplayArgs),
    /// Turn a run log into CSV, a thrust profile or MCAP (Foxglove).
    Export(ExportArgs),
    /// Draw a run's figures (PNG) from its log (OILSLOG6 or MCAP).
    Plot(PlotArgs),
    /// Drive the high-fidelity propulsion model open loop with a profile, or draw its figures.
    Hifi(cmd::hifi::HifiArgs),
    /// Write the training excitation as a thrust-command profile, to run through your
    /// own propulsion model (then `oils train --data`).
    Excitation(cmd::excitation::ExcitationArgs),
    /// Pack a surrogate model file (or hifi) as an FMI 3.0 / 2.0 co-simulation FMU.
    ExportFmu(cmd::export_fmu::ExportFmuArgs),
    /// Train the propulsion surrogate (seed paper): excitation, data, Lasso, CV, model file.
    Train(cmd::train::TrainArgs),
    /// Validate the surrogate against the hifi model (paper's cases, bounds, plots, uncertainty).
    Validate(cmd::validate::ValidateArgs),
    /// Render the onboard terrain map (with the camera's calibration) the reference GNC
    /// navigates by with --gnc-map, from a scenario's terrain and sun.
    Map(cmd::map::MapArgs),
    /// Monte Carlo campaigns: dispersions, model error and faults over many cases, on
    /// all local cores or a Slurm cluster.
    #[command(subcommand)]
    Mc(cmd::mc::McCmd),
    /// Run the onboard stub: what `oils run` spawns; by hand, it joins a run started
    /// with `oils run --no-stub`.
    Stub(Box<cmd::stub::StubArgs>),
}

#[derive(clap::Args)]
struct ExportArgs {
    /// The log file (`.oilslog`, or `.mcap` from `oils run --log-format mcap`).
    log: PathBuf,
    /// Write every step as CSV here.
    #[arg(long, required_unless_present_any = ["profile", "mcap", "layout", "frames"])]
    csv: Option<PathBuf>,
    /// Write every camera, lidar and test-card frame as a 16-bit grey PNG into this
    /// directory (`camera-000123.png`, ...): the log keeps the frames' hashes, so the run
    /// is replayed and each frame rendered again and checked against its hash.
    #[arg(long, value_name = "DIR")]
    frames: Option<PathBuf>,
    /// Write the run as MCAP here (opens in Foxglove; docs/foxglove-layout.json). A run
    /// with a camera, a lidar or the test card gets its frames as Foxglove RawImage
    /// messages too, rendered again by a replay (the log keeps their hashes).
    #[arg(long, value_name = "OUT.mcap")]
    mcap: Option<PathBuf>,
    /// Write the applied commands as a thrust-command profile CSV here (replayable with
    /// `oils run --fsw playback`, `oils hifi`, `oils validate`).
    #[arg(long)]
    profile: Option<PathBuf>,
    /// Write the layout of the log's records (CSV column names, byte offsets, dtypes,
    /// derived columns) as JSON here: the one in the log's header, or, for a log from
    /// before headers carried it, this build's (the Python package's `read_log(path,
    /// layout=OUT.json)` reads such a log with it).
    #[arg(long, value_name = "OUT.json")]
    layout: Option<PathBuf>,
    /// With --profile: keep one step in N (rows hold until the next).
    #[arg(long, default_value_t = 1)]
    every: usize,
}

#[derive(clap::Args)]
struct PlotArgs {
    /// The run's log (`.oilslog` or `.mcap`).
    log: PathBuf,
    /// Folder for the PNGs (created if needed).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

/// Errors print as one chain of causes (no backtrace, whatever RUST_BACKTRACE says)
/// and exit with status 1.
fn main() {
    if let Err(e) = real_main() {
        eprintln!("error: {e:#}{}", flag_hint(&e));
        std::process::exit(1);
    }
}

/// For a refused run-configuration setting, the `oils run` flag that sets it (the run
/// core names the configuration field; only the command line knows its flags).
fn flag_hint(e: &anyhow::Error) -> String {
    use oils_emulator::run_config::RunConfigError;
    let field =
        e.chain()
            .find_map(|c| match c.downcast_ref::<RunConfigError>() {
                Some(RunConfigError::Invalid { field, .. }) => Some(*field),
                _ => match c.downcast_ref::<oils_emulator::session::SessionError>() {
                    Some(oils_emulator::session::SessionError::Config(
                        RunConfigError::Invalid { field, .. },
                    )) => Some(*field),
                    _ => None,
                },
            });
    match field {
        Some(f) => format!(" [flag {}]", cmd::run::flag_of(f)),
        None => String::new(),
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
        Cmd::Run(args) => cmd::run::run(&args),
        Cmd::Replay(a) => cmd::run::replay(&a),
        Cmd::Export(a) => export(&a),
        Cmd::Plot(a) => cmd::plot::run(&a.log, &a.out),
        Cmd::Hifi(a) => cmd::hifi::run(&a),
        Cmd::Excitation(a) => cmd::excitation::run(&a),
        Cmd::Map(a) => cmd::map::run(&a),
        Cmd::ExportFmu(a) => cmd::export_fmu::run(&a),
        Cmd::Train(a) => cmd::train::run(&a),
        Cmd::Validate(a) => cmd::validate::run(&a),
        Cmd::Mc(c) => cmd::mc::run(&c),
        Cmd::Stub(a) => cmd::stub::run(&a),
    }
}

/// `oils export LOG --frames DIR`: replays the run, writing each frame rendered again.
fn export_frames(
    log_path: &std::path::Path,
    log: oils_emulator::recorder::Log,
    dir: &std::path::Path,
) -> anyhow::Result<()> {
    let camera_bits = camera_bits_of(&log)?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let written = std::rc::Rc::new(std::cell::Cell::new(0u64));
    let count = written.clone();
    let out = dir.to_path_buf();
    let tap: oils_emulator::link::FrameTap = Box::new(move |ann, pixels| {
        let name = oils_shared::frame_device_name(ann.device).unwrap_or("frame");
        let path = out.join(format!("{name}-{:06}.png", ann.seq));
        let file = std::io::BufWriter::new(std::fs::File::create(&path)?);
        oils_emulator::frame_png::write_png(ann, pixels, camera_bits, file)
            .map_err(|e| std::io::Error::other(format!("{}: {e}", path.display())))?;
        count.set(count.get() + 1);
        Ok(())
    });
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let started = std::time::Instant::now();
    oils_emulator::session::replay_tapping_frames(log_path, log, &stop, Some(tap))
        .with_context(|| format!("replaying {} for its frames", log_path.display()))?;
    eprintln!(
        "oils export: {} frames to {} in {:.1} s (rendered again by a replay, each checked against the log's hash)",
        written.get(),
        dir.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The camera's ADC bits in a log's header (12 unless it says otherwise).
fn camera_bits_of(log: &oils_emulator::recorder::Log) -> anyhow::Result<u32> {
    let header = oils_emulator::exact_json::value_from_str(&log.header_json)
        .context("log header is not JSON")?;
    Ok(header["config"]["scenario"]["sensors"]["camera"]["bits"]
        .as_u64()
        .unwrap_or(12) as u32)
}

/// `oils export LOG --mcap OUT` of a run with frame devices: the records and, rendered
/// again by a replay (the log keeps only their hashes), every frame as a Foxglove
/// `RawImage`, each written after the records up to its time of validity.
fn export_mcap_with_frames(
    log_path: &std::path::Path,
    log: oils_emulator::recorder::Log,
    path: &std::path::Path,
) -> anyhow::Result<()> {
    use std::cell::RefCell;
    use std::rc::Rc;
    let camera_bits = camera_bits_of(&log)?;
    let sink = Rc::new(RefCell::new(oils_lab::mcap_log::McapSink::create(
        path,
        &log.header_json,
    )?));
    let records = Rc::new(log.records.clone());
    let next = Rc::new(std::cell::Cell::new(0usize));
    let (tap_sink, tap_records, tap_next) = (sink.clone(), records.clone(), next.clone());
    let tap: oils_emulator::link::FrameTap = Box::new(move |ann, pixels| {
        let mut sink = tap_sink.borrow_mut();
        let mut i = tap_next.get();
        while i < tap_records.len() && tap_records[i].telemetry.header.t_ns <= ann.t_ns {
            sink.write_record(&tap_records[i])
                .map_err(|e| std::io::Error::other(e.to_string()))?;
            i += 1;
        }
        tap_next.set(i);
        sink.write_frame(ann, pixels, camera_bits)
            .map_err(|e| std::io::Error::other(e.to_string()))
    });
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let started = std::time::Instant::now();
    eprintln!(
        "oils export: the log announces frames: replaying the run to render them again for {}",
        path.display()
    );
    oils_emulator::session::replay_tapping_frames(log_path, log, &stop, Some(tap))
        .with_context(|| format!("replaying {} for its frames", log_path.display()))?;
    let mut sink = sink.borrow_mut();
    for r in &records[next.get()..] {
        sink.write_record(r)?;
    }
    sink.close()?;
    let (written, frames) = sink.written();
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    eprintln!(
        "oils export: {written} records and {frames} frames to {} ({:.1} MB) in {:.1} s",
        path.display(),
        bytes as f64 / 1e6,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn export(a: &ExportArgs) -> anyhow::Result<()> {
    if a.every == 0 {
        bail!("--every 0: keep one step in N needs N >= 1");
    }
    let mut paths: Vec<(&str, &std::path::Path)> = vec![("the log", a.log.as_path())];
    for (name, p) in [
        ("--csv", &a.csv),
        ("--mcap", &a.mcap),
        ("--profile", &a.profile),
        ("--layout", &a.layout),
        ("--frames", &a.frames),
    ] {
        if let Some(p) = p {
            paths.push((name, p.as_path()));
        }
    }
    cmd::refuse_aliases(&paths)?;
    let log = oils_lab::mcap_log::read_any(&a.log)?;
    for w in &log.warnings {
        eprintln!("oils export: {}: {w}", a.log.display());
    }
    if !log.damaged_records.is_empty() {
        // One record per step from step 0, so a record's position is its step.
        let shown: Vec<String> = log
            .damaged_records
            .iter()
            .take(10)
            .map(u64::to_string)
            .collect();
        bail!(
            "{}: {} damaged records (CRC mismatch), at steps {}{}; nothing exported",
            a.log.display(),
            log.damaged_records.len(),
            shown.join(", "),
            if log.damaged_records.len() > 10 {
                ", ..."
            } else {
                ""
            }
        );
    }
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
    let has_frames = log
        .records
        .iter()
        .any(|r| r.telemetry.sensors.frame_count > 0);
    if let (Some(path), true) = (&a.mcap, has_frames) {
        export_mcap_with_frames(&a.log, log.clone(), path)?;
    } else if let Some(path) = &a.mcap {
        let started = std::time::Instant::now();
        let stats = oils_lab::mcap_log::export_mcap(&log, path)?;
        eprintln!(
            "oils export: {} records to {} ({:.1} MB) in {:.2} s{torn}",
            stats.records,
            path.display(),
            stats.bytes as f64 / 1e6,
            started.elapsed().as_secs_f64()
        );
    }
    if let Some(path) = &a.layout {
        // Every number as written (serde_json's own parser may read a float one ulp off).
        let header = oils_emulator::exact_json::value_from_str(&log.header_json)
            .context("log header is not JSON")?;
        let (layout, whose) = match header.get("layout") {
            Some(l) => (l.clone(), "the log's header"),
            None => {
                let site = oils_emulator::log_fields::Site::of_log_header(&log.header_json)
                    .map_err(|why| anyhow::anyhow!("the log's header names no site: {why}"))?;
                (
                    oils_emulator::log_layout::layout(&site)?,
                    "this build (the log's header has none)",
                )
            }
        };
        if let Some(e) = layout.get("error") {
            bail!("the log's header holds no usable layout: {e}");
        }
        let mut text = serde_json::to_string_pretty(&layout)?;
        text.push('\n');
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
        eprintln!(
            "oils export: record layout from {whose} to {}",
            path.display()
        );
    }
    if let Some(dir) = &a.frames {
        export_frames(&a.log, log.clone(), dir)?;
    }
    if let Some(path) = &a.profile {
        // The engine rating the run used is in the log's header.
        let header = oils_emulator::exact_json::value_from_str(&log.header_json)
            .context("log header is not JSON")?;
        let max_thrust_n = header["config"]["scenario"]["propulsion"]["max_thrust_n"]
            .as_f64()
            .context("log header lacks config.scenario.propulsion.max_thrust_n")?;
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
