//! The user's propulsion model through the Functional Mock-up Interface (FMI 2.0 and
//! 3.0 co-simulation): bench models packed as FMUs ([`export`]) and the user's FMU as
//! the truth in training, validation and the loop ([`import`]). The FMU's C interface is
//! in its own crates (`oils-fmu` exports it, `oils-fmi` calls it); nothing here is
//! unsafe. See `docs/fmu.md`.

pub mod describe;
pub mod export;
pub mod import;

/// An FMU could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum FmuError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The ZIP archive could not be written or read.
    #[error("FMU archive: {0}")]
    Zip(String),
    /// No FMU platform name for this machine.
    #[error("no FMU binary platform for {os}/{arch} (supported: Linux on x86-64 and AArch64)")]
    Platform {
        /// OS.
        os: &'static str,
        /// Architecture.
        arch: &'static str,
    },
    /// The FMU binary was not found.
    #[error("the FMU binary liboils_fmu.so is not beside the oils executable in {looked}: build it with `cargo build --release -p oils-fmu`, or name it with --binary PATH or OILS_FMU_BINARY")]
    NoBinary {
        /// Where it was looked for.
        looked: String,
    },
}
