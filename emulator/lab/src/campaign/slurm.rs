//! The Slurm backend: a campaign as a job array of `oils mc run --shard I/K` tasks and a
//! merge job after them. A shard runs the same code as a local campaign, so its results
//! are the same files; this module only writes the two batch scripts and submits them.

use super::store::write_atomic;
use super::CampaignError;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A campaign's submission to Slurm.
#[derive(Debug, Clone)]
pub struct SlurmSubmission {
    /// The campaign's name (a comment in the scripts).
    pub name: String,
    /// The campaign directory, absolute, on a filesystem every node sees.
    pub dir: PathBuf,
    /// Array tasks (shards), at least 1.
    pub tasks: u64,
    /// CPUs per task (each task runs that many cases at once).
    pub cpus_per_task: u32,
    /// The `oils` binary the tasks run, absolute.
    pub oils: PathBuf,
    /// The sbatch command.
    pub sbatch: String,
    /// Options passed to both sbatch calls (partition, account, time...).
    pub sbatch_args: Vec<String>,
}

/// What a submission produced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Submitted {
    /// The array job's id.
    pub array_id: String,
    /// The merge job's id.
    pub merge_id: String,
    /// Where the scripts and the tasks' output are.
    pub slurm_dir: PathBuf,
}

/// Quotes `s` for a POSIX shell.
fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

impl SlurmSubmission {
    /// The folder of the scripts and the tasks' output: `DIR/slurm`.
    pub fn slurm_dir(&self) -> PathBuf {
        self.dir.join("slurm")
    }

    /// The array script: shard `$SLURM_ARRAY_TASK_ID` of `tasks`.
    pub fn array_script(&self) -> String {
        let (oils_q, dir_q) = self.quoted();
        format!(
            "#!/bin/bash\n\
             # oils campaign `{name}`: shard $SLURM_ARRAY_TASK_ID of {k} (written by `oils mc submit`).\n\
             #SBATCH --job-name=oils-mc\n\
             #SBATCH --array=0-{last}\n\
             #SBATCH --cpus-per-task={cpus}\n\
             #SBATCH --output={out}/shard-%a.out\n\
             set -euo pipefail\n\
             exec {oils_q} mc run --out {dir_q} --shard \"${{SLURM_ARRAY_TASK_ID}}/{k}\" --jobs \"${{SLURM_CPUS_PER_TASK:-{cpus}}}\"\n",
            name = self.name,
            k = self.tasks,
            last = self.tasks - 1,
            cpus = self.cpus_per_task,
            out = self.slurm_dir().display(),
        )
    }

    /// The merge script, run after every shard.
    pub fn merge_script(&self) -> String {
        let (oils_q, dir_q) = self.quoted();
        format!(
            "#!/bin/bash\n\
             # oils campaign `{name}`: merge after every shard (written by `oils mc submit`).\n\
             #SBATCH --job-name=oils-mc-merge\n\
             #SBATCH --cpus-per-task=1\n\
             #SBATCH --output={out}/merge.out\n\
             set -euo pipefail\n\
             exec {oils_q} mc merge {dir_q}\n",
            name = self.name,
            out = self.slurm_dir().display(),
        )
    }

    fn quoted(&self) -> (String, String) {
        (
            sh_quote(&self.oils.display().to_string()),
            sh_quote(&self.dir.display().to_string()),
        )
    }

    /// Writes both scripts into [`Self::slurm_dir`] and returns their paths (array, merge).
    pub fn write_scripts(&self) -> Result<(PathBuf, PathBuf), CampaignError> {
        if self.tasks == 0 {
            return Err(CampaignError::Spec(
                "a Slurm submission needs at least one task".into(),
            ));
        }
        let dir = self.slurm_dir();
        std::fs::create_dir_all(&dir).map_err(|source| CampaignError::Io {
            path: dir.clone(),
            source,
        })?;
        let array = dir.join("array.sbatch");
        let merge = dir.join("merge.sbatch");
        write_atomic(&array, self.array_script().as_bytes())?;
        write_atomic(&merge, self.merge_script().as_bytes())?;
        Ok((array, merge))
    }

    /// The sbatch call for `script` with `extra` options first.
    pub fn sbatch_command(&self, script: &Path, extra: &[String]) -> Command {
        let mut cmd = Command::new(&self.sbatch);
        cmd.arg("--parsable")
            .args(extra)
            .args(&self.sbatch_args)
            .arg(script);
        cmd
    }

    /// Writes the scripts and submits the array, then the merge job depending on it.
    pub fn submit(&self) -> Result<Submitted, CampaignError> {
        let (array, merge) = self.write_scripts()?;
        let array_id = self.run_sbatch(&array, &[])?;
        let merge_id = self.run_sbatch(&merge, &[format!("--dependency=afterany:{array_id}")])?;
        Ok(Submitted {
            array_id,
            merge_id,
            slurm_dir: self.slurm_dir(),
        })
    }

    fn run_sbatch(&self, script: &Path, extra: &[String]) -> Result<String, CampaignError> {
        let fail = |why: String| {
            CampaignError::Slurm(format!("{} {}: {why}", self.sbatch, script.display()))
        };
        let out = self
            .sbatch_command(script, extra)
            .output()
            .map_err(|e| fail(format!("{e} (is Slurm installed?)")))?;
        if !out.status.success() {
            return Err(fail(format!(
                "failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            )));
        }
        let text = String::from_utf8_lossy(&out.stdout);
        let id = text.trim().split(';').next().unwrap_or("").to_string();
        if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
            return Err(fail(format!("printed no job id: `{}`", text.trim())));
        }
        Ok(id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn submission(dir: &Path) -> SlurmSubmission {
        SlurmSubmission {
            name: "t".into(),
            dir: dir.to_path_buf(),
            tasks: 3,
            cpus_per_task: 2,
            oils: PathBuf::from("/opt/it's/oils"),
            sbatch: "sbatch".into(),
            sbatch_args: vec!["--partition=long".into()],
        }
    }

    #[test]
    fn the_array_script_runs_every_shard_with_quoted_paths() {
        let s = submission(Path::new("/campaigns/a b"));
        let text = s.array_script();
        assert!(text.contains("#SBATCH --array=0-2"), "{text}");
        assert!(
            text.contains("--shard \"${SLURM_ARRAY_TASK_ID}/3\""),
            "{text}"
        );
        assert!(
            text.contains("'/opt/it'\\''s/oils' mc run --out '/campaigns/a b'"),
            "{text}"
        );
        assert!(s.merge_script().contains("mc merge '/campaigns/a b'"));
    }

    #[test]
    fn a_failing_or_silent_sbatch_is_an_error_naming_it() {
        let dir = std::env::temp_dir().join(format!("oils-slurm-{}", std::process::id()));
        let mut s = submission(&dir);
        s.sbatch = "false".into();
        let e = s.submit().unwrap_err().to_string();
        assert!(e.contains("false") && e.contains("array.sbatch"), "{e}");
        s.sbatch = "true".into();
        let e = s.submit().unwrap_err().to_string();
        assert!(e.contains("no job id"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
