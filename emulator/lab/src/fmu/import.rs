//! The user's propulsion model as an FMI 2.0 / 3.0 co-simulation FMU, as the bench's
//! truth: `oils train --truth fmu:PATH`, `oils validate --truth fmu:PATH`,
//! `oils run --propulsion fmu:PATH`. `PATH` is the `.fmu`, or a variable mapping
//! ([`Mapping`], TOML, `docs/fmu.md`) that names it; an FMU whose variables have the
//! names `oils export-fmu` writes needs no mapping ([`Mapping::oils`]).
//!
//! The C interface is called through the `oils-fmi` crate; [`FmuPropulsion`] is the
//! bench's [`Propulsion`] over one instance. Everything here is safe Rust.

use oils_emulator::propulsion::held::Held;
use oils_emulator::propulsion::BuildError;
use oils_emulator::propulsion::{EngineCommand, Propulsion, PropulsionOutput};
use oils_emulator::run_config::RunConfig;
use oils_fmi::{FmiError, Fmu, Instance, ModelDescription, VarType};
use oils_shared::ENGINE_COUNT;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The prefix of an FMU on the command line (`fmu:PATH`).
pub const PREFIX: &str = "fmu:";

/// The mapping of an FMU's variables to the bench's propulsion commands and outputs
/// (`docs/fmu.md`, "Variable mapping").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mapping {
    /// The FMU, relative to the mapping file (absent in [`Mapping::oils`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fmu: Option<PathBuf>,
    /// The communication step, seconds; default: the model description's default
    /// experiment step, else its fixed internal step (FMI 3.0), else the bench's step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_s: Option<f64>,
    /// What the bench sets before each step.
    pub inputs: Inputs,
    /// What it reads after each step.
    pub outputs: Outputs,
}

/// Inputs: one variable per engine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    /// Thrust command per engine, N (Real / Float64).
    pub thrust_cmd_n: Vec<String>,
    /// Engine on/off (Boolean, or Real 1/0). Absent: an engine that is off is
    /// commanded 0 N.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub on: Option<Vec<String>>,
}

/// Outputs (Real / Float64).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Outputs {
    /// Thrust per engine at the step's end, N.
    pub thrust_n: Vec<String>,
    /// Helium (gas) bottle pressure, Pa.
    pub gas_pressure_pa: String,
    /// Fuel ejected since the start, kg.
    pub ejected_fuel_kg: String,
    /// Oxidiser ejected since the start, kg.
    pub ejected_ox_kg: String,
    /// Mean thrust per engine over the step, N. Absent: the mean of the thrusts at the
    /// step's two ends.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_thrust_n: Option<Vec<String>>,
    /// Chamber pressure per engine, Pa. Absent: reported as 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber_pressure_pa: Option<Vec<String>>,
    /// Fuel tank pressure, Pa. Absent: 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fuel_tank_pa: Option<String>,
    /// Oxidiser tank pressure, Pa. Absent: 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ox_tank_pa: Option<String>,
    /// Fuel mass flow, kg/s. Absent: the ejected fuel's change over the step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fuel_flow_kg_s: Option<String>,
    /// Oxidiser mass flow, kg/s. Absent: as for fuel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ox_flow_kg_s: Option<String>,
}

fn engines(f: impl Fn(usize) -> String) -> Vec<String> {
    (1..=ENGINE_COUNT).map(f).collect()
}

impl Mapping {
    /// The mapping of an FMU that `oils export-fmu` wrote (the names of
    /// `oils_fmu::VARIABLES`): the one used when `fmu:` names an `.fmu`. Its optional
    /// entries apply only where the FMU has the variable.
    pub fn oils() -> Self {
        Self {
            fmu: None,
            step_s: None,
            inputs: Inputs {
                thrust_cmd_n: engines(|e| format!("cmd{e}_n")),
                on: Some(engines(|e| format!("on{e}"))),
            },
            outputs: Outputs {
                thrust_n: engines(|e| format!("thrust{e}_n")),
                gas_pressure_pa: "gas_pressure_pa".into(),
                ejected_fuel_kg: "ejected_fuel_kg".into(),
                ejected_ox_kg: "ejected_ox_kg".into(),
                mean_thrust_n: Some(engines(|e| format!("mean_thrust{e}_n"))),
                chamber_pressure_pa: Some(engines(|e| format!("chamber{e}_pa"))),
                fuel_tank_pa: Some("fuel_tank_pa".into()),
                ox_tank_pa: Some("ox_tank_pa".into()),
                fuel_flow_kg_s: Some("fuel_flow_kg_s".into()),
                ox_flow_kg_s: Some("ox_flow_kg_s".into()),
            },
        }
    }

    /// Parses a mapping file's text.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| e.to_string())
    }
}

/// An FMU could not be imported as the bench's propulsion model.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The FMU could not be opened or called.
    #[error("{path}: {source}")]
    Fmi {
        /// The FMU.
        path: PathBuf,
        /// What failed.
        #[source]
        source: FmiError,
    },
    /// `fmu:` without a path, or the mapping file could not be read.
    #[error("{0}")]
    Source(String),
    /// The mapping is malformed.
    #[error("variable mapping {path}: {why}")]
    Mapping {
        /// The mapping file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// A mapped variable is not in the FMU.
    #[error("{fmu}: the FMU has no variable `{name}` (mapped as {role}){hint}")]
    MissingVariable {
        /// The FMU.
        fmu: PathBuf,
        /// The name.
        name: String,
        /// Its place in the mapping (`inputs.thrust_cmd_n[0]`).
        role: String,
        /// A note on what to do.
        hint: String,
    },
    /// A mapped variable has the wrong type or causality.
    #[error("{fmu}: variable `{name}` (mapped as {role}) is {found}, the bench needs {expected}")]
    MistypedVariable {
        /// The FMU.
        fmu: PathBuf,
        /// The name.
        name: String,
        /// Its place in the mapping.
        role: String,
        /// What it is.
        found: String,
        /// What it must be.
        expected: String,
    },
    /// The FMU's step does not fit the step the bench takes.
    #[error("{fmu}: the FMU's step {fmu_step_s} s ({source_of_step}) does not fit {caller} {caller_step_s} s: one must be a whole multiple of the other (set step_s in the variable mapping)")]
    Step {
        /// The FMU.
        fmu: PathBuf,
        /// The FMU's communication step, seconds.
        fmu_step_s: f64,
        /// Where that step came from.
        source_of_step: &'static str,
        /// The bench's step, seconds.
        caller_step_s: f64,
        /// Whose step it is (`the surrogate's sample time`, `the plant step`).
        caller: String,
    },
}

/// A variable's value reference and, for an on/off input, whether it is Real.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Slot {
    vr: u32,
    real: bool,
}

/// A mapping checked against an FMU: value references in the order the instance uses.
#[derive(Debug, Clone, PartialEq)]
struct Resolved {
    cmd: [u32; ENGINE_COUNT],
    on: Option<[Slot; ENGINE_COUNT]>,
    /// Outputs read after each step: thrust x4, gas, fuel, ox, then the optional ones.
    out_vrs: Vec<u32>,
    mean: Option<usize>,
    chamber: Option<usize>,
    fuel_tank: Option<usize>,
    ox_tank: Option<usize>,
    fuel_flow: Option<usize>,
    ox_flow: Option<usize>,
}

/// Where an FMU and its mapping come from (the `PATH` of `fmu:PATH`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FmuSource {
    /// What was given: the `.fmu` or the mapping `.toml`.
    pub given: PathBuf,
}

impl FmuSource {
    /// `fmu:PATH`'s source, or `None` when `spec` does not start with `fmu:`.
    pub fn parse(spec: &str) -> Option<Result<Self, ImportError>> {
        let path = spec.strip_prefix(PREFIX)?;
        Some(if path.is_empty() {
            Err(ImportError::Source(
                "fmu: needs a path: fmu:MODEL.fmu or fmu:MAPPING.toml".into(),
            ))
        } else {
            Ok(Self {
                given: PathBuf::from(path),
            })
        })
    }
}

/// An FMU loaded and its mapping checked: makes instances ([`FmuModel::instantiate`]).
#[derive(Debug, Clone)]
pub struct FmuModel {
    fmu: Arc<Fmu>,
    resolved: Arc<Resolved>,
    /// The `.fmu` file.
    pub path: PathBuf,
    /// The communication step, nanoseconds.
    pub step_ns: u64,
    step_source: &'static str,
    /// BLAKE3 of the FMU's bytes and the mapping's text (provenance).
    pub hash: String,
    /// The first failure of any instance (instantiation, a refused call, a non-finite
    /// output), in the FMU's words.
    errors: Arc<Mutex<Option<String>>>,
}

impl FmuModel {
    /// Loads what `source` names.
    pub fn load(source: &FmuSource) -> Result<Self, ImportError> {
        let given = &source.given;
        let is_toml = given.extension().is_some_and(|e| e == "toml");
        let (mapping, mapping_text, fmu_path) = if is_toml {
            let text = std::fs::read_to_string(given).map_err(|e| {
                ImportError::Source(format!("variable mapping {}: {e}", given.display()))
            })?;
            let mapping = Mapping::from_toml(&text).map_err(|why| ImportError::Mapping {
                path: given.clone(),
                why,
            })?;
            let Some(rel) = mapping.fmu.clone() else {
                return Err(ImportError::Mapping {
                    path: given.clone(),
                    why: "no `fmu = \"MODEL.fmu\"`: the mapping must name its FMU".into(),
                });
            };
            let dir = given.parent().unwrap_or(Path::new(""));
            (mapping, text, dir.join(rel))
        } else {
            (Mapping::oils(), String::new(), given.clone())
        };
        let bytes = std::fs::read(&fmu_path)
            .map_err(|e| ImportError::Source(format!("{}: {e}", fmu_path.display())))?;
        let mut h = blake3::Hasher::new();
        h.update(&bytes);
        h.update(mapping_text.as_bytes());
        let hash = h.finalize().to_hex().to_string();
        let fmu = Fmu::open(&fmu_path).map_err(|source| ImportError::Fmi {
            path: fmu_path.clone(),
            source,
        })?;
        let resolved = resolve(&mapping, fmu.description(), &fmu_path, is_toml)?;
        let d = fmu.description();
        let (step_s, step_source) =
            match (mapping.step_s, d.default_step_s, d.fixed_internal_step_s) {
                (Some(s), _, _) => (Some(s), "step_s of the variable mapping"),
                (None, Some(s), _) => (
                    Some(s),
                    "the model description's DefaultExperiment stepSize",
                ),
                (None, None, Some(s)) => (Some(s), "the model description's fixedInternalStepSize"),
                (None, None, None) => (None, "the bench's step"),
            };
        let step_ns = match step_s {
            Some(s) if s.is_finite() && s > 0.0 && (s * 1e9).round() >= 1.0 && s <= 1e3 => {
                (s * 1e9).round() as u64
            }
            Some(s) => {
                return Err(ImportError::Mapping {
                    path: given.clone(),
                    why: format!("step_s = {s} ({step_source}): must be in (0, 1000] seconds"),
                })
            }
            None => 0,
        };
        Ok(Self {
            fmu: Arc::new(fmu),
            resolved: Arc::new(resolved),
            path: fmu_path,
            step_ns,
            step_source,
            hash,
            errors: Arc::default(),
        })
    }

    /// The first failure of an instance since the last call (instantiation in
    /// [`FmuModel::factory`], a refused call or a non-finite output while stepping).
    pub fn take_error(&self) -> Option<String> {
        self.errors.lock().ok().and_then(|mut e| e.take())
    }

    fn record(&self, e: String) {
        if let Ok(mut slot) = self.errors.lock() {
            slot.get_or_insert(e);
        }
    }

    /// A factory of instances for callers that take infallible ones (training's and
    /// validation's case runners): an instance that cannot be made is [`Unavailable`]
    /// and its error is kept for [`FmuModel::take_error`]. Check the step first
    /// ([`FmuModel::check_step`]).
    pub fn factory(
        &self,
        dt_ns: u64,
        caller: &'static str,
    ) -> impl Fn() -> Box<dyn Propulsion> + Sync + '_ {
        move || match self.instantiate(dt_ns, caller) {
            Ok(p) => p,
            Err(e) => {
                self.record(e.to_string());
                Box::new(Unavailable)
            }
        }
    }

    /// The model description.
    pub fn description(&self) -> &ModelDescription {
        self.fmu.description()
    }

    /// Whether the FMU allows one instance per process only.
    pub fn single_instance(&self) -> bool {
        self.fmu.description().only_once_per_process
    }

    /// The FMU's step for a bench step of `dt_ns` taken by `caller` (`the plant step`):
    /// an error when neither is a whole multiple of the other.
    pub fn check_step(&self, dt_ns: u64, caller: &str) -> Result<u64, ImportError> {
        let step = if self.step_ns == 0 {
            dt_ns
        } else {
            self.step_ns
        };
        if dt_ns == 0 || !(dt_ns.is_multiple_of(step) || step.is_multiple_of(dt_ns)) {
            return Err(ImportError::Step {
                fmu: self.path.clone(),
                fmu_step_s: step as f64 / 1e9,
                source_of_step: self.step_source,
                caller_step_s: dt_ns as f64 / 1e9,
                caller: caller.to_string(),
            });
        }
        Ok(step)
    }

    /// A fresh instance, stepped by the bench every `dt_ns` (`caller` names that step in
    /// an error): the FMU stepped `dt / step` times per bench step, or sampled and held
    /// when its step is the longer one.
    pub fn instantiate(
        &self,
        dt_ns: u64,
        caller: &str,
    ) -> Result<Box<dyn Propulsion>, ImportError> {
        self.instantiate_reporting(dt_ns, caller, true)
    }

    /// [`FmuModel::instantiate`]; a failure goes to [`FmuModel::take_error`] when
    /// `keep_error`, else to stderr (the loop has no one to ask).
    fn instantiate_reporting(
        &self,
        dt_ns: u64,
        caller: &str,
        keep_error: bool,
    ) -> Result<Box<dyn Propulsion>, ImportError> {
        let step = self.check_step(dt_ns, caller)?;
        let mut p = FmuPropulsion::new(self, step)?;
        p.errors = keep_error.then(|| self.errors.clone());
        Ok(if step > dt_ns {
            Box::new(Held::new(p, step))
        } else {
            Box::new(p)
        })
    }
}

fn resolve(
    m: &Mapping,
    d: &ModelDescription,
    fmu: &Path,
    explicit: bool,
) -> Result<Resolved, ImportError> {
    let hint = if explicit {
        String::new()
    } else {
        "; an FMU not written by `oils export-fmu` needs a variable mapping: pass fmu:MAPPING.toml (docs/fmu.md)".to_string()
    };
    let find =
        |name: &str, role: String, input: bool, boolean_ok: bool| -> Result<Slot, ImportError> {
            let v = d
                .variable(name)
                .ok_or_else(|| ImportError::MissingVariable {
                    fmu: fmu.to_path_buf(),
                    name: name.to_string(),
                    role: role.clone(),
                    hint: hint.clone(),
                })?;
            let mistyped = |found: String, expected: &str| ImportError::MistypedVariable {
                fmu: fmu.to_path_buf(),
                name: name.to_string(),
                role: role.clone(),
                found,
                expected: expected.to_string(),
            };
            let real_name = VarType::Real.name(d.version);
            let expected_ty = if boolean_ok {
                format!("a Boolean or a {real_name}")
            } else {
                format!("a {real_name}")
            };
            let real = match &v.ty {
                VarType::Real => true,
                VarType::Boolean if boolean_ok => false,
                other => {
                    return Err(mistyped(
                        format!("of type {}", other.name(d.version)),
                        &expected_ty,
                    ))
                }
            };
            if v.array {
                return Err(mistyped("an array".into(), "a scalar"));
            }
            let ok = if input {
                v.causality == "input"
            } else {
                matches!(v.causality.as_str(), "output" | "local")
            };
            if !ok {
                return Err(mistyped(
                    format!("of causality {}", v.causality),
                    if input {
                        "causality input"
                    } else {
                        "causality output"
                    },
                ));
            }
            Ok(Slot { vr: v.vr, real })
        };
    let per_engine = |names: &[String], role: &str| -> Result<(), ImportError> {
        if names.len() != ENGINE_COUNT {
            return Err(ImportError::Mapping {
                path: fmu.to_path_buf(),
                why: format!(
                    "{role} lists {} variables, the bench has {ENGINE_COUNT} engines",
                    names.len()
                ),
            });
        }
        Ok(())
    };
    // Optional entries of the default mapping apply only where the FMU has them.
    let wanted = |name: &str| explicit || d.variable(name).is_some();
    per_engine(&m.inputs.thrust_cmd_n, "inputs.thrust_cmd_n")?;
    let mut cmd = [0; ENGINE_COUNT];
    for (e, n) in m.inputs.thrust_cmd_n.iter().enumerate() {
        cmd[e] = find(n, format!("inputs.thrust_cmd_n[{e}]"), true, false)?.vr;
    }
    let on = match &m.inputs.on {
        Some(names) if names.iter().all(|n| wanted(n)) => {
            per_engine(names, "inputs.on")?;
            let mut s = [Slot { vr: 0, real: true }; ENGINE_COUNT];
            for (e, n) in names.iter().enumerate() {
                s[e] = find(n, format!("inputs.on[{e}]"), true, true)?;
            }
            Some(s)
        }
        _ => None,
    };
    let o = &m.outputs;
    per_engine(&o.thrust_n, "outputs.thrust_n")?;
    let mut out_vrs = Vec::new();
    for (e, n) in o.thrust_n.iter().enumerate() {
        out_vrs.push(find(n, format!("outputs.thrust_n[{e}]"), false, false)?.vr);
    }
    for (n, role) in [
        (&o.gas_pressure_pa, "outputs.gas_pressure_pa"),
        (&o.ejected_fuel_kg, "outputs.ejected_fuel_kg"),
        (&o.ejected_ox_kg, "outputs.ejected_ox_kg"),
    ] {
        out_vrs.push(find(n, role.into(), false, false)?.vr);
    }
    let mut group =
        |names: &Option<Vec<String>>, role: &str| -> Result<Option<usize>, ImportError> {
            match names {
                Some(names) if names.iter().all(|n| wanted(n)) => {
                    per_engine(names, role)?;
                    let at = out_vrs.len();
                    for (e, n) in names.iter().enumerate() {
                        out_vrs.push(find(n, format!("{role}[{e}]"), false, false)?.vr);
                    }
                    Ok(Some(at))
                }
                _ => Ok(None),
            }
        };
    let mean = group(&o.mean_thrust_n, "outputs.mean_thrust_n")?;
    let chamber = group(&o.chamber_pressure_pa, "outputs.chamber_pressure_pa")?;
    let mut one = |name: &Option<String>, role: &str| -> Result<Option<usize>, ImportError> {
        match name {
            Some(n) if wanted(n) => {
                out_vrs.push(find(n, role.into(), false, false)?.vr);
                Ok(Some(out_vrs.len() - 1))
            }
            _ => Ok(None),
        }
    };
    let fuel_tank = one(&o.fuel_tank_pa, "outputs.fuel_tank_pa")?;
    let ox_tank = one(&o.ox_tank_pa, "outputs.ox_tank_pa")?;
    let fuel_flow = one(&o.fuel_flow_kg_s, "outputs.fuel_flow_kg_s")?;
    let ox_flow = one(&o.ox_flow_kg_s, "outputs.ox_flow_kg_s")?;
    Ok(Resolved {
        cmd,
        on,
        out_vrs,
        mean,
        chamber,
        fuel_tank,
        ox_tank,
        fuel_flow,
        ox_flow,
    })
}

/// The bench's propulsion model over one FMU instance. Each bench step sets the
/// commands, takes `dt / step` communication steps and reads the outputs (no
/// allocation). A call the FMU refuses, or a non-finite output, ends the model:
/// [`Propulsion::failure`] says so and [`FmuPropulsion::error`] has the FMU's words.
pub struct FmuPropulsion {
    inst: Instance,
    map: Arc<Resolved>,
    step_ns: u64,
    out: PropulsionOutput,
    values: Vec<f64>,
    cmd: [f64; ENGINE_COUNT],
    on_real: [f64; ENGINE_COUNT],
    on_bool: [bool; ENGINE_COUNT],
    on_real_vrs: Vec<u32>,
    on_bool_vrs: Vec<u32>,
    failure: Option<&'static str>,
    error: Option<String>,
    errors: Option<Arc<Mutex<Option<String>>>>,
}

impl FmuPropulsion {
    /// Instantiates `model`, to be stepped by whole multiples of `step_ns`.
    pub fn new(model: &FmuModel, step_ns: u64) -> Result<Self, ImportError> {
        let map = model.resolved.clone();
        let (mut on_real_vrs, mut on_bool_vrs) = (Vec::new(), Vec::new());
        for s in map.on.iter().flatten() {
            if s.real {
                on_real_vrs.push(s.vr);
            } else {
                on_bool_vrs.push(s.vr);
            }
        }
        let mut reals: Vec<u32> = map.cmd.to_vec();
        reals.extend(&on_real_vrs);
        let zeros = vec![0.0; reals.len()];
        let falses = vec![false; on_bool_vrs.len()];
        let err = |source| ImportError::Fmi {
            path: model.path.clone(),
            source,
        };
        let inst = Instance::new(
            model.fmu.clone(),
            "oils-propulsion",
            0.0,
            (&reals, &zeros),
            (&on_bool_vrs, &falses),
        )
        .map_err(err)?;
        let mut p = Self {
            inst,
            values: vec![0.0; map.out_vrs.len()],
            map,
            step_ns,
            out: PropulsionOutput::default(),
            cmd: [0.0; ENGINE_COUNT],
            on_real: [0.0; ENGINE_COUNT],
            on_bool: [false; ENGINE_COUNT],
            on_real_vrs,
            on_bool_vrs,
            failure: None,
            error: None,
            errors: None,
        };
        p.read().map_err(err)?;
        let first = p.out;
        p.out.mean_thrust_n = first.thrust_n;
        if let Some(why) = p.check_finite() {
            return Err(ImportError::Source(format!(
                "{}: the FMU's initial outputs: {why}",
                model.path.display()
            )));
        }
        Ok(p)
    }

    /// What the FMU said when it failed, if it did.
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// Reads every mapped output into `self.out` (mean thrust: as mapped, else left).
    fn read(&mut self) -> Result<(), FmiError> {
        self.inst.get_reals(&self.map.out_vrs, &mut self.values)?;
        let v = &self.values;
        let m = &self.map;
        let o = &mut self.out;
        o.thrust_n.copy_from_slice(&v[..ENGINE_COUNT]);
        o.gas_pressure_pa = v[ENGINE_COUNT];
        o.ejected_fuel_kg = v[ENGINE_COUNT + 1];
        o.ejected_ox_kg = v[ENGINE_COUNT + 2];
        if let Some(i) = m.chamber {
            o.chamber_pressure_pa
                .copy_from_slice(&v[i..i + ENGINE_COUNT]);
        }
        let get = |i: Option<usize>| i.map_or(0.0, |i| v[i]);
        o.fuel_tank_pressure_pa = get(m.fuel_tank);
        o.ox_tank_pressure_pa = get(m.ox_tank);
        o.fuel_flow_kg_s = get(m.fuel_flow);
        o.ox_flow_kg_s = get(m.ox_flow);
        Ok(())
    }

    fn check_finite(&self) -> Option<&'static str> {
        let o = &self.out;
        let all = o
            .thrust_n
            .iter()
            .chain(&o.mean_thrust_n)
            .chain(&o.chamber_pressure_pa)
            .chain([
                &o.gas_pressure_pa,
                &o.fuel_tank_pressure_pa,
                &o.ox_tank_pressure_pa,
                &o.ejected_fuel_kg,
                &o.ejected_ox_kg,
                &o.fuel_flow_kg_s,
                &o.ox_flow_kg_s,
            ]);
        let mut all = all;
        all.any(|x| !x.is_finite())
            .then_some("the FMU returned a non-finite output")
    }

    fn fail(&mut self, why: &'static str, e: Option<FmiError>) {
        self.failure = Some(why);
        let text = match e {
            Some(e) => format!("{why}: {e}"),
            None => why.to_string(),
        };
        let text = format!("at t = {} s: {text}", self.inst.time_s());
        match self.errors.as_ref().and_then(|s| s.lock().ok()).as_mut() {
            Some(slot) => {
                slot.get_or_insert(text.clone());
            }
            // In the loop: the run ends aborted with `failure()`; the FMU's own words go
            // to stderr, once (the only output of this model, at its end).
            None => eprintln!("oils: FMU propulsion model failed {text}"),
        }
        self.error = Some(text);
    }

    fn try_step(
        &mut self,
        cmd: &EngineCommand,
        dt_ns: u64,
    ) -> Result<(), (&'static str, Option<FmiError>)> {
        if dt_ns == 0 || !dt_ns.is_multiple_of(self.step_ns) {
            return Err((
                "the bench step is not a whole number of the FMU's steps",
                None,
            ));
        }
        for e in 0..ENGINE_COUNT {
            self.cmd[e] = if self.map.on.is_some() || cmd.on[e] {
                cmd.thrust_cmd_n[e]
            } else {
                0.0
            };
        }
        let mut set = self.inst.set_reals(&self.map.cmd, &self.cmd);
        if let Some(on) = &self.map.on {
            // The switches, real-valued ones and Boolean ones each in engine order.
            let (mut nr, mut nb) = (0, 0);
            for (e, s) in on.iter().enumerate() {
                if s.real {
                    self.on_real[nr] = if cmd.on[e] { 1.0 } else { 0.0 };
                    nr += 1;
                } else {
                    self.on_bool[nb] = cmd.on[e];
                    nb += 1;
                }
            }
            if nr > 0 {
                set =
                    set.and_then(|()| self.inst.set_reals(&self.on_real_vrs, &self.on_real[..nr]));
            }
            if nb > 0 {
                set =
                    set.and_then(|()| self.inst.set_bools(&self.on_bool_vrs, &self.on_bool[..nb]));
            }
        }
        set.map_err(|e| ("the FMU refused an input", Some(e)))?;
        let n = dt_ns / self.step_ns;
        let before = self.out;
        let mut mean_sum = [0.0; ENGINE_COUNT];
        for _ in 0..n {
            let start = self.out.thrust_n;
            self.inst
                .do_step(self.step_ns)
                .map_err(|e| ("the FMU's step failed", Some(e)))?;
            self.read()
                .map_err(|e| ("the FMU refused to give its outputs", Some(e)))?;
            for e in 0..ENGINE_COUNT {
                mean_sum[e] += match self.map.mean {
                    Some(i) => self.values[i + e],
                    None => 0.5 * (start[e] + self.out.thrust_n[e]),
                };
            }
        }
        for (mean, sum) in self.out.mean_thrust_n.iter_mut().zip(mean_sum) {
            *mean = sum / n as f64;
        }
        let dt_s = dt_ns as f64 / 1e9;
        if self.map.fuel_flow.is_none() {
            self.out.fuel_flow_kg_s = (self.out.ejected_fuel_kg - before.ejected_fuel_kg) / dt_s;
        }
        if self.map.ox_flow.is_none() {
            self.out.ox_flow_kg_s = (self.out.ejected_ox_kg - before.ejected_ox_kg) / dt_s;
        }
        if let Some(why) = self.check_finite() {
            return Err((why, None));
        }
        Ok(())
    }
}

impl Propulsion for FmuPropulsion {
    fn name(&self) -> &'static str {
        "fmu"
    }

    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        if self.failure.is_some() {
            return self.out;
        }
        let last = self.out;
        if let Err((why, e)) = self.try_step(cmd, dt_ns) {
            self.out = last;
            self.fail(why, e);
        }
        self.out
    }

    fn output(&self) -> PropulsionOutput {
        self.out
    }

    fn failure(&self) -> Option<&'static str> {
        self.failure
    }
}

/// Builds the FMU a run configuration names (`propulsion = "fmu"`,
/// `propulsion_fmu = PATH`), stepped at the plant step: the session's
/// `Extras::propulsion` in `oils run --propulsion fmu:PATH`.
pub fn build_for_run(cfg: &RunConfig) -> Result<Box<dyn Propulsion>, BuildError> {
    let Some(path) = &cfg.propulsion_fmu else {
        return Err(BuildError::External(
            "propulsion = \"fmu\" without propulsion_fmu = PATH".into(),
        ));
    };
    let err = |e: ImportError| BuildError::External(e.to_string());
    let model = FmuModel::load(&FmuSource {
        given: path.clone(),
    })
    .map_err(err)?;
    model
        .instantiate_reporting(cfg.dt_ns(), "the plant step", false)
        .map_err(err)
}

/// Stands in for an FMU instance that could not be made (see [`FmuModel::factory`]):
/// outputs zero, and fails at once.
pub struct Unavailable;

impl Propulsion for Unavailable {
    fn name(&self) -> &'static str {
        "fmu"
    }
    fn step(&mut self, _: &EngineCommand, _: u64) -> PropulsionOutput {
        PropulsionOutput::default()
    }
    fn output(&self) -> PropulsionOutput {
        PropulsionOutput::default()
    }
    fn failure(&self) -> Option<&'static str> {
        Some("the FMU could not be instantiated")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oils_fmu::{Causality, VARIABLES};

    #[test]
    fn the_default_mapping_names_what_export_fmu_declares() {
        // Every name of the default mapping is a variable of the packed binary, with the
        // causality its place needs, and every input and output of it is mapped.
        let m = Mapping::oils();
        let ins: Vec<&String> = m
            .inputs
            .thrust_cmd_n
            .iter()
            .chain(m.inputs.on.iter().flatten())
            .collect();
        let o = &m.outputs;
        let outs: Vec<&String> = o
            .thrust_n
            .iter()
            .chain([&o.gas_pressure_pa, &o.ejected_fuel_kg, &o.ejected_ox_kg])
            .chain(o.mean_thrust_n.iter().flatten())
            .chain(o.chamber_pressure_pa.iter().flatten())
            .chain(
                [
                    &o.fuel_tank_pa,
                    &o.ox_tank_pa,
                    &o.fuel_flow_kg_s,
                    &o.ox_flow_kg_s,
                ]
                .into_iter()
                .flatten(),
            )
            .collect();
        for (names, causality) in [(&ins, Causality::Input), (&outs, Causality::Output)] {
            let declared: Vec<&str> = VARIABLES
                .iter()
                .filter(|v| v.causality == causality)
                .map(|v| v.name)
                .collect();
            let mut mapped: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
            mapped.sort_unstable();
            let mut declared = declared;
            declared.sort_unstable();
            assert_eq!(mapped, declared, "{causality:?}");
        }
        // The mapping file form reads back.
        let text = toml::to_string(&m).unwrap();
        assert_eq!(Mapping::from_toml(&text).unwrap(), m);
        assert!(Mapping::from_toml("[inputs]\nthrust_cmd_n = []\nbogus = 1\n").is_err());
    }

    #[test]
    fn fmu_sources_need_a_path() {
        assert!(FmuSource::parse("hifi").is_none());
        assert!(matches!(FmuSource::parse("fmu:"), Some(Err(_))));
        assert_eq!(
            FmuSource::parse("fmu:a/b.fmu").unwrap().unwrap().given,
            PathBuf::from("a/b.fmu")
        );
    }
}
