//! What the importer reads of `modelDescription.xml`: the FMI version, the
//! co-simulation interface's model identifier, the token, the default step and every
//! scalar variable's name, value reference, type and causality.

use crate::FmiError;

/// FMI version of an FMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmiVersion {
    /// FMI 2.0.
    V2,
    /// FMI 3.0.
    V3,
}

impl FmiVersion {
    /// `2.0` or `3.0`.
    pub fn as_str(self) -> &'static str {
        match self {
            FmiVersion::V2 => "2.0",
            FmiVersion::V3 => "3.0",
        }
    }

    /// The folder under `binaries/` for this machine, as the standard names it.
    pub fn platform(self) -> Option<&'static str> {
        match (self, std::env::consts::OS, std::env::consts::ARCH) {
            (FmiVersion::V2, "linux", "x86_64") => Some("linux64"),
            (FmiVersion::V2, "linux", "x86") => Some("linux32"),
            (FmiVersion::V3, "linux", "x86_64") => Some("x86_64-linux"),
            (_, "linux", "aarch64") => Some("aarch64-linux"),
            (FmiVersion::V2, "macos", _) => Some("darwin64"),
            (FmiVersion::V3, "macos", "x86_64") => Some("x86_64-darwin"),
            (FmiVersion::V3, "macos", "aarch64") => Some("aarch64-darwin"),
            (FmiVersion::V2, "windows", "x86_64") => Some("win64"),
            (FmiVersion::V3, "windows", "x86_64") => Some("x86_64-windows"),
            _ => None,
        }
    }
}

/// A variable's type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VarType {
    /// `Real` (2.0) or `Float64` (3.0).
    Real,
    /// `Boolean`.
    Boolean,
    /// Any other type, by its element name (`Integer`, `Int32`, `String`, `Float32`...).
    Other(String),
}

impl VarType {
    /// How the model description writes it.
    pub fn name(&self, version: FmiVersion) -> &str {
        match (self, version) {
            (VarType::Real, FmiVersion::V2) => "Real",
            (VarType::Real, FmiVersion::V3) => "Float64",
            (VarType::Boolean, _) => "Boolean",
            (VarType::Other(s), _) => s,
        }
    }
}

/// One scalar variable.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    /// Name.
    pub name: String,
    /// Value reference.
    pub vr: u32,
    /// Type.
    pub ty: VarType,
    /// Causality (`input`, `output`, `parameter`, `local`, `independent`...;
    /// `local` when not given, as the standard defaults it).
    pub causality: String,
    /// Unit, if declared.
    pub unit: Option<String>,
    /// An array (FMI 3.0 `<Dimension>`): not importable as a scalar.
    pub array: bool,
}

/// The parts of a model description the importer uses.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelDescription {
    /// FMI version.
    pub version: FmiVersion,
    /// `modelName`.
    pub model_name: String,
    /// GUID (2.0) or instantiation token (3.0).
    pub token: String,
    /// `generationTool`, if given.
    pub generation_tool: Option<String>,
    /// The co-simulation interface's `modelIdentifier` (the binary's file name).
    pub model_identifier: String,
    /// `canHandleVariableCommunicationStepSize`.
    pub variable_step: bool,
    /// `canBeInstantiatedOnlyOncePerProcess`.
    pub only_once_per_process: bool,
    /// FMI 3.0 `fixedInternalStepSize`, seconds.
    pub fixed_internal_step_s: Option<f64>,
    /// `DefaultExperiment stepSize`, seconds.
    pub default_step_s: Option<f64>,
    /// The scalar variables, in document order.
    pub variables: Vec<Variable>,
}

fn flag(node: roxmltree::Node, name: &str) -> bool {
    node.attribute(name) == Some("true")
}

fn seconds(node: Option<roxmltree::Node>, name: &str) -> Result<Option<f64>, FmiError> {
    let Some(v) = node.and_then(|n| n.attribute(name)) else {
        return Ok(None);
    };
    match v.trim().parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 => Ok(Some(s)),
        _ => Err(FmiError::Description(format!(
            "{name}=\"{v}\" is not a positive number of seconds"
        ))),
    }
}

impl ModelDescription {
    /// Parses the XML text.
    pub fn parse(xml: &str) -> Result<Self, FmiError> {
        let doc = roxmltree::Document::parse(xml)
            .map_err(|e| FmiError::Description(format!("not XML: {e}")))?;
        let root = doc.root_element();
        if !root.has_tag_name("fmiModelDescription") {
            return Err(FmiError::Description(format!(
                "the root element is <{}>, not <fmiModelDescription>",
                root.tag_name().name()
            )));
        }
        let version_attr = root.attribute("fmiVersion").unwrap_or("");
        let version = if version_attr == "2.0" {
            FmiVersion::V2
        } else if version_attr.starts_with("3.") {
            FmiVersion::V3
        } else {
            return Err(FmiError::Version(version_attr.to_string()));
        };
        let token_attr = match version {
            FmiVersion::V2 => "guid",
            FmiVersion::V3 => "instantiationToken",
        };
        let token = root
            .attribute(token_attr)
            .ok_or_else(|| FmiError::Description(format!("no {token_attr} attribute")))?
            .to_string();
        let cs = root
            .children()
            .find(|n| n.has_tag_name("CoSimulation"))
            .ok_or(FmiError::NotCoSimulation)?;
        let model_identifier = cs
            .attribute("modelIdentifier")
            .filter(|s| !s.is_empty() && !s.contains(['/', '\\']))
            .ok_or_else(|| {
                FmiError::Description("<CoSimulation> has no usable modelIdentifier".into())
            })?
            .to_string();
        let experiment = root
            .children()
            .find(|n| n.has_tag_name("DefaultExperiment"));
        let mv = root
            .children()
            .find(|n| n.has_tag_name("ModelVariables"))
            .ok_or_else(|| FmiError::Description("no <ModelVariables>".into()))?;
        let mut variables = Vec::new();
        for n in mv.children().filter(|n| n.is_element()) {
            let (ty_node, ty) = match version {
                FmiVersion::V2 => {
                    if !n.has_tag_name("ScalarVariable") {
                        continue;
                    }
                    let Some(t) = n.children().find(|c| c.is_element()) else {
                        return Err(FmiError::Description(format!(
                            "variable {} has no type element",
                            n.attribute("name").unwrap_or("?")
                        )));
                    };
                    let ty = match t.tag_name().name() {
                        "Real" => VarType::Real,
                        "Boolean" => VarType::Boolean,
                        other => VarType::Other(other.to_string()),
                    };
                    (t, ty)
                }
                FmiVersion::V3 => {
                    let ty = match n.tag_name().name() {
                        "Float64" => VarType::Real,
                        "Boolean" => VarType::Boolean,
                        other => VarType::Other(other.to_string()),
                    };
                    (n, ty)
                }
            };
            let name = n
                .attribute("name")
                .ok_or_else(|| FmiError::Description("a variable without a name".into()))?;
            let vr = n
                .attribute("valueReference")
                .and_then(|v| v.trim().parse::<u32>().ok())
                .ok_or_else(|| {
                    FmiError::Description(format!("variable {name}: no valid valueReference"))
                })?;
            variables.push(Variable {
                name: name.to_string(),
                vr,
                ty,
                causality: n.attribute("causality").unwrap_or("local").to_string(),
                unit: ty_node.attribute("unit").map(str::to_string),
                array: n.children().any(|c| c.has_tag_name("Dimension")),
            });
        }
        Ok(Self {
            version,
            model_name: root.attribute("modelName").unwrap_or("").to_string(),
            token,
            generation_tool: root.attribute("generationTool").map(str::to_string),
            model_identifier,
            variable_step: flag(cs, "canHandleVariableCommunicationStepSize"),
            only_once_per_process: flag(cs, "canBeInstantiatedOnlyOncePerProcess"),
            fixed_internal_step_s: seconds(Some(cs), "fixedInternalStepSize")?,
            default_step_s: seconds(experiment, "stepSize")?,
            variables,
        })
    }

    /// The variable named `name`.
    pub fn variable(&self, name: &str) -> Option<&Variable> {
        self.variables.iter().find(|v| v.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V2: &str = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{g}">
  <CoSimulation modelIdentifier="m" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment stepSize="0.01"/>
  <ModelVariables>
    <ScalarVariable name="u" valueReference="1" causality="input"><Real start="0" unit="N"/></ScalarVariable>
    <ScalarVariable name="b" valueReference="2" causality="input"><Boolean/></ScalarVariable>
    <ScalarVariable name="i" valueReference="3" causality="output"><Integer/></ScalarVariable>
  </ModelVariables>
</fmiModelDescription>"#;

    #[test]
    fn fmi2_variables_types_and_steps_are_read() {
        let d = ModelDescription::parse(V2).unwrap();
        assert_eq!(d.version, FmiVersion::V2);
        assert_eq!(d.token, "{g}");
        assert_eq!(d.default_step_s, Some(0.01));
        assert!(d.variable_step);
        let u = d.variable("u").unwrap();
        assert_eq!(
            (u.vr, &u.ty, u.causality.as_str()),
            (1, &VarType::Real, "input")
        );
        assert_eq!(u.unit.as_deref(), Some("N"));
        assert_eq!(d.variable("b").unwrap().ty, VarType::Boolean);
        assert_eq!(
            d.variable("i").unwrap().ty,
            VarType::Other("Integer".into())
        );
    }

    #[test]
    fn fmi3_and_bad_descriptions() {
        let v3 = r#"<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="t">
  <CoSimulation modelIdentifier="x" fixedInternalStepSize="0.005"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent"/>
    <Float64 name="y" valueReference="9" causality="output"><Dimension start="2"/></Float64>
    <Int32 name="k" valueReference="4" causality="input"/>
  </ModelVariables>
</fmiModelDescription>"#;
        let d = ModelDescription::parse(v3).unwrap();
        assert_eq!(d.version, FmiVersion::V3);
        assert_eq!(d.fixed_internal_step_s, Some(0.005));
        assert!(d.variable("y").unwrap().array);
        assert_eq!(d.variable("k").unwrap().ty.name(d.version), "Int32");
        let me = v3.replace("<CoSimulation", "<ModelExchange");
        assert!(matches!(
            ModelDescription::parse(&me),
            Err(FmiError::NotCoSimulation)
        ));
        let v1 = V2.replace("fmiVersion=\"2.0\"", "fmiVersion=\"1.0\"");
        assert!(matches!(ModelDescription::parse(&v1), Err(FmiError::Version(v)) if v == "1.0"));
        let bad_step = V2.replace("stepSize=\"0.01\"", "stepSize=\"-1\"");
        let e = ModelDescription::parse(&bad_step).unwrap_err().to_string();
        assert!(e.contains("stepSize"), "{e}");
        assert!(ModelDescription::parse("<x").is_err());
    }
}
