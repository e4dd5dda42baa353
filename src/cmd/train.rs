//! `oils train`: the system-identification pipeline of the seed paper, end to end.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use oils_lab::fmu::import::{FmuModel, FmuSource};
use oils_lab::training::fit::Variant;
use oils_lab::training::{recorded, report, train_configured, user, Progress, TrainConfig};
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

/// The committed training configuration, used when `--config` is not given, so that
/// `oils train` alone reproduces the committed default model.
pub const COMMITTED_CONFIG: &str = include_str!("../../emulator/config/train.toml");

/// Arguments of `oils train`.
#[derive(clap::Args, Debug, Clone)]
pub struct TrainArgs {
    /// Report folder (CSV, PNG, summary, model files).
    #[arg(long, default_value = "target/oils-train")]
    pub out: PathBuf,
    /// Training configuration (TOML); default: the committed emulator/config/train.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Also write the dataset as CSV (raw time series and the paper's features) here.
    #[arg(long, value_name = "DIR")]
    pub export_dataset: Option<PathBuf>,
    /// Also write the deployed model file here (e.g. emulator/models/surrogate-default.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Time the final Lasso fit of the paper model (Gram + path) and print it.
    #[arg(long)]
    pub time_lasso: bool,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Descent profile for the held-out free-run check (never used for training).
    #[arg(long, default_value = "emulator/data/descent-profile.csv")]
    pub descent: PathBuf,
    /// Skip the held-out free-run checks against the reference model.
    #[arg(long)]
    pub no_holdout: bool,
    /// Train on recorded time series instead of a reference model (CSV, the layout of
    /// docs/recorded-data.md, e.g. what `oils hifi --out` writes; several files are
    /// joined in order). Default configuration: emulator/config/train-user.toml.
    #[arg(long, value_name = "CSV", num_args = 1.., conflicts_with = "truth")]
    pub data: Vec<PathBuf>,
    /// The reference model to train on: `hifi` (the configuration's, by default) or
    /// `fmu:PATH` (the user's FMU, or its variable-mapping TOML; docs/fmu.md). Default
    /// configuration for an FMU: emulator/config/train-user.toml.
    #[arg(long, value_name = "MODEL")]
    pub truth: Option<String>,
}

/// Where the training data come from.
enum Source {
    /// The configuration's reference model (hifi).
    Configured,
    /// Recorded files.
    Data(Vec<PathBuf>),
    /// The user's FMU (or its variable mapping).
    Fmu(FmuSource),
}

impl Source {
    fn of(args: &TrainArgs) -> Result<Self> {
        if !args.data.is_empty() {
            return Ok(Source::Data(args.data.clone()));
        }
        match args.truth.as_deref() {
            None | Some("hifi") => Ok(Source::Configured),
            Some(other) => match FmuSource::parse(other) {
                Some(src) => Ok(Source::Fmu(src.context("--truth")?)),
                None => bail!("--truth {other}: expected hifi or fmu:PATH"),
            },
        }
    }

    /// The configuration used when `--config` is not given.
    fn default_config(&self) -> &'static str {
        match self {
            Source::Configured => COMMITTED_CONFIG,
            Source::Data(_) | Source::Fmu(_) => oils_lab::training::user::USER_CONFIG,
        }
    }
}

/// Progress bars on stderr (hidden when stderr is not a terminal).
struct Bars {
    quiet: bool,
    bar: Mutex<Option<ProgressBar>>,
}

impl Progress for Bars {
    fn begin(&self, phase: &str, total: u64) {
        if self.quiet {
            return;
        }
        let bar = ProgressBar::new(total);
        let style = ProgressStyle::with_template("{msg:>16} [{bar:40}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
        bar.set_style(style);
        bar.set_message(phase.to_string());
        if let Ok(mut b) = self.bar.lock() {
            *b = Some(bar);
        }
    }
    fn tick(&self) {
        if let Ok(b) = self.bar.lock() {
            if let Some(bar) = b.as_ref() {
                bar.inc(1);
            }
        }
    }
    fn finish(&self) {
        if let Ok(mut b) = self.bar.lock() {
            if let Some(bar) = b.take() {
                bar.finish();
            }
        }
    }
}

/// Runs `oils train`.
pub fn run(args: &TrainArgs) -> Result<()> {
    let source = Source::of(args)?;
    let text = match &args.config {
        Some(p) => std::fs::read_to_string(p)
            .with_context(|| format!("reading training configuration {}", p.display()))?,
        None => source.default_config().to_string(),
    };
    let cfg = TrainConfig::from_toml(&text).context("training configuration")?;
    let bars = Bars {
        quiet: args.quiet,
        bar: Mutex::new(None),
    };
    let fmu = match &source {
        Source::Fmu(src) => Some(load_fmu(src, cfg.sample_time_ns)?),
        _ => None,
    };
    let t0 = Instant::now();
    let outcome = match &source {
        Source::Configured => train_configured(&cfg, &bars).context("training")?,
        Source::Fmu(_) => {
            let Some(fmu) = &fmu else {
                bail!("--truth fmu: the FMU was not loaded");
            };
            let mut model = fmu
                .instantiate(cfg.sample_time_ns, SAMPLE_TIME)
                .with_context(|| format!("instantiating {}", fmu.path.display()))?;
            let info = oils_lab::training::ReferenceInfo {
                name: format!("{}{}", oils_lab::fmu::import::PREFIX, fmu.path.display()),
                param_hash: fmu.hash.clone(),
            };
            let trained = user::train_on_model(&cfg, model.as_mut(), &info, &bars);
            if let Some(e) = fmu.take_error() {
                bail!("training on {}: {e}", fmu.path.display());
            }
            trained.context("training on the FMU")?
        }
        Source::Data(paths) => {
            let mut runs = Vec::new();
            for p in paths {
                let run = recorded::load(p, cfg.sample_time_ns).context("reading recorded data")?;
                println!(
                    "data: {}: {} rows every {} s, {} samples of {} s{}",
                    p.display(),
                    run.rows,
                    run.file_step_ns as f64 / 1e9,
                    run.dataset.len(),
                    cfg.sample_time_ns as f64 / 1e9,
                    if run.dropped_rows > 0 {
                        format!(
                            " ({} rows after the last whole sample not used)",
                            run.dropped_rows
                        )
                    } else {
                        String::new()
                    }
                );
                runs.push(run);
            }
            let info = user::data_info(paths).context("hashing the recorded data")?;
            user::train_on_data(&cfg, &runs, &info, &bars).context("training on recorded data")?
        }
    };
    let train_s = t0.elapsed().as_secs_f64();
    // What was derived from the reference rather than read from the configuration.
    if let Some(stroke) = outcome.valve.and_then(|v| v.stroke) {
        println!(
            "derived: stroke table from hifi's calibration, {} knots {}..={} N: {:.4?}",
            stroke.strokes().len(),
            stroke.first_n(),
            stroke.last_n(),
            stroke.strokes()
        );
    }
    if let Some(fit) = &outcome.clock_fit {
        println!("derived: {fit}");
    }
    let written =
        report::write_reports(&outcome, &args.out, cfg.top_terms).context("writing the reports")?;
    let deployed = outcome.deployed_model();
    let model_path = args.out.join("surrogate.json");
    std::fs::write(&model_path, deployed.to_json())
        .with_context(|| format!("writing {}", model_path.display()))?;
    if let Some(p) = &args.model {
        std::fs::write(p, deployed.to_json())
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(dir) = &args.export_dataset {
        let paper = outcome
            .models
            .iter()
            .find(|m| m.variant == Variant::Paper)
            .context("no paper model")?;
        let spec = paper.model.submodels[0].features;
        outcome
            .dataset
            .export_csv(dir, &spec)
            .with_context(|| format!("exporting the dataset to {}", dir.display()))?;
        println!("dataset exported to {}", dir.display());
    }
    if args.time_lasso {
        let paper = outcome.models.iter().find(|m| m.variant == Variant::Paper);
        if let Some(paper) = paper {
            let (gram_s, fit_s) = oils_lab::training::cv::time_final_fit(
                Variant::Paper,
                paper.selection.history,
                paper.selection.mu,
                &outcome.dataset,
                &cfg.cv,
                &cfg.variants,
            );
            println!(
                "lasso timing (paper model, n={}, mu={:e}, tol={:e}): Gram {:.4} s, active-set Lasso (7 outputs, single penalty, from zero) {:.4} s",
                paper.selection.history, paper.selection.mu, cfg.cv.tol, gram_s, fit_s
            );
        }
    }
    let figures = oils_lab::training::figures::write_figures(&outcome, &args.out)
        .context("drawing the figures")?;
    let mut summary = report::summary(&outcome, cfg.top_terms);
    let mut holdout_pngs = Vec::new();
    if matches!(source, Source::Data(_)) && !args.no_holdout {
        summary.push_str("\n(held-out free runs skipped: recorded data have no model to run them on; judge the model with `oils validate --model M --data FILE`)\n");
    } else if fmu.as_ref().is_some_and(FmuModel::single_instance) && !args.no_holdout {
        summary.push_str("\n(held-out free runs skipped: the FMU can be instantiated only once per process; judge the model with `oils validate --model M --truth fmu:PATH`)\n");
    } else if !args.no_holdout {
        let (text, pngs) = holdout(&cfg, &outcome, args, fmu.as_ref())?;
        summary.push_str(&text);
        holdout_pngs = pngs;
    }
    std::fs::write(args.out.join("summary.md"), &summary).context("writing summary.md")?;
    print!("{summary}");
    println!(
        "\ntraining took {train_s:.1} s; reports in {}:",
        args.out.display()
    );
    for p in written.iter().chain(&figures).chain(&holdout_pngs) {
        println!("  {}", p.display());
    }
    println!("  {}", model_path.display());
    Ok(())
}

/// How an FMU's error names the step it must fit.
const SAMPLE_TIME: &str = "the surrogate's sample time";

/// The FMU `--truth fmu:` names, checked against the sample time.
fn load_fmu(src: &FmuSource, sample_time_ns: u64) -> Result<FmuModel> {
    let fmu = FmuModel::load(src).context("--truth")?;
    fmu.check_step(sample_time_ns, SAMPLE_TIME)
        .context("--truth")?;
    let d = fmu.description();
    println!(
        "truth: {} (FMI {} co-simulation, `{}`), step {} s",
        fmu.path.display(),
        d.version.as_str(),
        d.model_name,
        fmu.check_step(sample_time_ns, SAMPLE_TIME)? as f64 / 1e9
    );
    Ok(fmu)
}

/// Free runs of every trained model against the reference on the held-out cases (sine,
/// stair, descent profile); returns the summary section and the figures written.
fn holdout(
    cfg: &TrainConfig,
    outcome: &oils_lab::training::TrainOutcome,
    args: &TrainArgs,
    fmu: Option<&FmuModel>,
) -> Result<(String, Vec<PathBuf>)> {
    use oils_lab::training::holdout::{run_cases, table, Case};
    let dt = cfg.sample_time_ns;
    let mut cases = vec![Case::sine(dt), Case::stair(dt)];
    let mut note = String::new();
    match oils_shared::profile::ThrustProfile::load(&args.descent) {
        Ok(p) => cases.push(Case::from_profile("descent", &p, dt)),
        Err(e) => note = format!("(descent case skipped: {e})\n"),
    }
    let models: Vec<_> = outcome.models.iter().map(|m| &m.model).collect();
    let names: Vec<&str> = outcome.models.iter().map(|m| m.variant.as_str()).collect();
    let t0 = Instant::now();
    let (results, against) = match fmu {
        Some(fmu) => {
            let results = run_cases(cases, &fmu.factory(dt, SAMPLE_TIME), &models, dt);
            if let Some(e) = fmu.take_error() {
                bail!("held-out free runs on {}: {e}", fmu.path.display());
            }
            (results, format!("the FMU {}", fmu.path.display()))
        }
        None => {
            let hifi = oils_lab::training::hifi_params_of(cfg)?;
            let spec = oils_lab::training::reference_spec(cfg, &hifi);
            let reference = || {
                oils_emulator::propulsion::build(&spec)
                    .unwrap_or_else(|e| unreachable!("the reference was built for training: {e}"))
            };
            (
                run_cases(cases, &reference, &models, dt),
                cfg.reference.as_str().to_string(),
            )
        }
    };
    let mut text = format!(
        "\n## Held-out free runs against {against} ({:.1} s)\n\n{note}",
        t0.elapsed().as_secs_f64()
    );
    text.push_str(&table(&results, &names));
    let mut pngs = Vec::new();
    for r in &results {
        let p = args.out.join(format!("holdout_{}.png", r.case.name));
        oils_lab::training::figures::holdout(r, &names, &p)
            .with_context(|| format!("drawing {}", p.display()))?;
        pngs.push(p);
    }
    Ok((text, pngs))
}
