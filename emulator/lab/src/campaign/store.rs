//! The campaign directory: the spec it was started with, one result file per case
//! (written atomically, so a crash leaves a case either done or not started), and the
//! merged results.
//!
//! ```text
//! DIR/campaign.toml      the spec (resolved: flags applied)
//! DIR/cases/0000042.json case 42's result
//! DIR/nominal.json       the nominal run (the base without dispersions)
//! DIR/cases.csv          merged: one row per case
//! DIR/summary.json       merged: statistics
//! DIR/timing.json        wall times (not byte-identical between runs)
//! DIR/plots/*.png        footprint, histograms, traces
//! ```

use super::case::CaseResult;
use super::spec::CampaignSpec;
use super::CampaignError;
use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};

/// A campaign directory.
#[derive(Debug, Clone)]
pub struct Store {
    dir: PathBuf,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CampaignError + '_ {
    move |source| CampaignError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `bytes` to `path` atomically: a temporary file beside it, flushed to disk,
/// renamed over `path`, and the directory synced.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), CampaignError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(
        ".{name}.{}.{:?}.tmp",
        std::process::id(),
        std::thread::current().id()
    ));
    let mut f = std::fs::File::create(&tmp).map_err(io(&tmp))?;
    f.write_all(bytes).map_err(io(&tmp))?;
    f.sync_all().map_err(io(&tmp))?;
    drop(f);
    std::fs::rename(&tmp, path).map_err(io(path))?;
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

impl Store {
    /// The directory (not created yet).
    pub fn new(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
        }
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// `DIR/campaign.toml`.
    pub fn spec_path(&self) -> PathBuf {
        self.dir.join("campaign.toml")
    }

    fn cases_dir(&self) -> PathBuf {
        self.dir.join("cases")
    }

    /// Where case `index`'s result lives.
    pub fn case_path(&self, index: u64) -> PathBuf {
        self.cases_dir().join(format!("{index:07}.json"))
    }

    /// `DIR/nominal.json`.
    pub fn nominal_path(&self) -> PathBuf {
        self.dir.join("nominal.json")
    }

    /// The spec stored in the directory, if any.
    pub fn stored_spec(&self) -> Result<Option<CampaignSpec>, CampaignError> {
        let path = self.spec_path();
        if !path.exists() {
            return Ok(None);
        }
        CampaignSpec::load(&path).map(Some)
    }

    /// Creates the directory for `spec`, or checks that it holds the same campaign
    /// (a campaign started again resumes; another spec in the same place is refused).
    pub fn open(&self, spec: &CampaignSpec) -> Result<(), CampaignError> {
        std::fs::create_dir_all(self.cases_dir()).map_err(io(&self.cases_dir()))?;
        match self.stored_spec()? {
            Some(stored) if &stored == spec => Ok(()),
            Some(_) => Err(CampaignError::Store(format!(
                "{} holds another campaign ({}): give the same spec and flags to resume it, or another --out",
                self.dir.display(),
                self.spec_path().display()
            ))),
            None => write_atomic(&self.spec_path(), spec.to_toml()?.as_bytes()),
        }
    }

    /// Writes a case's result atomically.
    pub fn write_case(&self, result: &CaseResult) -> Result<(), CampaignError> {
        let path = match result.index {
            Some(i) => self.case_path(i),
            None => self.nominal_path(),
        };
        let text = serde_json::to_string(result)
            .map_err(|e| CampaignError::Store(format!("{}: {e}", path.display())))?;
        write_atomic(&path, text.as_bytes())
    }

    /// Reads a stored result; `Ok(None)` if there is none.
    pub fn read_result(&self, path: &Path) -> Result<Option<CaseResult>, CampaignError> {
        match std::fs::read_to_string(path) {
            Ok(text) => oils_emulator::exact_json::from_str(&text)
                .map(Some)
                .map_err(|e| {
                    CampaignError::Store(format!(
                        "{}: not a case result ({e}); delete it to run the case again",
                        path.display()
                    ))
                }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(source) => Err(CampaignError::Io {
                path: path.to_path_buf(),
                source,
            }),
        }
    }

    /// Case `index`'s stored result.
    pub fn read_case(&self, index: u64) -> Result<Option<CaseResult>, CampaignError> {
        self.read_result(&self.case_path(index))
    }

    /// Indices with a stored result.
    pub fn done(&self) -> Result<BTreeSet<u64>, CampaignError> {
        let dir = self.cases_dir();
        let mut done = BTreeSet::new();
        let entries = match std::fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(done),
            Err(source) => return Err(CampaignError::Io { path: dir, source }),
        };
        for entry in entries {
            let entry = entry.map_err(io(&dir))?;
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if let Some(i) = name
                .strip_suffix(".json")
                .filter(|s| s.len() >= 7 && s.bytes().all(|b| b.is_ascii_digit()))
                .and_then(|s| s.parse().ok())
            {
                done.insert(i);
            }
        }
        Ok(done)
    }
}
