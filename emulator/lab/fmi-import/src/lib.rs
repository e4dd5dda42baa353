//! A small importer of FMI 2.0 and 3.0 co-simulation FMUs: [`Fmu::open`] unzips the
//! archive into a private folder, reads `modelDescription.xml`
//! ([`description::ModelDescription`]) and loads `binaries/<platform>/<id>.so` with
//! `libloading`; [`Instance`] calls its C API (instantiate, set up / enter
//! initialization, exit initialization, set real and Boolean inputs, do step, get real
//! outputs, terminate, free) with the typed errors of [`FmiError`].
//!
//! Why hand-written and not the `fmi` crate: `fmi` generates its bindings with bindgen,
//! which needs libclang at build time (not on the bench's build machines, nor in its
//! CI). The handful of functions a co-simulation master calls are declared here from the
//! standard's headers (`fmi2Functions.h`, `fmi3Functions.h`) instead; libloading is
//! maintained and has no build-time dependency.
//!
//! This crate holds the unsafe code of the import; the lab's `fmu::import` (the variable
//! mapping and the bench's `Propulsion` over an FMU) is safe Rust on top of it.
#![warn(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]

pub mod description;
mod ffi;
mod instance;

pub use description::{FmiVersion, ModelDescription, VarType, Variable};
pub use instance::Instance;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// An FMU could not be opened or called.
#[derive(Debug, thiserror::Error)]
pub enum FmiError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The archive is not a readable ZIP file or has an unsafe entry.
    #[error("{path}: not a readable FMU archive: {why}")]
    Archive {
        /// The FMU.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// The model description is missing or malformed.
    #[error("modelDescription.xml: {0}")]
    Description(String),
    /// An FMI version this importer does not read.
    #[error("modelDescription.xml: fmiVersion \"{0}\" is not supported (FMI 2.0 and 3.0 are)")]
    Version(String),
    /// The FMU offers no co-simulation interface.
    #[error("modelDescription.xml: the FMU has no <CoSimulation> interface (only co-simulation FMUs can be imported; Model Exchange needs a solver the bench does not have)")]
    NotCoSimulation,
    /// No binary for this machine in the archive.
    #[error("the FMU has no binary for this machine: {expected} is not in the archive{}", if .found.is_empty() { String::new() } else { format!(" (it has {})", .found.join(", ")) })]
    NoBinary {
        /// The path looked for.
        expected: String,
        /// The binaries it has.
        found: Vec<String>,
    },
    /// The binary could not be loaded.
    #[error("loading {path}: {source}")]
    Load {
        /// The binary.
        path: PathBuf,
        /// The loader's error.
        source: libloading::Error,
    },
    /// The binary lacks a function the importer calls.
    #[error("the FMU binary has no function {name}: {source}")]
    Symbol {
        /// The C function.
        name: &'static str,
        /// The loader's error.
        source: libloading::Error,
    },
    /// Instantiation returned null.
    #[error("{function} failed{}", log_suffix(.log))]
    Instantiate {
        /// The C function.
        function: &'static str,
        /// What the FMU logged.
        log: Vec<String>,
    },
    /// A call answered a status other than OK (or warning).
    #[error("{function} returned {status}{}", log_suffix(.log))]
    Call {
        /// The C function.
        function: &'static str,
        /// The status, named.
        status: &'static str,
        /// What the FMU logged.
        log: Vec<String>,
    },
}

fn log_suffix(log: &[String]) -> String {
    if log.is_empty() {
        String::new()
    } else {
        format!(": {}", log.join("; "))
    }
}

/// An FMU opened for import: its description, its unpacked folder (removed on drop)
/// and its loaded binary. Instances ([`Instance::new`]) share it.
pub struct Fmu {
    description: ModelDescription,
    dir: TempDir,
    binary: ffi::Binary,
}

impl std::fmt::Debug for Fmu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fmu")
            .field("model", &self.description.model_name)
            .field("fmi", &self.description.version.as_str())
            .field("dir", &self.dir.0)
            .finish()
    }
}

impl Fmu {
    /// Unzips `path`, reads its model description and loads its binary for this
    /// machine.
    pub fn open(path: &Path) -> Result<Self, FmiError> {
        let file = std::fs::File::open(path).map_err(|source| FmiError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let archive_err = |why: String| FmiError::Archive {
            path: path.to_path_buf(),
            why,
        };
        let mut zip = zip::ZipArchive::new(file).map_err(|e| archive_err(e.to_string()))?;
        let dir = TempDir::new()?;
        for i in 0..zip.len() {
            let mut entry = zip.by_index(i).map_err(|e| archive_err(e.to_string()))?;
            let Some(rel) = entry.enclosed_name() else {
                return Err(archive_err(format!(
                    "entry {} leaves the archive's folder",
                    entry.name()
                )));
            };
            let target = dir.0.join(rel);
            let io = |source| FmiError::Io {
                path: target.clone(),
                source,
            };
            if entry.is_dir() {
                std::fs::create_dir_all(&target).map_err(io)?;
                continue;
            }
            if let Some(parent) = target.parent() {
                std::fs::create_dir_all(parent).map_err(io)?;
            }
            let mut bytes = Vec::new();
            entry
                .read_to_end(&mut bytes)
                .map_err(|e| archive_err(format!("{}: {e}", entry.name())))?;
            std::fs::write(&target, bytes).map_err(io)?;
        }
        let md_path = dir.0.join("modelDescription.xml");
        let xml = std::fs::read_to_string(&md_path).map_err(|source| FmiError::Io {
            path: md_path.clone(),
            source,
        })?;
        let description = ModelDescription::parse(&xml)?;
        std::fs::create_dir_all(dir.0.join("resources")).map_err(|source| FmiError::Io {
            path: dir.0.join("resources"),
            source,
        })?;
        let platform = description.version.platform().unwrap_or("unknown-platform");
        let rel = format!(
            "binaries/{platform}/{}{}",
            description.model_identifier,
            std::env::consts::DLL_SUFFIX
        );
        let lib = dir.0.join(&rel);
        if !lib.is_file() {
            let found = (0..zip.len())
                .filter_map(|i| zip.name_for_index(i).map(str::to_string))
                .filter(|n| n.starts_with("binaries/") && !n.ends_with('/'))
                .collect();
            return Err(FmiError::NoBinary {
                expected: rel,
                found,
            });
        }
        let binary = ffi::Binary::load(&lib, description.version)?;
        Ok(Self {
            description,
            dir,
            binary,
        })
    }

    /// The model description.
    pub fn description(&self) -> &ModelDescription {
        &self.description
    }

    /// The unpacked `resources/` folder.
    pub fn resources(&self) -> PathBuf {
        self.dir.0.join("resources")
    }
}

/// A private folder under the system's temporary directory, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new() -> Result<Self, FmiError> {
        static COUNT: AtomicU64 = AtomicU64::new(0);
        let n = COUNT.fetch_add(1, Ordering::Relaxed);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let dir =
            std::env::temp_dir().join(format!("oils-fmu-{}-{n}-{nanos:08x}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|source| FmiError::Io {
            path: dir.clone(),
            source,
        })?;
        Ok(Self(dir))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A `file:` URI of an absolute path (FMI 2.0's resource location), percent-encoded.
pub fn file_uri(path: &Path) -> String {
    let mut s = String::from("file://");
    for b in path.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-_.~".contains(&b) {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uris_encode_what_is_not_plain() {
        assert_eq!(file_uri(Path::new("/tmp/a b/r%")), "file:///tmp/a%20b/r%25");
    }

    #[test]
    fn a_file_that_is_not_an_archive_is_refused_by_name() {
        let p = std::env::temp_dir().join(format!("oils-fmi-test-{}.fmu", std::process::id()));
        std::fs::write(&p, b"not a zip").unwrap();
        let e = Fmu::open(&p).unwrap_err();
        let _ = std::fs::remove_file(&p);
        assert!(matches!(e, FmiError::Archive { .. }), "{e}");
        assert!(e.to_string().contains("not a readable FMU archive"), "{e}");
        let e = Fmu::open(Path::new("/nonexistent/x.fmu")).unwrap_err();
        assert!(matches!(e, FmiError::Io { .. }), "{e}");
    }
}
