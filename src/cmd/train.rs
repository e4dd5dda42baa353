//! `oils train`: the system-identification pipeline of the seed paper, end to end.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use oils_emulator::surrogate::fit::Variant;
use oils_emulator::surrogate::{report, train_configured, Progress, TrainConfig};
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
    let text = match &args.config {
        Some(p) => std::fs::read_to_string(p)
            .with_context(|| format!("reading training configuration {}", p.display()))?,
        None => COMMITTED_CONFIG.to_string(),
    };
    let cfg = TrainConfig::from_toml(&text).context("training configuration")?;
    let bars = Bars {
        quiet: args.quiet,
        bar: Mutex::new(None),
    };
    let t0 = Instant::now();
    let outcome = train_configured(&cfg, &bars).context("training")?;
    let train_s = t0.elapsed().as_secs_f64();
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
            let (gram_s, fit_s) = oils_emulator::surrogate::cv::time_final_fit(
                Variant::Paper,
                paper.selection.history,
                paper.selection.mu,
                &outcome.dataset,
                &cfg.cv,
                &cfg.variants,
            );
            println!(
                "lasso timing (paper model, n={}, mu={:e}, tol={:e}): Gram {:.4} s, coordinate descent (7 outputs, single penalty) {:.4} s",
                paper.selection.history, paper.selection.mu, cfg.cv.tol, gram_s, fit_s
            );
        }
    }
    print!("{}", report::summary(&outcome, cfg.top_terms));
    println!(
        "\ntraining took {train_s:.1} s; reports in {}:",
        args.out.display()
    );
    for p in written {
        println!("  {}", p.display());
    }
    println!("  {}", model_path.display());
    Ok(())
}
