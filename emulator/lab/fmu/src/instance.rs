//! What one FMU instance is, in safe Rust: the bench's propulsion model built from the
//! FMU's resources, the held command, the time, and the outputs of the latest step. The
//! C entry points only convert arguments and call these methods.

use crate::variables::{self, VarType, VARIABLES, VR_CMD, VR_ON};
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::{
    self, EngineCommand, Propulsion, PropulsionKind, PropulsionOutput, PropulsionSpec,
};
use oils_shared::ENGINE_COUNT;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The resource file naming the packed model (in the FMU's `resources/`).
pub const RESOURCE_FILE: &str = "oils-propulsion.json";
/// Value of [`Resource::format`].
pub const RESOURCE_FORMAT: &str = "oils-fmu-propulsion";
/// Version of the resource file this binary reads.
pub const RESOURCE_VERSION: u32 = 1;

/// The packed model, as `resources/oils-propulsion.json` holds it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Resource {
    /// Always [`RESOURCE_FORMAT`].
    pub format: String,
    /// [`RESOURCE_VERSION`].
    pub version: u32,
    /// The model description's instantiation token (FMI 3.0) or GUID (FMI 2.0); an
    /// instantiation with another one is refused.
    pub token: String,
    /// `surrogate` or `hifi`.
    pub kind: PropulsionKind,
    /// The engines.
    pub engines: PropulsionConfig,
    /// hifi's parameters (`hifi`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hifi: Option<HifiParams>,
    /// The surrogate's model file, a name in `resources/` (`surrogate`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surrogate_model: Option<String>,
    /// The model's step, nanoseconds: a communication step must be a whole multiple.
    pub step_ns: u64,
}

impl Resource {
    /// Reads and checks `resources/oils-propulsion.json` in `dir`.
    pub fn load(dir: &Path) -> Result<Self, String> {
        let path = dir.join(RESOURCE_FILE);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let r: Self = serde_json::from_str(&text)
            .map_err(|e| format!("{} is malformed: {e}", path.display()))?;
        if r.format != RESOURCE_FORMAT || r.version != RESOURCE_VERSION {
            return Err(format!(
                "{} is format {} version {}, this binary reads {RESOURCE_FORMAT} version {RESOURCE_VERSION}",
                path.display(),
                r.format,
                r.version
            ));
        }
        if r.step_ns == 0 {
            return Err("step_ns is 0".into());
        }
        Ok(r)
    }

    /// The model it names, with its files in `dir`.
    pub fn spec(&self, dir: &Path) -> PropulsionSpec {
        PropulsionSpec {
            surrogate_model: self.surrogate_model.as_ref().map(|f| dir.join(f)),
            hifi: self.hifi.clone().unwrap_or_default(),
            step_ns: Some(self.step_ns),
            ..PropulsionSpec::new(self.kind, &self.engines)
        }
    }
}

/// One instance.
pub struct Instance {
    model: Box<dyn Propulsion>,
    step_ns: u64,
    max_thrust_n: f64,
    cmd: EngineCommand,
    out: PropulsionOutput,
    start_s: f64,
    /// Time since the start, nanoseconds (integer: no drift over a long run).
    elapsed_ns: u64,
}

impl Instance {
    /// Builds the model the resources in `dir` name; `token` must be theirs.
    pub fn new(dir: &Path, token: &str) -> Result<Self, String> {
        let r = Resource::load(dir)?;
        if r.token != token {
            return Err(format!(
                "instantiation token {token} is not this FMU's ({})",
                r.token
            ));
        }
        let model = propulsion::build(&r.spec(dir)).map_err(|e| error_chain(&e))?;
        let out = model.output();
        Ok(Self {
            model,
            step_ns: r.step_ns,
            max_thrust_n: r.engines.max_thrust_n,
            cmd: EngineCommand::default(),
            out,
            start_s: 0.0,
            elapsed_ns: 0,
        })
    }

    /// Sets the start time (initialization).
    pub fn set_start(&mut self, start_s: f64) {
        self.start_s = if start_s.is_finite() { start_s } else { 0.0 };
    }

    /// Sets a `Float64` input: a thrust command, finite, clamped into `[0, rating]` as
    /// the bench's link does.
    pub fn set_float(&mut self, vr: u32, value: f64) -> Result<(), String> {
        let e = vr.wrapping_sub(VR_CMD) as usize;
        if e >= ENGINE_COUNT {
            return Err(format!("value reference {vr} is not a Float64 input"));
        }
        if !value.is_finite() {
            return Err(format!(
                "{} = {value}: not finite",
                VARIABLES[vr as usize].name
            ));
        }
        self.cmd.thrust_cmd_n[e] = value.clamp(0.0, self.max_thrust_n);
        Ok(())
    }

    /// Sets a `Boolean` input (an engine's switch).
    pub fn set_bool(&mut self, vr: u32, value: bool) -> Result<(), String> {
        let e = vr.wrapping_sub(VR_ON) as usize;
        if e >= ENGINE_COUNT {
            return Err(format!("value reference {vr} is not a Boolean input"));
        }
        self.cmd.on[e] = value;
        Ok(())
    }

    /// A `Float64` variable's value.
    pub fn float(&self, vr: u32) -> Result<f64, String> {
        variables::float_value(vr, &self.out, &self.cmd, self.time_s())
            .ok_or_else(|| format!("value reference {vr} is not a Float64 variable"))
    }

    /// A `Boolean` variable's value.
    pub fn bool(&self, vr: u32) -> Result<bool, String> {
        let e = vr.wrapping_sub(VR_ON) as usize;
        match VARIABLES.get(vr as usize) {
            Some(v) if v.ty == VarType::Boolean && e < ENGINE_COUNT => Ok(self.cmd.on[e]),
            _ => Err(format!("value reference {vr} is not a Boolean variable")),
        }
    }

    /// Current time, seconds.
    pub fn time_s(&self) -> f64 {
        self.start_s + self.elapsed_ns as f64 / 1e9
    }

    /// One communication step of `h_s` with the held command: a whole number of the
    /// model's steps, taken as one step of the bench (the same call the plant makes).
    pub fn do_step(&mut self, h_s: f64) -> Result<(), String> {
        let h_ns = (h_s * 1e9).round();
        let step_s = self.step_ns as f64 / 1e9;
        if !(1.0..1e15).contains(&h_ns) || !(h_ns as u64).is_multiple_of(self.step_ns) {
            return Err(format!(
                "communication step {h_s} s is not a whole multiple of the model's step {step_s} s"
            ));
        }
        self.out = self.model.step(&self.cmd, h_ns as u64);
        self.elapsed_ns += h_ns as u64;
        if let Some(why) = self.model.failure() {
            return Err(format!("the {} model failed: {why}", self.model.name()));
        }
        Ok(())
    }
}

fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(c) = source {
        s.push_str(": ");
        s.push_str(&c.to_string());
        source = c.source();
    }
    s
}
