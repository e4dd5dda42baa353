//! `oils hifi`: run the high-fidelity propulsion model open loop from a thrust-command
//! profile and write every output as CSV, and/or draw its documentation figures.

use anyhow::{bail, Context, Result};
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::{runner, HifiParams, HifiPropulsion};
use oils_lab::hifi_figures as figures;
use oils_shared::profile::{ProfileRules, ThrustProfile, MAX_PROFILE_END_S};
use std::io::BufWriter;
use std::path::PathBuf;

/// Seconds simulated after a profile's last row unless `--duration-s` says otherwise.
const TAIL_S: f64 = 2.0;
/// Longest `--duration-s` (and implied duration): the latest profile row plus the tail.
const MAX_DURATION_S: f64 = MAX_PROFILE_END_S + TAIL_S;
/// Most output rows (`duration / dt`): ~1 kB each, so at most ~4 GB of CSV.
const MAX_STEPS: u64 = 4_000_000;

/// Arguments of `oils hifi`.
#[derive(Debug, clap::Args)]
pub struct HifiArgs {
    /// Thrust-command profile CSV (`t,cmd1..cmd4,on1..on4`: s, N, 0/1; rows hold).
    #[arg(long, value_name = "CSV", requires = "out")]
    pub profile: Option<PathBuf>,
    /// Output CSV: every model output at the bench step, units in the header.
    #[arg(long, value_name = "CSV", requires = "profile")]
    pub out: Option<PathBuf>,
    /// Model parameters (TOML; any subset of `emulator/config/hifi.toml`).
    #[arg(long, value_name = "TOML")]
    pub params: Option<PathBuf>,
    /// Bench step, milliseconds.
    #[arg(long, value_name = "MS", default_value_t = 10.0)]
    pub dt_ms: f64,
    /// Simulated duration, seconds (default: the profile's last row plus 2 s).
    #[arg(long, value_name = "S")]
    pub duration_s: Option<f64>,
    /// Write the documentation figures (step-stair, fall, cross-coupling, full
    /// descent) as PNG files into this directory. The descent uses `--profile` if
    /// given, else the committed descent profile.
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
}

/// Runs `oils hifi`.
pub fn run(args: &HifiArgs) -> Result<()> {
    if args.profile.is_none() && args.plots.is_none() {
        bail!("nothing to do: give --profile CSV --out CSV, or --plots DIR (or both)");
    }
    if !(args.dt_ms.is_finite() && args.dt_ms >= 0.001 && args.dt_ms <= 1000.0) {
        bail!("--dt-ms must be between 0.001 and 1000, got {}", args.dt_ms);
    }
    let dt_ns = (args.dt_ms * 1e6).round() as u64;
    let params = match &args.params {
        Some(p) => HifiParams::load(p).with_context(|| format!("loading {}", p.display()))?,
        None => HifiParams::default(),
    };
    let cfg = PropulsionConfig::default();
    let profile = match &args.profile {
        Some(p) => Some(
            ThrustProfile::load_with(p, &ProfileRules::rated(cfg.max_thrust_n))
                .with_context(|| format!("reading profile {}", p.display()))?,
        ),
        None => None,
    };

    if let (Some(profile), Some(out)) = (&profile, &args.out) {
        let duration_s = match args.duration_s {
            Some(d) if d.is_finite() && d > 0.0 && d <= MAX_DURATION_S => d,
            Some(d) => bail!("--duration-s must be in (0, {MAX_DURATION_S}] s, got {d}"),
            None => profile.end_ns() as f64 * 1e-9 + TAIL_S,
        };
        let steps = (duration_s * 1e9 / dt_ns as f64).ceil();
        if steps > MAX_STEPS as f64 {
            bail!(
                "{duration_s} s at --dt-ms {} is {steps} output rows; at most {MAX_STEPS} (shorten the profile or --duration-s, or lengthen --dt-ms)",
                args.dt_ms
            );
        }
        let mut model = HifiPropulsion::new(&params, &cfg).context("building the hifi model")?;
        let file =
            std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
        let mut w = BufWriter::new(file);
        let started = std::time::Instant::now();
        let summary = runner::run_profile(
            &mut model,
            profile,
            dt_ns,
            (duration_s * 1e9).round() as i64,
            &mut w,
        )
        .with_context(|| format!("running the profile into {}", out.display()))?;
        let wall_s = started.elapsed().as_secs_f64();
        let last = &summary.last.out;
        eprintln!(
            "hifi: {} steps, {:.1} s simulated in {:.2} s wall ({:.0}x real time); \
             ejected fuel {:.2} kg, ox {:.2} kg; gas {:.1} bar",
            summary.steps,
            summary.duration_s,
            wall_s,
            summary.duration_s / wall_s.max(1e-9),
            last.ejected_fuel_kg,
            last.ejected_ox_kg,
            last.gas_pressure_pa * 1e-5
        );
    }

    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let written = figures::write_all(dir, &params, &cfg, profile.as_ref(), dt_ns)
            .context("drawing the hifi figures")?;
        for f in written {
            eprintln!("wrote {}", f.display());
        }
    }
    Ok(())
}
