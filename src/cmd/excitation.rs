//! `oils excitation`: the training excitation (seed paper eq. 1-4: 4-sphere sines over M
//! levels, steps, ramps, on/off switching; exactly what `oils train` drives its
//! reference with) as a thrust-command profile, one row per sample time, for the user
//! to run through their own propulsion model or test stand.

use anyhow::{Context, Result};
use oils_lab::training::TrainConfig;
use std::path::PathBuf;

/// Arguments of `oils excitation`.
#[derive(Debug, clap::Args)]
pub struct ExcitationArgs {
    /// The profile CSV to write (`t,cmd1..cmd4,on1..on4`: s, N, 0/1; a row per sample
    /// time). Its sample time and length also go to `<OUT>.json` beside it.
    #[arg(long, value_name = "CSV")]
    pub out: PathBuf,
    /// Training configuration whose excitation and sample time to write (default: the
    /// committed emulator/config/train-user.toml; its excitation is train.toml's).
    #[arg(long, value_name = "TOML")]
    pub config: Option<PathBuf>,
}

/// Runs `oils excitation`.
pub fn run(args: &ExcitationArgs) -> Result<()> {
    let text = match &args.config {
        Some(p) => std::fs::read_to_string(p)
            .with_context(|| format!("reading training configuration {}", p.display()))?,
        None => oils_lab::training::user::USER_CONFIG.to_string(),
    };
    let cfg = TrainConfig::from_toml(&text).context("training configuration")?;
    let ex = cfg.excitation.generate(cfg.sample_time_ns);
    let profile = ex
        .to_profile()
        .context("the excitation is not a valid profile")?;
    std::fs::write(&args.out, profile.to_csv())
        .with_context(|| format!("writing {}", args.out.display()))?;
    let sample_s = cfg.sample_time_ns as f64 / 1e9;
    let duration_s = ex.inputs.len() as f64 * sample_s;
    let meta = serde_json::json!({
        "profile": args.out.file_name().map(|n| n.to_string_lossy().into_owned()),
        "sample_time_s": sample_s,
        "sample_time_ns": cfg.sample_time_ns,
        "rows": ex.inputs.len(),
        "duration_s": duration_s,
        "excitation_seed": cfg.excitation.seed,
        "train_config_hash": cfg.hash_hex(),
        "row_meaning": "each row's command holds for one sample time, from its t to the next row's",
    });
    let meta_path = args.out.with_extension("json");
    std::fs::write(&meta_path, format!("{meta:#}\n"))
        .with_context(|| format!("writing {}", meta_path.display()))?;
    println!(
        "excitation: {} rows, sample time {sample_s} s, {duration_s} s, to {} (and {})",
        ex.inputs.len(),
        args.out.display(),
        meta_path.display()
    );
    println!(
        "run it through your model for {duration_s} s and train on the result, e.g. with hifi:\n  oils hifi --profile {} --out data.csv --duration-s {duration_s}\n  oils train --data data.csv --model my-surrogate.json",
        args.out.display()
    );
    Ok(())
}
