//! `oils export-fmu`: a learned surrogate (or hifi) packed as an FMI 3.0 (or 2.0)
//! co-simulation FMU that runs without the bench, in Simulink, Dymola, OpenModelica,
//! FMPy or any FMI importer. With `--profile`, the bench also runs the packed model on
//! that profile and writes what the FMU must answer, for comparison.

use anyhow::{bail, Context, Result};
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::surrogate::model_file::ModelFile;
use oils_emulator::propulsion::surrogate::DEFAULT_MODEL_JSON;
use oils_emulator::propulsion::{self, PropulsionKind, PropulsionSpec};
use oils_lab::fmu::describe::FmiVersion;
use oils_lab::fmu::export::{self, Packable};
use oils_shared::profile::{ProfileRules, ThrustProfile};
use std::path::PathBuf;

/// Arguments of `oils export-fmu`.
#[derive(Debug, clap::Args)]
pub struct ExportFmuArgs {
    /// Surrogate model file to pack (default: the committed model).
    #[arg(long, value_name = "FILE", conflicts_with = "hifi")]
    pub model: Option<PathBuf>,
    /// Pack the hifi model instead (the round trip of `--truth fmu:`).
    #[arg(long)]
    pub hifi: bool,
    /// hifi's parameters (TOML; default: emulator/config/hifi.toml's values).
    #[arg(long, value_name = "TOML", requires = "hifi")]
    pub hifi_params: Option<PathBuf>,
    /// hifi's step inside the FMU, milliseconds (a communication step must be a multiple).
    #[arg(long, value_name = "MS", default_value_t = 10, requires = "hifi")]
    pub hifi_step_ms: u64,
    /// The FMU to write.
    #[arg(long, value_name = "FMU")]
    pub out: PathBuf,
    /// FMI version: 3 or 2.
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub fmi_version: u8,
    /// The FMU binary (default: liboils_fmu.so beside this executable, or $OILS_FMU_BINARY).
    #[arg(long, value_name = "SO")]
    pub binary: Option<PathBuf>,
    /// Also run the packed model in the bench on this profile (rows held, to the last
    /// row plus 2 s, in the model's steps) and write its outputs to --profile-out.
    #[arg(long, value_name = "CSV", requires = "profile_out")]
    pub profile: Option<PathBuf>,
    /// Where to write the bench's outputs on --profile (time, then the FMU's outputs).
    #[arg(long, value_name = "CSV", requires = "profile")]
    pub profile_out: Option<PathBuf>,
}

/// Runs `oils export-fmu`.
pub fn run(args: &ExportFmuArgs) -> Result<()> {
    let version = match args.fmi_version {
        2 => FmiVersion::V2,
        3 => FmiVersion::V3,
        n => bail!("--fmi-version {n}: expected 2 or 3"),
    };
    let engines = PropulsionConfig::default();
    let what =
        if args.hifi {
            let params = match &args.hifi_params {
                Some(p) => HifiParams::load(p)
                    .with_context(|| format!("hifi parameters {}", p.display()))?,
                None => HifiParams::default(),
            };
            if !(1..=1000).contains(&args.hifi_step_ms) {
                bail!("--hifi-step-ms must be 1-1000, got {}", args.hifi_step_ms);
            }
            Packable::Hifi {
                params: Box::new(params),
                step_ns: args.hifi_step_ms * 1_000_000,
            }
        } else {
            let text = match &args.model {
                Some(p) => std::fs::read_to_string(p)
                    .with_context(|| format!("reading {}", p.display()))?,
                None => DEFAULT_MODEL_JSON.to_string(),
            };
            let file = ModelFile::parse(&text).context("surrogate model file")?;
            Packable::Surrogate {
                text,
                file: Box::new(file),
            }
        };
    let binary = export::find_binary(args.binary.as_deref())?;
    let resource = export::pack(&args.out, &what, &engines, version, &binary)
        .with_context(|| format!("packing {}", args.out.display()))?;
    println!(
        "wrote {} (FMI {}.0 co-simulation, {} model, step {} s, token {})",
        args.out.display(),
        args.fmi_version,
        resource.kind.as_str(),
        resource.step_ns as f64 / 1e9,
        resource.token
    );
    if let (Some(p), Some(out)) = (&args.profile, &args.profile_out) {
        let profile = ThrustProfile::load_with(p, &ProfileRules::rated(engines.max_thrust_n))
            .with_context(|| format!("reading profile {}", p.display()))?;
        let spec = PropulsionSpec {
            surrogate_model: args.model.clone(),
            hifi: resource.hifi.clone().unwrap_or_default(),
            step_ns: Some(resource.step_ns),
            ..PropulsionSpec::new(
                if args.hifi {
                    PropulsionKind::Hifi
                } else {
                    PropulsionKind::Surrogate
                },
                &engines,
            )
        };
        let mut model = propulsion::build(&spec).context("building the bench's model")?;
        let duration_ns = profile.end_ns() + 2_000_000_000;
        let file =
            std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
        let steps = export::bench_csv(
            model.as_mut(),
            &profile,
            resource.step_ns,
            duration_ns,
            &mut std::io::BufWriter::new(file),
        )
        .with_context(|| format!("writing {}", out.display()))?;
        println!(
            "bench run of the packed model: {steps} steps to {}",
            out.display()
        );
    }
    Ok(())
}
