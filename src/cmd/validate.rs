//! `oils validate`: the surrogate, free-running, against the hifi model on the paper's
//! validation profiles (and any profile CSV given); a table, a JSON report, one figure
//! per case, and the error statistics written beside the model as its uncertainty.

use anyhow::{bail, Context, Result};
use oils_emulator::config::ScenarioConfig;
use oils_emulator::propulsion::hifi::runner::DESCENT_PROFILE_CSV;
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::surrogate::model_file::ModelFile;
use oils_emulator::propulsion::surrogate::DEFAULT_MODEL_JSON;
use oils_emulator::propulsion::{
    build_hifi, build_surrogate, BuildError, Propulsion, PropulsionKind, PropulsionSpec,
};
use oils_lab::fmu::import::{FmuModel, FmuSource};
use oils_lab::validation::cases::{self, CaseKind};
use oils_lab::validation::report::{Bounds, ValidationReport};
use oils_lab::validation::uncertainty::ModelUncertainty;
use oils_lab::validation::{plots, recorded, run_cases};
use oils_shared::profile::ThrustProfile;
use std::path::{Path, PathBuf};

/// How an FMU's error names the step it must fit.
const SAMPLE_TIME: &str = "the surrogate's sample time";

/// The committed descent profile, read at run time (the file may be replaced).
const DESCENT_PATH: &str = "emulator/data/descent-profile.csv";

/// Arguments of `oils validate`.
#[derive(Debug, clap::Args)]
pub struct ValidateArgs {
    /// Surrogate model file (default: the committed model).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Also validate on this thrust-command profile CSV (repeatable), judged like the
    /// descent (`t,cmd1..cmd4,on1..on4`: s, N, 0/1; rows hold).
    #[arg(long, value_name = "CSV")]
    pub profile: Vec<PathBuf>,
    /// The descent profile (default: emulator/data/descent-profile.csv, or the copy built
    /// into the binary when that path does not exist).
    #[arg(long, value_name = "CSV")]
    pub descent: Option<PathBuf>,
    /// Write the JSON report here (default: <out>/validate.json).
    #[arg(long, value_name = "JSON")]
    pub report: Option<PathBuf>,
    /// Write one PNG per case here (default: <out>/plots).
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
    /// Write the error statistics (model uncertainty) here (default: beside --model as
    /// <model>.uncertainty.json; for the committed model <out>/surrogate-default.uncertainty.json).
    #[arg(long, value_name = "JSON")]
    pub uncertainty: Option<PathBuf>,
    /// Default folder for the outputs not given explicitly.
    #[arg(long, value_name = "DIR", default_value = "target/oils-validate")]
    pub out: PathBuf,
    /// Hifi parameter TOML (default: emulator/config/hifi.toml's values).
    #[arg(long, value_name = "TOML")]
    pub hifi_params: Option<PathBuf>,
    /// Only the built-in cases whose names contain one of these (e.g. `sine`, `rise`,
    /// `descent`); user profiles always run.
    #[arg(long, value_name = "NAME")]
    pub only: Vec<String>,
    /// Exit non-zero when a case breaks the paper's bounds.
    #[arg(long)]
    pub check: bool,
    /// Judge the model on these recorded runs instead (CSV, the layout of
    /// docs/recorded-data.md): the recording is the truth, the surrogate runs free on
    /// its commands, each run is judged as a whole against the descent bounds.
    #[arg(long, value_name = "CSV", num_args = 1.., conflicts_with_all = ["profile", "only", "descent", "truth"])]
    pub data: Vec<PathBuf>,
    /// The truth the surrogate is judged against: `hifi` (default) or `fmu:PATH`, the
    /// user's FMU or its variable-mapping TOML (docs/fmu.md), run on the same cases.
    #[arg(long, value_name = "MODEL", conflicts_with = "hifi_params")]
    pub truth: Option<String>,
}

/// Runs `oils validate`.
pub fn run(args: &ValidateArgs) -> Result<()> {
    let scenario = ScenarioConfig::default();
    let cfg = scenario.propulsion.clone();
    // Refuse a bad model or parameter file before anything runs.
    let model_bytes = match &args.model {
        Some(p) => std::fs::read(p).with_context(|| format!("reading {}", p.display()))?,
        None => DEFAULT_MODEL_JSON.as_bytes().to_vec(),
    };
    let model_file = ModelFile::parse(&String::from_utf8_lossy(&model_bytes))
        .with_context(|| format!("surrogate model {}", model_name(args)))?;
    // Both models step at the surrogate's own sample time.
    let dt_ns = model_file.model.sample_time_ns;
    let spec = PropulsionSpec {
        surrogate_model: args.model.clone(),
        hifi: match &args.hifi_params {
            Some(p) => {
                HifiParams::load(p).with_context(|| format!("hifi parameters {}", p.display()))?
            }
            None => HifiParams::default(),
        },
        step_ns: Some(dt_ns),
        ..PropulsionSpec::new(PropulsionKind::Shadow, &cfg)
    };
    build_surrogate(&spec).context("building the surrogate")?;
    build_hifi(&spec).context("building the hifi model")?;

    let bounds = Bounds::PAPER;
    let model =
        || -> Result<Box<dyn Propulsion>, BuildError> { Ok(Box::new(build_surrogate(&spec)?)) };
    let print = |r: &oils_lab::validation::report::CaseReport| {
        eprintln!(
            "  {:<12} thrust max|err| {:8.3} N  rms {:7.3} N  mass max|err| {:7.3} kg  {}",
            r.name,
            r.thrust_max_abs_error_n,
            r.thrust_rms_error_n,
            r.mass_max_abs_error_kg,
            if r.pass {
                "within the paper's bounds"
            } else {
                "OUTSIDE the paper's bounds"
            }
        )
    };
    let fmu = match args.truth.as_deref() {
        None | Some("hifi") => None,
        Some(other) => {
            let src = FmuSource::parse(other)
                .with_context(|| format!("--truth {other}: expected hifi or fmu:PATH"))?
                .context("--truth")?;
            let fmu = FmuModel::load(&src).context("--truth")?;
            fmu.check_step(dt_ns, SAMPLE_TIME).context("--truth")?;
            Some(fmu)
        }
    };
    let (reports, traces, truth_name) = if let Some(fmu) = &fmu {
        let all = cases_of(args, &cfg)?;
        let make = fmu.factory(dt_ns, SAMPLE_TIME);
        let truth = || -> Result<Box<dyn Propulsion>, BuildError> { Ok(make()) };
        let ran = run_cases(
            &all,
            &truth,
            &model,
            dt_ns,
            scenario.wet_mass_kg(),
            &bounds,
            print,
        );
        if let Some(e) = fmu.take_error() {
            bail!("running {}: {e}", fmu.path.display());
        }
        let (r, t) = ran?;
        (r, t, "fmu")
    } else if args.data.is_empty() {
        let all = cases_of(args, &cfg)?;
        let truth =
            || -> Result<Box<dyn Propulsion>, BuildError> { Ok(Box::new(build_hifi(&spec)?)) };
        let (r, t) = run_cases(
            &all,
            &truth,
            &model,
            dt_ns,
            scenario.wet_mass_kg(),
            &bounds,
            print,
        )?;
        (r, t, "hifi")
    } else {
        let (mut reports, mut traces) = (Vec::new(), Vec::new());
        for p in &args.data {
            let run =
                oils_lab::training::recorded::load(p, dt_ns).context("reading recorded data")?;
            let case = recorded::case_of(&run)
                .with_context(|| format!("{}: commands as a profile", p.display()))?;
            let truth = || -> Result<Box<dyn Propulsion>, BuildError> {
                Ok(Box::new(recorded::Playback::new(&run)))
            };
            let (r, t) = run_cases(
                &[case],
                &truth,
                &model,
                dt_ns,
                scenario.wet_mass_kg(),
                &bounds,
                print,
            )?;
            reports.extend(r);
            traces.extend(t);
        }
        (reports, traces, "data")
    };
    let mut report = ValidationReport::new(
        model_name(args),
        model_file.provenance.reference.clone(),
        format!("{:?}", model_file.variant),
        match (truth_name, &fmu) {
            ("data", _) => format!("recorded data: {}", list(&args.data)),
            (_, Some(fmu)) => format!(
                "FMU {} (BLAKE3 with its mapping {})",
                fmu.path.display(),
                fmu.hash
            ),
            _ => args
                .hifi_params
                .as_ref()
                .map_or_else(|| "defaults".into(), |p| p.display().to_string()),
        },
        dt_ns as f64 * 1e-6,
        bounds,
        reports,
    );
    report.truth = truth_name.into();
    print!("{}", report.table());

    let json_path = args
        .report
        .clone()
        .unwrap_or_else(|| args.out.join("validate.json"));
    write_file(&json_path, &(report.to_json() + "\n"))?;
    eprintln!("wrote {}", json_path.display());

    let plot_dir = args.plots.clone().unwrap_or_else(|| args.out.join("plots"));
    std::fs::create_dir_all(&plot_dir)
        .with_context(|| format!("creating {}", plot_dir.display()))?;
    for t in &traces {
        let p = plots::write_case(&plot_dir, t, &bounds)
            .with_context(|| format!("plotting case {}", t.case.name))?;
        eprintln!("wrote {}", p.display());
    }

    let unc_path = match (&args.uncertainty, &args.model) {
        (Some(p), _) => p.clone(),
        (None, Some(m)) => ModelUncertainty::path_beside(m),
        (None, None) => args.out.join("surrogate-default.uncertainty.json"),
    };
    ModelUncertainty::from_traces(&traces, &model_name(args), &model_bytes, truth_name, 10.0)
        .save(&unc_path)?;
    eprintln!("wrote {}", unc_path.display());

    if args.check && !report.pass {
        bail!("the surrogate breaks the paper's bounds (see the table above)");
    }
    Ok(())
}

/// The built-in cases, the descent and the user's profiles, as the flags select them.
fn cases_of(
    args: &ValidateArgs,
    cfg: &oils_emulator::config::PropulsionConfig,
) -> Result<Vec<cases::Case>> {
    let mut all = cases::builtin();
    let descent = match &args.descent {
        Some(p) => cases::from_path(p, CaseKind::Descent, cfg.max_thrust_n)?,
        None if Path::new(DESCENT_PATH).exists() => {
            cases::from_path(Path::new(DESCENT_PATH), CaseKind::Descent, cfg.max_thrust_n)?
        }
        None => {
            eprintln!("oils validate: {DESCENT_PATH} not found; using the built-in copy");
            let p = ThrustProfile::parse(DESCENT_PROFILE_CSV)
                .map_err(|e| anyhow::anyhow!("built-in descent profile: {e}"))?;
            cases::from_profile(
                "descent",
                CaseKind::Descent,
                p,
                "built-in",
                cfg.max_thrust_n,
            )?
        }
    };
    all.push(descent);
    if !args.only.is_empty() {
        all.retain(|c| args.only.iter().any(|o| c.name.contains(o.as_str())));
    }
    for p in &args.profile {
        all.push(cases::from_path(p, CaseKind::Profile, cfg.max_thrust_n)?);
    }
    if all.is_empty() {
        bail!("no case selected (check --only)");
    }
    Ok(all)
}

fn model_name(args: &ValidateArgs) -> String {
    args.model
        .as_ref()
        .map_or_else(|| "committed default".into(), |p| p.display().to_string())
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn list(paths: &[PathBuf]) -> String {
    let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    names.join(", ")
}
