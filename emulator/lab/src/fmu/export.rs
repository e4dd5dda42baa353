//! Packs a bench propulsion model (a surrogate model file, or hifi) as an FMU: the model
//! description, the `oils-fmu` binary as `binaries/<platform>/oils_propulsion.so`, and
//! the model in `resources/` ([`oils_fmu::Resource`]). Also runs the packed model in
//! the bench on a profile, so an FMU run elsewhere can be compared with it.

use super::describe::{model_description, Description, FmiVersion};
use super::FmuError;
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::runner::command_at;
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::surrogate::model_file::ModelFile;
use oils_emulator::propulsion::{Propulsion, PropulsionKind};
use oils_fmu::variables::float_value;
use oils_fmu::{Causality, Resource, RESOURCE_FILE, RESOURCE_FORMAT, RESOURCE_VERSION, VARIABLES};
use oils_shared::profile::ThrustProfile;
use std::io::Write;
use std::path::{Path, PathBuf};

/// File name of the FMU binary as cargo builds it.
pub const BINARY_FILE: &str = "liboils_fmu.so";
/// The surrogate's model file in `resources/`.
pub const MODEL_RESOURCE: &str = "surrogate.json";

/// What to pack.
#[derive(Debug, Clone)]
pub enum Packable {
    /// A surrogate model file: its text (packed as it is) and the checked file.
    Surrogate {
        /// The file's text.
        text: String,
        /// The parsed, checked file.
        file: Box<ModelFile>,
    },
    /// hifi with these parameters, stepped every `step_ns`.
    Hifi {
        /// Parameters.
        params: Box<HifiParams>,
        /// Step, nanoseconds.
        step_ns: u64,
    },
}

impl Packable {
    /// The resource file naming it (token included).
    pub fn resource(&self, engines: &PropulsionConfig) -> Resource {
        let (kind, hifi, model, step_ns) = match self {
            Packable::Surrogate { file, .. } => (
                PropulsionKind::Surrogate,
                None,
                Some(MODEL_RESOURCE.to_string()),
                file.model.sample_time_ns,
            ),
            Packable::Hifi { params, step_ns } => (
                PropulsionKind::Hifi,
                Some((**params).clone()),
                None,
                *step_ns,
            ),
        };
        let mut r = Resource {
            format: RESOURCE_FORMAT.into(),
            version: RESOURCE_VERSION,
            token: String::new(),
            kind,
            engines: engines.clone(),
            hifi,
            surrogate_model: model,
            step_ns,
        };
        let mut h = blake3::Hasher::new();
        h.update(serde_json::to_string(&r).unwrap_or_default().as_bytes());
        if let Packable::Surrogate { text, .. } = self {
            h.update(text.as_bytes());
        }
        let b = h.finalize();
        let x = b.to_hex();
        r.token = format!(
            "{{{}-{}-{}-{}-{}}}",
            &x[0..8],
            &x[8..12],
            &x[12..16],
            &x[16..20],
            &x[20..32]
        );
        r
    }
}

/// Where the FMU binary is: `explicit`, else `$OILS_FMU_BINARY`, else beside this
/// executable (or in its `deps/`, where cargo leaves it for tests).
pub fn find_binary(explicit: Option<&Path>) -> Result<PathBuf, FmuError> {
    if let Some(p) = explicit {
        return Ok(p.to_path_buf());
    }
    if let Some(p) = std::env::var_os("OILS_FMU_BINARY") {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe().map_err(|source| FmuError::Io {
        path: "the running executable".into(),
        source,
    })?;
    let dir = exe.parent().unwrap_or(Path::new("."));
    let candidates = [
        dir.join(BINARY_FILE),
        dir.join("deps").join(BINARY_FILE),
        dir.parent().unwrap_or(dir).join(BINARY_FILE),
    ];
    candidates
        .iter()
        .find(|p| p.is_file())
        .cloned()
        .ok_or_else(|| FmuError::NoBinary {
            looked: dir.display().to_string(),
        })
}

/// Writes the FMU of `what` to `out`; returns the resource it holds.
pub fn pack(
    out: &Path,
    what: &Packable,
    engines: &PropulsionConfig,
    version: FmiVersion,
    binary: &Path,
) -> Result<Resource, FmuError> {
    let platform = version.platform().ok_or(FmuError::Platform {
        os: std::env::consts::OS,
        arch: std::env::consts::ARCH,
    })?;
    let lib = std::fs::read(binary).map_err(|source| FmuError::Io {
        path: binary.display().to_string(),
        source,
    })?;
    let resource = what.resource(engines);
    let (name, about) = match what {
        Packable::Surrogate { file, .. } => (
            "oils propulsion surrogate".to_string(),
            format!(
                "The learned sparse surrogate of the oils bench ({} variant, history {}, trained on {}): four throttleable engines, commands and switches in, thrust, gas pressure and ejected propellant out.",
                file.variant.as_str(),
                file.selection.history,
                file.provenance.reference
            ),
        ),
        Packable::Hifi { .. } => (
            "oils propulsion hifi".to_string(),
            "The oils bench's high-fidelity lumped-parameter model of the pressure-fed propulsion system: four throttleable engines, commands and switches in, thrust, pressures and ejected propellant out.".to_string(),
        ),
    };
    let xml = model_description(
        version,
        &Description {
            model_name: name,
            description: about,
            token: resource.token.clone(),
            step_s: resource.step_ns as f64 / 1e9,
            tool: format!("oils {}", env!("CARGO_PKG_VERSION")),
        },
    );
    let io = |source| FmuError::Io {
        path: out.display().to_string(),
        source,
    };
    let file = std::fs::File::create(out).map_err(io)?;
    let mut zip = zip::ZipWriter::new(file);
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .last_modified_time(zip::DateTime::default());
    let mut add = |name: &str, bytes: &[u8], mode: u32| -> Result<(), FmuError> {
        zip.start_file(name, opts.unix_permissions(mode))
            .map_err(|e| FmuError::Zip(e.to_string()))?;
        zip.write_all(bytes).map_err(io)
    };
    add("modelDescription.xml", xml.as_bytes(), 0o644)?;
    add(
        &format!("binaries/{platform}/{}.so", oils_fmu::MODEL_IDENTIFIER),
        &lib,
        0o755,
    )?;
    let json = serde_json::to_string_pretty(&resource).map_err(|e| FmuError::Zip(e.to_string()))?;
    add(
        &format!("resources/{RESOURCE_FILE}"),
        json.as_bytes(),
        0o644,
    )?;
    if let Packable::Surrogate { text, .. } = what {
        add(
            &format!("resources/{MODEL_RESOURCE}"),
            text.as_bytes(),
            0o644,
        )?;
    }
    zip.finish().map_err(|e| FmuError::Zip(e.to_string()))?;
    Ok(resource)
}

/// The header of [`bench_csv`]: time, then the FMU's outputs in value-reference order.
pub fn bench_csv_header() -> String {
    let mut h = String::from("time");
    for v in VARIABLES
        .iter()
        .filter(|v| v.causality == Causality::Output)
    {
        h.push(',');
        h.push_str(v.name);
    }
    h
}

/// Runs `model` on `profile` (each row's command, as given, held from its time) in
/// steps of `step_ns` to `duration_ns`, and writes the FMU's outputs at every step end
/// (the first row: the initial outputs) as CSV, shortest round-trip decimals.
pub fn bench_csv(
    model: &mut dyn Propulsion,
    profile: &ThrustProfile,
    step_ns: u64,
    duration_ns: i64,
    out: &mut impl Write,
) -> std::io::Result<u64> {
    writeln!(out, "{}", bench_csv_header())?;
    let mut row = |t_ns: i64, o: &oils_emulator::propulsion::PropulsionOutput| {
        let cmd = command_at(profile, t_ns);
        write!(out, "{}", t_ns as f64 / 1e9)?;
        for v in VARIABLES
            .iter()
            .filter(|v| v.causality == Causality::Output)
        {
            write!(
                out,
                ",{}",
                float_value(v.vr, o, &cmd, 0.0).unwrap_or(f64::NAN)
            )?;
        }
        writeln!(out)
    };
    row(0, &model.output())?;
    let mut t_ns = 0i64;
    let mut steps = 0;
    while t_ns < duration_ns {
        let o = model.step(&command_at(profile, t_ns), step_ns);
        t_ns += step_ns as i64;
        steps += 1;
        row(t_ns, &o)?;
    }
    out.flush()?;
    Ok(steps)
}
