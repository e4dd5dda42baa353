//! `oils mc`: Monte Carlo campaigns. `run` (local, all cores, or one shard), `merge`,
//! `case` (one case again, bit for bit), `submit --slurm` (a job array and a merge
//! job), `compare` (the same cases under two propulsion models), `report` (the
//! campaign's HTML page).

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::recorder::LogFormat;
use oils_lab::campaign::slurm::SlurmSubmission;
use oils_lab::campaign::{
    self, case, compare, local, run_cases, CampaignSpec, Merged, RunOptions, Shard, Store,
};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// `oils mc ...`.
#[derive(Debug, clap::Subcommand)]
pub enum McCmd {
    /// Run a campaign's cases on this machine (all cores), or one shard of it; a
    /// campaign started again resumes. Without --shard, merges at the end.
    Run(McRunArgs),
    /// Merge a campaign's case results into cases.csv, summary.json and plots/.
    Merge(McMergeArgs),
    /// Run one case of a campaign again, alone (same digest, bit for bit), with a log.
    Case(McCaseArgs),
    /// Submit a campaign to Slurm: a job array of shards and a merge job after it.
    Submit(McSubmitArgs),
    /// Run the same cases under two propulsion models and compare the dispersions.
    Compare(McCompareArgs),
    /// Merge a campaign and write its self-contained HTML page, DIR/report.html.
    Report(McReportArgs),
}

/// `oils mc report`.
#[derive(Debug, clap::Args)]
pub struct McReportArgs {
    /// Campaign directory.
    pub dir: PathBuf,
    /// Report even if some cases have no result yet (they are listed as missing).
    #[arg(long)]
    pub partial: bool,
}

/// What selects and changes the campaign.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SpecArgs {
    /// Campaign spec TOML [default: the campaign already in --out, else the committed
    /// emulator/campaigns/default.toml].
    #[arg(long, value_name = "TOML")]
    pub spec: Option<PathBuf>,
    /// Number of cases (overrides the spec).
    #[arg(long)]
    pub cases: Option<u64>,
    /// Master seed (overrides the spec).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Propulsion model of every case (overrides the spec's base).
    #[arg(long, value_name = "MODEL")]
    pub propulsion: Option<PropulsionKind>,
    /// Wall-time budget of one case, seconds (overrides the spec).
    #[arg(long, value_name = "SECONDS")]
    pub case_timeout_s: Option<f64>,
    /// What the reference GNC navigates from in every case (overrides the spec's
    /// base): bench, or sensors (its own filter; the telemetry then carries the device
    /// samples and the plant steps at 5 ms, as `oils run --telemetry sensors`).
    #[arg(long, value_name = "bench|sensors")]
    pub gnc_nav: Option<oils_shared::fsw::GncNavigation>,
    /// What the reference GNC turns the vehicle with in every case (overrides the
    /// spec's base): torque or thrusters.
    #[arg(long, value_name = "torque|thrusters")]
    pub gnc_attitude: Option<oils_shared::fsw::GncAttitude>,
    /// The reference GNC's hazard avoidance at the hover: on or off (overrides the
    /// spec's `base.gnc.hazard_avoidance`; off flies the same cases blind).
    #[arg(long, value_name = "on|off", value_parser = ["on", "off"])]
    pub gnc_hda: Option<String>,
}

/// `oils mc run`.
#[derive(Debug, clap::Args)]
pub struct McRunArgs {
    #[command(flatten)]
    pub spec: SpecArgs,
    /// Campaign directory (created; a campaign already there resumes).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Worker threads [default: one per core].
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Run only shard I of K (contiguous); I may be `auto`: read from
    /// SLURM_ARRAY_TASK_ID, PBS_ARRAY_INDEX or JOB_COMPLETION_INDEX. No merge.
    #[arg(long, value_name = "I/K")]
    pub shard: Option<String>,
    /// Skip the PNG plots when merging.
    #[arg(long)]
    pub no_plots: bool,
}

/// `oils mc merge`.
#[derive(Debug, clap::Args)]
pub struct McMergeArgs {
    /// Campaign directory.
    pub dir: PathBuf,
    /// Merge even if some cases have no result yet (they are listed as missing).
    #[arg(long)]
    pub partial: bool,
    /// Skip the PNG plots.
    #[arg(long)]
    pub no_plots: bool,
}

/// `oils mc case`.
#[derive(Debug, clap::Args)]
pub struct McCaseArgs {
    /// Campaign directory.
    pub dir: PathBuf,
    /// Case index.
    #[arg(long)]
    pub index: u64,
    /// Write the run's log here.
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Log format: oilslog or mcap (Foxglove). [default: oilslog, or from --log's extension]
    #[arg(long, value_name = "FORMAT")]
    pub log_format: Option<LogFormat>,
    /// Write the JSON report here (its `config` repeats the case with `oils run --config-from`).
    #[arg(long, value_name = "JSON")]
    pub report: Option<PathBuf>,
    /// Draw the run's figures into DIR (needs --log).
    #[arg(long, value_name = "DIR", requires = "log")]
    pub plots: Option<PathBuf>,
}

/// `oils mc submit`.
#[derive(Debug, clap::Args)]
pub struct McSubmitArgs {
    /// Submit to Slurm (sbatch job array plus a merge job).
    #[arg(long, required = true)]
    pub slurm: bool,
    #[command(flatten)]
    pub spec: SpecArgs,
    /// Campaign directory, on a filesystem every node sees.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Number of array tasks (shards).
    #[arg(long, value_name = "K", default_value_t = 8)]
    pub array_size: u64,
    /// CPUs per array task (each task runs that many cases at once).
    #[arg(long, default_value_t = 1)]
    pub cpus_per_task: u32,
    /// The oils binary the tasks run [default: this one].
    #[arg(long, value_name = "PATH")]
    pub oils: Option<PathBuf>,
    /// The sbatch command.
    #[arg(long, default_value = "sbatch")]
    pub sbatch: String,
    /// Write the scripts and print the sbatch commands without submitting.
    #[arg(long)]
    pub dry_run: bool,
    /// Options passed to both sbatch calls (after `--`: e.g. -- --partition=long --account=gnc --time=02:00:00).
    #[arg(last = true, value_name = "SBATCH OPTIONS")]
    pub sbatch_args: Vec<String>,
}

/// `oils mc compare`.
#[derive(Debug, clap::Args)]
pub struct McCompareArgs {
    #[command(flatten)]
    pub spec: SpecArgs,
    /// Directory: one campaign per model in DIR/<model>, the comparison in DIR.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The two models, comma-separated.
    #[arg(long, default_value = "surrogate,hifi", value_delimiter = ',')]
    pub models: Vec<PropulsionKind>,
    /// Worker threads [default: one per core].
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Skip the PNG plots.
    #[arg(long)]
    pub no_plots: bool,
}

/// Runs an `oils mc` subcommand.
pub fn run(cmd: &McCmd) -> Result<()> {
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    match cmd {
        McCmd::Run(a) => mc_run(a, &stop),
        McCmd::Merge(a) => mc_merge(a, &stop),
        McCmd::Case(a) => mc_case(a, &stop),
        McCmd::Submit(a) => mc_submit(a),
        McCmd::Compare(a) => mc_compare(a, &stop),
        McCmd::Report(a) => mc_report(a, &stop),
    }
}

/// The spec for `dir`: `--spec`, else the one stored in `dir`, else the default; then
/// the flags.
fn resolve(args: &SpecArgs, store: &Store) -> Result<CampaignSpec> {
    let mut spec = match &args.spec {
        Some(path) => CampaignSpec::load(path)?,
        None => match store.stored_spec()? {
            Some(stored) => stored,
            None => CampaignSpec::default_campaign(),
        },
    };
    if let Some(n) = args.cases {
        spec.cases = n;
    }
    if let Some(s) = args.seed {
        spec.seed = s;
    }
    if let Some(m) = args.propulsion {
        spec.base.propulsion = m;
    }
    if let Some(t) = args.case_timeout_s {
        spec.case_timeout_s = t;
    }
    if let Some(n) = args.gnc_nav {
        spec.base.gnc.navigation = n;
        if n == oils_shared::fsw::GncNavigation::Sensors && !spec.base.telemetry.sensors() {
            spec.base
                .set_telemetry(oils_emulator::run_config::TelemetrySource::Sensors, false);
        }
    }
    if let Some(a) = args.gnc_attitude {
        spec.base.gnc.attitude = a;
    }
    if let Some(h) = &args.gnc_hda {
        spec.base.gnc.hazard_avoidance = h == "on";
    }
    spec.validate()?;
    campaign::case::check_targets(&spec)?;
    Ok(spec)
}

fn progress_bar(total: u64, already: u64, label: &str) -> ProgressBar {
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::new(total)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{prefix} [{bar:30}] {pos}/{len} cases  {per_sec}  ETA {eta}  {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_prefix(label.to_string());
    bar.set_position(already);
    bar.reset_eta();
    bar
}

/// Runs a campaign's (or shard's) cases with a progress bar (a plain line every 5 %
/// when stderr is not a terminal, as under Slurm).
fn run_with_progress(
    spec: &CampaignSpec,
    store: &Store,
    options: RunOptions,
    stop: &AtomicBool,
    label: &str,
) -> Result<local::BatchReport> {
    let range = options.shard.map_or(0..spec.cases, |s| s.range(spec.cases));
    let total = range.end - range.start;
    let bar = progress_bar(total, 0, label);
    let plain = bar.is_hidden();
    let landed = std::sync::atomic::AtomicU64::new(0);
    let step = (total / 20).max(1);
    let started = std::time::Instant::now();
    let report = run_cases(spec, store, options, stop, &|p| {
        if p.result.outcome == "landed" {
            landed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        let l = landed.load(std::sync::atomic::Ordering::Relaxed);
        bar.set_position(p.finished);
        bar.set_message(format!("{l} landed"));
        if plain && (p.finished % step == 0 || p.finished == p.total) {
            eprintln!(
                "{label}: {}/{} cases ({l} landed this session), {:.0} s",
                p.finished,
                p.total,
                started.elapsed().as_secs_f64()
            );
        }
    });
    bar.finish_and_clear();
    let report = report?;
    eprintln!(
        "{label}: {} cases run in {:.1} s ({:.0} cases/min), {} already done{}",
        report.ran,
        report.wall_s,
        if report.wall_s > 0.0 {
            report.ran as f64 / report.wall_s * 60.0
        } else {
            0.0
        },
        report.skipped,
        if report.outcomes.is_empty() {
            String::new()
        } else {
            format!(
                "; outcomes: {}",
                report
                    .outcomes
                    .iter()
                    .map(|(o, n)| format!("{n} {o}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
    );
    if report.interrupted || stop.load(std::sync::atomic::Ordering::Relaxed) {
        bail!(
            "interrupted: {} of {} cases done; run the same command again to resume",
            report.skipped + report.ran,
            report.assigned
        );
    }
    Ok(report)
}

fn write_timing(store: &Store, report: &local::BatchReport, jobs: usize) -> Result<()> {
    let timing = serde_json::json!({
        "cases_run": report.ran,
        "wall_s": report.wall_s,
        "cases_per_minute": if report.wall_s > 0.0 { report.ran as f64 / report.wall_s * 60.0 } else { 0.0 },
        "mean_case_wall_s": if report.ran > 0 { report.case_wall_s / report.ran as f64 } else { 0.0 },
        "jobs": jobs,
        "note": "this session's wall time; differs between runs (cases.csv and summary.json do not)",
    });
    campaign::store::write_atomic(
        &store.dir().join("timing.json"),
        (serde_json::to_string_pretty(&timing)? + "\n").as_bytes(),
    )?;
    Ok(())
}

fn jobs_of(jobs: Option<usize>) -> usize {
    jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

fn mc_run(a: &McRunArgs, stop: &AtomicBool) -> Result<()> {
    let store = Store::new(&a.out);
    let spec = resolve(&a.spec, &store)?;
    let shard = a
        .shard
        .as_deref()
        .map(|s| Shard::parse(s, &|v| std::env::var(v).ok()))
        .transpose()
        .map_err(anyhow::Error::msg)?;
    if let Some(j) = a.jobs {
        if j == 0 {
            bail!("--jobs 0: give at least one worker");
        }
    }
    let options = RunOptions {
        jobs: a.jobs,
        shard,
    };
    let label = match shard {
        Some(s) => format!("oils mc shard {}/{}", s.index, s.count),
        None => "oils mc".to_string(),
    };
    // Held to the end: a second `oils mc run` on this campaign (or shard) fails at once.
    let _lock = store.lock(shard.map(|s| (s.index, s.count)))?;
    let report = run_with_progress(&spec, &store, options, stop, &label)?;
    if shard.is_some() {
        eprintln!(
            "{label}: done; merge with `oils mc merge {}` when every shard is",
            a.out.display()
        );
        return Ok(());
    }
    write_timing(&store, &report, jobs_of(a.jobs))?;
    let merged = campaign::merge(&spec, &store, false, !a.no_plots, stop)?;
    print_summary(&merged, &a.out);
    write_page(&spec, &merged, &a.out)?;
    none_all_invalid(&merged)
}

/// A campaign whose every case is `invalid` or `error` flew nothing: an error, not a
/// result.
fn none_all_invalid(merged: &Merged) -> Result<()> {
    let r = &merged.results;
    if !r.is_empty()
        && r.iter()
            .all(|c| c.outcome == "invalid" || c.outcome == "error")
    {
        bail!(
            "every one of the {} cases is invalid or an error: nothing flew (first: {} {}); check the spec's base and dispersions",
            r.len(),
            r[0].outcome,
            r[0].error.as_deref().unwrap_or("no reason recorded")
        );
    }
    Ok(())
}

/// `DIR/report.html` with the figures `DIR/plots/` holds.
fn write_page(spec: &CampaignSpec, merged: &Merged, dir: &Path) -> Result<()> {
    let figures: Vec<PathBuf> = campaign::plots::FIGURES
        .iter()
        .map(|f| dir.join("plots").join(f))
        .filter(|p| p.exists())
        .collect();
    let page = oils_lab::report_page::write_campaign(spec, merged, dir, &figures)
        .context("writing the campaign's page")?;
    println!("report page            {}", page.display());
    Ok(())
}

fn mc_report(a: &McReportArgs, stop: &AtomicBool) -> Result<()> {
    let store = Store::new(&a.dir);
    let spec = store
        .stored_spec()?
        .with_context(|| format!("{} holds no campaign (no campaign.toml)", a.dir.display()))?;
    let merged = campaign::merge(&spec, &store, a.partial, true, stop)?;
    print_summary(&merged, &a.dir);
    write_page(&spec, &merged, &a.dir)
}

fn mc_merge(a: &McMergeArgs, stop: &AtomicBool) -> Result<()> {
    let store = Store::new(&a.dir);
    let spec = store
        .stored_spec()?
        .with_context(|| format!("{} holds no campaign (no campaign.toml)", a.dir.display()))?;
    let merged = campaign::merge(&spec, &store, a.partial, !a.no_plots, stop)?;
    print_summary(&merged, &a.dir);
    write_page(&spec, &merged, &a.dir)?;
    none_all_invalid(&merged)
}

fn fmt_stat(merged: &Merged, name: &str, unit: &str) -> String {
    match merged.summary.figures.get(name) {
        Some(s) => format!(
            "{name:<22} mean {:>9.3}  std {:>8.3}  p1 {:>9.3}  p50 {:>9.3}  p99 {:>9.3} {unit}",
            s.mean, s.std, s.p1, s.p50, s.p99
        ),
        None => format!("{name:<22} (no case touched down)"),
    }
}

fn print_summary(merged: &Merged, dir: &Path) {
    let s = &merged.summary;
    println!(
        "campaign {}: {} cases, {}, seed {}",
        s.name, s.merged, s.propulsion, s.seed
    );
    println!(
        "landed {} of {} ({:.1} %); outcomes: {}",
        s.landed,
        s.merged,
        100.0 * s.landed_fraction,
        s.outcomes
            .iter()
            .map(|(o, n)| format!("{n} {o}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if !s.unsafe_touchdowns.is_empty() {
        println!(
            "unsafe touchdowns: {}",
            s.unsafe_touchdowns
                .iter()
                .map(|(why, n)| format!("{why} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    println!(
        "landed by faults: {}",
        s.landed_by_faults
            .iter()
            .map(|(f, c)| format!("{f} {}/{}", c.landed, c.cases))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "nominal: {} (digest {})",
        s.nominal.outcome,
        &s.nominal.digest[..s.nominal.digest.len().min(16)]
    );
    for (name, unit) in [
        ("vertical_speed_mps", "m/s"),
        ("horizontal_speed_mps", "m/s"),
        ("tilt_deg", "deg"),
        ("site_error_m", "m"),
        ("propellant_used_kg", "kg"),
        ("nav_error_m", "m"),
        ("nav_horizontal_error_m", "m"),
        ("nav_horizontal_error_50m_m", "m"),
        ("nav_altitude_error_m", "m"),
    ] {
        if s.figures.contains_key(name) {
            println!("{}", fmt_stat(merged, name, unit));
        }
    }
    if let Some(e) = &s.footprint_3sigma {
        println!(
            "footprint 3-sigma      {:.0} m x {:.0} m full axes (semi-axes {:.0} m x {:.0} m), major axis at {:.0} deg from downrange",
            2.0 * e.semi_major_m,
            2.0 * e.semi_minor_m,
            e.semi_major_m,
            e.semi_minor_m,
            e.angle_deg
        );
    }
    if !s.missing.is_empty() {
        println!(
            "missing                {} cases (merged with --partial)",
            s.missing.len()
        );
    }
    println!(
        "results                {}/cases.csv, {}/summary.json, {}/plots/",
        dir.display(),
        dir.display(),
        dir.display()
    );
}

fn mc_case(a: &McCaseArgs, stop: &AtomicBool) -> Result<()> {
    let store = Store::new(&a.dir);
    let spec = store
        .stored_spec()?
        .with_context(|| format!("{} holds no campaign (no campaign.toml)", a.dir.display()))?;
    if a.index >= spec.cases {
        bail!(
            "--index {}: the campaign has cases 0-{}",
            a.index,
            spec.cases - 1
        );
    }
    let uncertainty = case::load_uncertainty(&spec)?;
    let setup = campaign::case_setup(&spec, uncertainty.as_ref(), a.index)?;
    if let Some(why) = &setup.invalid {
        bail!("case {} is invalid: {why}", a.index);
    }
    let mut cfg = setup.config.clone();
    if let Some(log) = &a.log {
        cfg.log.enabled = true;
        cfg.log.path = Some(log.clone());
        cfg.log.format = a.log_format.unwrap_or_else(|| LogFormat::from_path(log));
    }
    for (name, value) in &setup.applied {
        eprintln!("  {name:<28} {value}");
    }
    for f in &setup.faults {
        eprintln!("  fault                        {f}");
    }
    let extras = oils_emulator::session::Extras {
        sinks: Some(&oils_lab::mcap_log::McapOpener),
        ..Default::default()
    };
    let report = oils_lab::onboard::fly_in_process(&cfg, a.index, stop, extras)
        .with_context(|| format!("case {}", a.index))?;
    print!("{}", report.table());
    if let Some(path) = &a.report {
        std::fs::write(path, report.to_json() + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(dir) = &a.plots {
        super::plot::after_run(&report, dir)?;
    }
    match store.read_case(a.index)? {
        Some(stored) if stored.digest == report.summary.digest => {
            println!(
                "digest {} equals the campaign's record of case {}",
                report.summary.digest, a.index
            );
        }
        Some(stored) if stored.digest.is_empty() => {
            println!(
                "the campaign recorded case {} as {} (no digest)",
                a.index, stored.outcome
            );
        }
        Some(stored) => bail!(
            "case {}: digest {} differs from the campaign's record {} (a different build or spec?)",
            a.index,
            report.summary.digest,
            stored.digest
        ),
        None => println!("the campaign has no result for case {} yet", a.index),
    }
    Ok(())
}

fn mc_submit(a: &McSubmitArgs) -> Result<()> {
    if a.array_size == 0 {
        bail!("--array-size 0: give at least one task");
    }
    let dir =
        std::path::absolute(&a.out).with_context(|| format!("resolving {}", a.out.display()))?;
    let store = Store::new(&dir);
    let spec = resolve(&a.spec, &store)?;
    store.open(&spec)?;
    let submission = SlurmSubmission {
        name: spec.name.clone(),
        dir: dir.clone(),
        tasks: a.array_size.min(spec.cases),
        cpus_per_task: a.cpus_per_task,
        oils: match &a.oils {
            Some(p) => std::path::absolute(p)?,
            None => std::env::current_exe().context("locating this oils binary")?,
        },
        sbatch: a.sbatch.clone(),
        sbatch_args: a.sbatch_args.clone(),
    };
    if a.dry_run {
        let (array, merge) = submission.write_scripts()?;
        println!("{:?}", submission.sbatch_command(&array, &[]));
        let after = ["--dependency=afterany:DRY-RUN".to_string()];
        println!("{:?}", submission.sbatch_command(&merge, &after));
        return Ok(());
    }
    let s = submission.submit()?;
    println!(
        "submitted campaign `{}` ({} cases) to Slurm: array job {} ({} tasks), merge job {}",
        spec.name, spec.cases, s.array_id, submission.tasks, s.merge_id
    );
    println!(
        "follow with `squeue -j {},{}`; logs in {}; results in {}",
        s.array_id,
        s.merge_id,
        s.slurm_dir.display(),
        dir.display()
    );
    println!("{} {}", s.array_id, s.merge_id);
    Ok(())
}

fn mc_compare(a: &McCompareArgs, stop: &AtomicBool) -> Result<()> {
    if a.models.len() != 2 || a.models[0] == a.models[1] {
        bail!("--models: give two different models, e.g. surrogate,hifi");
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut merged = Vec::new();
    for model in &a.models {
        let dir = a.out.join(model.as_str());
        let store = Store::new(&dir);
        let mut args = a.spec.clone();
        args.propulsion = Some(*model);
        let spec = resolve(&args, &store)?;
        let label = format!("oils mc {}", model.as_str());
        let options = RunOptions {
            jobs: a.jobs,
            shard: None,
        };
        let report = run_with_progress(&spec, &store, options, stop, &label)?;
        write_timing(&store, &report, jobs_of(a.jobs))?;
        let m = campaign::merge(&spec, &store, false, !a.no_plots, stop)?;
        print_summary(&m, &dir);
        write_page(&spec, &m, &dir)?;
        merged.push((spec, m));
    }
    let (spec, merged): (Vec<CampaignSpec>, Vec<Merged>) = merged.into_iter().unzip();
    let c = compare::compare(&merged[0], &merged[1]);
    if !a.no_plots {
        let fig = campaign::plots::write_compare(
            &spec[0],
            &merged[0],
            &merged[1],
            &c,
            &a.out.join("plots"),
        )?;
        println!("overlays               {}", fig.display());
    }
    campaign::store::write_atomic(
        &a.out.join("compare.json"),
        (serde_json::to_string_pretty(&c)? + "\n").as_bytes(),
    )?;
    campaign::store::write_atomic(
        &a.out.join("compare.csv"),
        compare::compare_csv(&merged[0], &merged[1]).as_bytes(),
    )?;
    println!(
        "\n{} vs {} over {} cases: landed {:.1} % vs {:.1} %, outcome differs in {}",
        c.models[0],
        c.models[1],
        c.cases,
        100.0 * c.landed_fraction[0],
        100.0 * c.landed_fraction[1],
        c.outcome_differs
    );
    println!(
        "{:<22} {:>10} {:>10} {:>10} {:>10} {:>12} {:>8} {:>9}",
        "figure",
        format!("mean {}", short(&c.models[0])),
        format!("mean {}", short(&c.models[1])),
        format!("std {}", short(&c.models[0])),
        format!("std {}", short(&c.models[1])),
        "diff p99|.|",
        "KS D",
        "KS p"
    );
    for (name, f) in &c.figures {
        let m = |i: usize| f.stats[i].as_ref().map_or(f64::NAN, |s| s.mean);
        let sd = |i: usize| f.stats[i].as_ref().map_or(f64::NAN, |s| s.std);
        let d = f
            .difference
            .as_ref()
            .map_or(f64::NAN, |s| s.p99.abs().max(s.p1.abs()));
        let (ks_d, ks_p) = f.ks.map_or((f64::NAN, f64::NAN), |k| (k.d, k.p_value));
        println!(
            "{name:<22} {:>10.3} {:>10.3} {:>10.3} {:>10.3} {:>12.3} {:>8.3} {:>9.3}",
            m(0),
            m(1),
            sd(0),
            sd(1),
            d,
            ks_d,
            ks_p
        );
    }
    println!(
        "comparison in {}/compare.json and compare.csv",
        a.out.display()
    );
    Ok(())
}

fn short(model: &str) -> &str {
    match model {
        "surrogate" => "surr",
        other => other,
    }
}
