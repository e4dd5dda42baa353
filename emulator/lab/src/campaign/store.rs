//! The campaign directory: the spec it was started with, one result file per case
//! (written atomically, so a crash leaves a case either done or not started), and the
//! merged results.
//!
//! ```text
//! DIR/campaign.toml      the spec (resolved: flags applied)
//! DIR/cases/0000042.json case 42's result: a line of identity, then the result
//! DIR/.lock              held (flock) by the `oils mc run` running the campaign
//! DIR/.lock-shard-I-of-K held by the run of shard I of K
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
    /// The campaign's identity (see [`Store::campaign_id`]), read once.
    campaign: std::sync::OnceLock<String>,
}

/// The first line of a stored case: which case of which campaign it is, and the BLAKE3
/// of the result's bytes (the second line), so a file copied over another, edited, or
/// from another campaign is refused by the merge instead of merged.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct CaseIdentity {
    /// `None` for the nominal run.
    index: Option<u64>,
    /// BLAKE3 of the campaign's stored spec (`campaign.toml`).
    campaign: String,
    /// BLAKE3 of the result line.
    blake3: String,
}

/// A lock on a campaign directory (or one shard of it), held while it lives.
#[derive(Debug)]
pub struct CampaignLock {
    _file: std::fs::File,
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
            campaign: std::sync::OnceLock::new(),
        }
    }

    /// The campaign's identity: the BLAKE3 of its stored spec (`none` before there is
    /// one). Every case file carries it.
    pub fn campaign_id(&self) -> String {
        self.campaign
            .get_or_init(|| match std::fs::read(self.spec_path()) {
                Ok(bytes) => blake3::hash(&bytes).to_hex().to_string(),
                Err(_) => "none".into(),
            })
            .clone()
    }

    /// Takes the campaign's advisory lock (`flock` on `DIR/.lock`, or on
    /// `DIR/.lock-shard-I-of-K` for one shard: shards run side by side by design), and
    /// writes this process's id into it. A second `oils mc run` on the same directory
    /// (or shard) fails at once, naming the holder's pid.
    pub fn lock(&self, shard: Option<(u64, u64)>) -> Result<CampaignLock, CampaignError> {
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::create_dir_all(&self.dir).map_err(io(&self.dir))?;
        let path = match shard {
            Some((i, k)) => self.dir.join(format!(".lock-shard-{i}-of-{k}")),
            None => self.dir.join(".lock"),
        };
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o600)
            .open(&path)
            .map_err(io(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let holder = std::fs::read_to_string(&path).unwrap_or_default();
                let what = match shard {
                    Some((i, k)) => format!("shard {i}/{k} of the campaign"),
                    None => "the campaign".into(),
                };
                return Err(CampaignError::Store(format!(
                    "{} is being run by another `oils mc run` (pid {}, holding {}); wait for it to finish, or give another --out",
                    what,
                    holder.split_whitespace().next().unwrap_or("unknown"),
                    path.display()
                )));
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io(&path)(e)),
        }
        file.set_len(0).map_err(io(&path))?;
        writeln!(file, "{}", std::process::id()).map_err(io(&path))?;
        Ok(CampaignLock { _file: file })
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
        let identity = CaseIdentity {
            index: result.index,
            campaign: self.campaign_id(),
            blake3: blake3::hash(text.as_bytes()).to_hex().to_string(),
        };
        let head = serde_json::to_string(&identity)
            .map_err(|e| CampaignError::Store(format!("{}: {e}", path.display())))?;
        write_atomic(&path, format!("{head}\n{text}\n").as_bytes())
    }

    /// Reads a stored result; `Ok(None)` if there is none. Refuses one whose identity
    /// line names another campaign, whose bytes do not match its hash (edited, damaged),
    /// or that was written before case files had an identity.
    pub fn read_result(&self, path: &Path) -> Result<Option<CaseResult>, CampaignError> {
        let refuse = |why: String| {
            CampaignError::Store(format!(
                "{}: {why}; delete it to run the case again",
                path.display()
            ))
        };
        match std::fs::read_to_string(path) {
            Ok(text) => {
                let (head, body) = text.split_once('\n').unwrap_or((&text, ""));
                let body = body.strip_suffix('\n').unwrap_or(body);
                let identity: CaseIdentity = serde_json::from_str(head).map_err(|_| {
                    refuse("not a case result of this oils (no identity line: written by an older oils, or not a case file)".into())
                })?;
                if blake3::hash(body.as_bytes()).to_hex().as_str() != identity.blake3 {
                    return Err(refuse(
                        "its content does not match its BLAKE3 (edited or damaged)".into(),
                    ));
                }
                let campaign = self.campaign_id();
                if identity.campaign != campaign {
                    return Err(refuse(format!(
                        "a case of another campaign (spec BLAKE3 {}, this campaign's {campaign})",
                        identity.campaign
                    )));
                }
                let result: CaseResult = oils_emulator::exact_json::from_str(body)
                    .map_err(|e| refuse(format!("not a case result ({e})")))?;
                if result.index != identity.index {
                    return Err(refuse(
                        "its identity and its result name different cases".into(),
                    ));
                }
                Ok(Some(result))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(source) => Err(CampaignError::Io {
                path: path.to_path_buf(),
                source,
            }),
        }
    }

    /// Case `index`'s stored result; refused when the file holds another case (a case
    /// file copied over another).
    pub fn read_case(&self, index: u64) -> Result<Option<CaseResult>, CampaignError> {
        let path = self.case_path(index);
        let result = self.read_result(&path)?;
        if let Some(other) = result
            .as_ref()
            .map(|r| r.index)
            .filter(|i| *i != Some(index))
        {
            return Err(CampaignError::Store(format!(
                "{} holds case {}, not case {index} (copied over it?); delete it to run case {index} again",
                path.display(),
                other.map_or("nominal".into(), |i| i.to_string())
            )));
        }
        Ok(result)
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
