//! The model description (`modelDescription.xml`) of a packed bench model, for FMI 2.0
//! or 3.0 co-simulation, written from the binary's own variable table
//! ([`oils_fmu::VARIABLES`]).

use oils_fmu::variables::UNITS;
use oils_fmu::{Causality, VarType, VARIABLES};
use std::fmt::Write as _;

/// Which FMI version to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmiVersion {
    /// FMI 2.0.
    V2,
    /// FMI 3.0.
    V3,
}

impl FmiVersion {
    /// The binaries folder for this machine (`binaries/<platform>/`), or `None` where
    /// the standard names none this packer supports (Linux on x86-64 or AArch64).
    pub fn platform(self) -> Option<&'static str> {
        if std::env::consts::OS != "linux" {
            return None;
        }
        match (self, std::env::consts::ARCH) {
            (FmiVersion::V2, "x86_64") => Some("linux64"),
            (FmiVersion::V3, "x86_64") => Some("x86_64-linux"),
            (_, "aarch64") => Some("aarch64-linux"),
            _ => None,
        }
    }
}

/// What the description says about the packed model.
#[derive(Debug, Clone, PartialEq)]
pub struct Description {
    /// `modelName`.
    pub model_name: String,
    /// One paragraph.
    pub description: String,
    /// Instantiation token (3.0) / GUID (2.0).
    pub token: String,
    /// The model's step, seconds (the default experiment's step, and the fixed step).
    pub step_s: f64,
    /// `generationTool`.
    pub tool: String,
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The XML text. The commands are declared `discrete`: the model samples them at each
/// communication point and holds them over the step, as the bench holds a command over
/// its step (an importer then hands them over as given, not interpolated).
pub fn model_description(version: FmiVersion, d: &Description) -> String {
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let head = |x: &mut String, version_attr: &str, token_attr: &str| {
        let _ = writeln!(
            x,
            "<fmiModelDescription fmiVersion=\"{version_attr}\" modelName=\"{}\" {token_attr}=\"{}\" description=\"{}\" generationTool=\"{}\" variableNamingConvention=\"flat\">",
            escape(&d.model_name),
            escape(&d.token),
            escape(&d.description),
            escape(&d.tool)
        );
    };
    let units = |x: &mut String| {
        x.push_str("  <UnitDefinitions>\n");
        for (name, [kg, m, s]) in UNITS {
            let mut base = String::new();
            for (sym, e) in [("kg", kg), ("m", m), ("s", s)] {
                if e != 0 {
                    let _ = write!(base, " {sym}=\"{e}\"");
                }
            }
            let _ = writeln!(
                x,
                "    <Unit name=\"{}\"><BaseUnit{base}/></Unit>",
                escape(name)
            );
        }
        x.push_str("  </UnitDefinitions>\n");
    };
    let step = d.step_s;
    match version {
        FmiVersion::V3 => {
            head(&mut x, "3.0", "instantiationToken");
            let _ = writeln!(
                x,
                "  <CoSimulation modelIdentifier=\"{}\" canHandleVariableCommunicationStepSize=\"true\" fixedInternalStepSize=\"{step}\" canReturnEarlyAfterIntermediateUpdate=\"false\" hasEventMode=\"false\" providesIntermediateUpdate=\"false\"/>",
                oils_fmu::MODEL_IDENTIFIER
            );
            units(&mut x);
            let _ = writeln!(
                x,
                "  <DefaultExperiment startTime=\"0\" stepSize=\"{step}\"/>"
            );
            x.push_str("  <ModelVariables>\n");
            for v in &VARIABLES {
                let unit = v
                    .unit
                    .map_or_else(String::new, |u| format!(" unit=\"{}\"", escape(u)));
                let (tag, variability, start) = match (v.ty, v.causality) {
                    (VarType::Float64, Causality::Input) => ("Float64", "discrete", " start=\"0\""),
                    (VarType::Boolean, Causality::Input) => {
                        ("Boolean", "discrete", " start=\"false\"")
                    }
                    (VarType::Float64, _) => ("Float64", "continuous", ""),
                    (VarType::Boolean, _) => ("Boolean", "discrete", ""),
                };
                let (causality, initial) = match v.causality {
                    Causality::Independent => ("independent", ""),
                    Causality::Input => ("input", ""),
                    Causality::Output => ("output", " initial=\"calculated\""),
                };
                let unit = if v.ty == VarType::Float64 {
                    unit
                } else {
                    String::new()
                };
                let _ = writeln!(
                    x,
                    "    <{tag} name=\"{}\" valueReference=\"{}\" description=\"{}\" causality=\"{causality}\" variability=\"{variability}\"{initial}{start}{unit}/>",
                    escape(v.name),
                    v.vr,
                    escape(v.description)
                );
            }
            x.push_str("  </ModelVariables>\n  <ModelStructure>\n");
            let outputs = VARIABLES
                .iter()
                .filter(|v| v.causality == Causality::Output);
            for v in outputs.clone() {
                let _ = writeln!(
                    x,
                    "    <Output valueReference=\"{}\" dependencies=\"\"/>",
                    v.vr
                );
            }
            for v in outputs {
                let _ = writeln!(
                    x,
                    "    <InitialUnknown valueReference=\"{}\" dependencies=\"\"/>",
                    v.vr
                );
            }
            x.push_str("  </ModelStructure>\n");
        }
        FmiVersion::V2 => {
            head(&mut x, "2.0", "guid");
            let _ = writeln!(
                x,
                "  <CoSimulation modelIdentifier=\"{}\" canHandleVariableCommunicationStepSize=\"true\" canNotUseMemoryManagementFunctions=\"true\"/>",
                oils_fmu::MODEL_IDENTIFIER
            );
            units(&mut x);
            let _ = writeln!(
                x,
                "  <DefaultExperiment startTime=\"0\" stepSize=\"{step}\"/>"
            );
            x.push_str("  <ModelVariables>\n");
            // FMI 2.0 has no independent variable to declare: time is the importer's.
            let listed: Vec<_> = VARIABLES
                .iter()
                .filter(|v| v.causality != Causality::Independent)
                .collect();
            for v in &listed {
                let (causality, variability, initial) = match (v.causality, v.ty) {
                    (Causality::Input, VarType::Float64) => ("input", "discrete", ""),
                    (Causality::Input, VarType::Boolean) => ("input", "discrete", ""),
                    (_, VarType::Float64) => ("output", "continuous", " initial=\"calculated\""),
                    (_, VarType::Boolean) => ("output", "discrete", " initial=\"calculated\""),
                };
                let inner = match (v.ty, v.causality) {
                    (VarType::Float64, Causality::Input) => format!(
                        "<Real start=\"0\"{}/>",
                        v.unit
                            .map_or_else(String::new, |u| format!(" unit=\"{}\"", escape(u)))
                    ),
                    (VarType::Float64, _) => format!(
                        "<Real{}/>",
                        v.unit
                            .map_or_else(String::new, |u| format!(" unit=\"{}\"", escape(u)))
                    ),
                    (VarType::Boolean, Causality::Input) => "<Boolean start=\"false\"/>".into(),
                    (VarType::Boolean, _) => "<Boolean/>".into(),
                };
                let _ = writeln!(
                    x,
                    "    <ScalarVariable name=\"{}\" valueReference=\"{}\" description=\"{}\" causality=\"{causality}\" variability=\"{variability}\"{initial}>{inner}</ScalarVariable>",
                    escape(v.name),
                    v.vr,
                    escape(v.description)
                );
            }
            x.push_str("  </ModelVariables>\n  <ModelStructure>\n    <Outputs>\n");
            let index: Vec<usize> = listed
                .iter()
                .enumerate()
                .filter(|(_, v)| v.causality == Causality::Output)
                .map(|(i, _)| i + 1)
                .collect();
            for i in &index {
                let _ = writeln!(x, "      <Unknown index=\"{i}\" dependencies=\"\"/>");
            }
            x.push_str("    </Outputs>\n    <InitialUnknowns>\n");
            for i in &index {
                let _ = writeln!(x, "      <Unknown index=\"{i}\" dependencies=\"\"/>");
            }
            x.push_str("    </InitialUnknowns>\n  </ModelStructure>\n");
        }
    }
    x.push_str("</fmiModelDescription>\n");
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn describe(v: FmiVersion) -> String {
        model_description(
            v,
            &Description {
                model_name: "m <&>".into(),
                description: "d \"q\"".into(),
                token: "{t}".into(),
                step_s: 0.01,
                tool: "oils".into(),
            },
        )
    }

    #[test]
    fn both_versions_declare_every_variable_and_output_once() {
        for (v, tag_of) in [(FmiVersion::V3, "Output"), (FmiVersion::V2, "Unknown")] {
            let xml = describe(v);
            let doc = roxmltree::Document::parse(&xml).unwrap();
            let root = doc.root_element();
            assert_eq!(root.attribute("modelName"), Some("m <&>"));
            let names: Vec<&str> = doc
                .descendants()
                .filter_map(|n| {
                    n.attribute("name").filter(|_| {
                        n.has_tag_name("Float64")
                            || n.has_tag_name("Boolean")
                            || n.has_tag_name("ScalarVariable")
                    })
                })
                .collect();
            let expected: Vec<&str> = VARIABLES
                .iter()
                .filter(|x| v == FmiVersion::V3 || x.causality != Causality::Independent)
                .map(|x| x.name)
                .collect();
            assert_eq!(names, expected);
            let outputs = VARIABLES
                .iter()
                .filter(|x| x.causality == Causality::Output)
                .count();
            let listed = doc.descendants().filter(|n| n.has_tag_name(tag_of)).count();
            // FMI 3.0: Output + InitialUnknown elements; FMI 2.0: Unknown in both lists.
            assert_eq!(
                listed,
                if v == FmiVersion::V3 {
                    outputs
                } else {
                    2 * outputs
                }
            );
        }
    }
}
