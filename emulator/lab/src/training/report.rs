//! Training reports: the paper's Fig. 2 (error vs history length) and Fig. 3 (train and
//! test RMSE and sparsity vs mu) as CSV (and PNG where plotting is available), the full
//! CV grid, the excitation profile, and a readable summary of the chosen models.

use super::cv::{CvResult, GridPoint};
use super::TrainOutcome;
use oils_emulator::propulsion::surrogate::features::{STATE_DIM, STATE_NAMES};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Writing a report failed.
#[derive(Debug, thiserror::Error)]
#[error("cannot write report file {path}: {message}")]
pub struct ReportError {
    /// File.
    pub path: String,
    /// Cause.
    pub message: String,
}

fn write(path: &Path, text: &str) -> Result<(), ReportError> {
    std::fs::write(path, text).map_err(|e| ReportError {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

/// The point of each history length with the lowest score (the curve of Fig. 2).
pub fn best_per_n(res: &CvResult) -> Vec<&GridPoint> {
    let mut out: Vec<&GridPoint> = Vec::new();
    for p in &res.points {
        match out.last_mut() {
            Some(last) if last.n == p.n => {
                if p.score < last.score {
                    *last = p;
                }
            }
            _ => out.push(p),
        }
    }
    out
}

/// The points at the chosen history length (the curve of Fig. 3), mu descending.
pub fn at_chosen_n(res: &CvResult) -> Vec<&GridPoint> {
    let n = res.chosen().n;
    res.points.iter().filter(|p| p.n == n).collect()
}

fn grid_csv(res: &CvResult) -> String {
    let mut s = String::from("n,mu,sparsity_pct,score,unconverged");
    for kind in ["train", "test", "free"] {
        for o in STATE_NAMES {
            let _ = write!(s, ",{kind}_rmse_{o}");
        }
    }
    s.push('\n');
    for p in &res.points {
        let _ = write!(
            s,
            "{},{:e},{},{},{}",
            p.n, p.mu, p.sparsity_pct, p.score, p.unconverged
        );
        for v in p.train_rmse.iter().chain(&p.test_rmse).chain(&p.free_rmse) {
            let _ = write!(s, ",{v}");
        }
        s.push('\n');
    }
    s
}

fn fig2_csv(res: &CvResult) -> String {
    let mut s = String::from(
        "n,best_mu,test_rmse_thrust_n,free_rmse_thrust_n,free_rmse_P_pa,free_rmse_m_f_kg,free_rmse_m_o_kg,score\n",
    );
    for p in best_per_n(res) {
        let _ = writeln!(
            s,
            "{},{:e},{},{},{},{},{},{}",
            p.n,
            p.mu,
            GridPoint::thrust(&p.test_rmse),
            GridPoint::thrust(&p.free_rmse),
            p.free_rmse[4],
            p.free_rmse[5],
            p.free_rmse[6],
            p.score
        );
    }
    s
}

fn fig3_csv(res: &CvResult) -> String {
    let mut s = String::from(
        "mu,train_rmse_thrust_n,test_rmse_thrust_n,free_rmse_thrust_n,sparsity_pct,score\n",
    );
    for p in at_chosen_n(res) {
        let _ = writeln!(
            s,
            "{:e},{},{},{},{},{}",
            p.mu,
            GridPoint::thrust(&p.train_rmse),
            GridPoint::thrust(&p.test_rmse),
            GridPoint::thrust(&p.free_rmse),
            p.sparsity_pct,
            p.score
        );
    }
    s
}

/// The text summary: the variants side by side, then each model's chosen (n, mu),
/// sparsity, active terms per output and top terms by name.
pub fn summary(out: &TrainOutcome, top: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# oils train: summary\n");
    let d = &out.dataset;
    let _ = writeln!(
        s,
        "data: {} steps of {} ms ({:.1} s of excitation)\n",
        d.len(),
        d.sample_time_ns as f64 * 1e-6,
        out.excitation.duration_s()
    );
    let _ = writeln!(s, "## Variants (cross-validated, mean over folds)\n");
    let _ = writeln!(
        s,
        "| variant | n | mu | sparsity % | active terms | one-step test RMSE thrust (N) | free-run RMSE thrust (N) | free-run RMSE P (Pa) | free-run RMSE m_f (kg) | free-run RMSE m_o (kg) | score |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for (i, (res, file)) in out.cv.iter().zip(&out.models).enumerate() {
        let c = res.chosen();
        let _ = writeln!(
            s,
            "| {}{} | {} | {:.3e} | {:.1} | {} | {:.3} | {:.3} | {:.4e} | {:.4} | {:.4} | {:.5} |",
            res.variant.as_str(),
            if i == out.deployed { " (deployed)" } else { "" },
            c.n,
            c.mu,
            file.sparsity_pct,
            file.model.active_terms(),
            GridPoint::thrust(&c.test_rmse),
            GridPoint::thrust(&c.free_rmse),
            c.free_rmse[4],
            c.free_rmse[5],
            c.free_rmse[6],
            c.score
        );
    }
    for (res, file) in out.cv.iter().zip(&out.models) {
        let _ = writeln!(s, "\n## {} model\n", res.variant.as_str());
        let c = res.chosen();
        let _ = writeln!(
            s,
            "chosen n = {}, mu = {:e}; sparsity {:.1} % ({} of {} coefficients active)\n",
            c.n,
            c.mu,
            file.sparsity_pct,
            file.model.active_terms(),
            file.model.total_terms()
        );
        if res.mu_at_grid_end() {
            let _ = writeln!(
                s,
                "The chosen mu is at the end of the grid: the score may fall beyond it; \
                 widen [cv] mu_min / mu_max.\n"
            );
        }
        let _ = writeln!(s, "free-run RMSE per output (CV):");
        for o in 0..STATE_DIM {
            let _ = writeln!(
                s,
                "  {:5} one-step {:.4e}  free-run {:.4e}",
                STATE_NAMES[o], c.test_rmse[o], c.free_rmse[o]
            );
        }
        let _ = writeln!(s, "\n```text\n{}```", file.model.describe(top));
    }
    s
}

/// Writes every report file into `dir`; returns the paths written.
pub fn write_reports(
    out: &TrainOutcome,
    dir: &Path,
    top: usize,
) -> Result<Vec<PathBuf>, ReportError> {
    std::fs::create_dir_all(dir).map_err(|e| ReportError {
        path: dir.display().to_string(),
        message: e.to_string(),
    })?;
    let mut written = Vec::new();
    let mut put = |name: String, text: String| -> Result<(), ReportError> {
        let p = dir.join(name);
        write(&p, &text)?;
        written.push(p);
        Ok(())
    };
    for res in &out.cv {
        let v = res.variant.as_str();
        put(format!("cv_grid_{v}.csv"), grid_csv(res))?;
        put(format!("fig2_error_vs_history_{v}.csv"), fig2_csv(res))?;
        put(format!("fig3_error_sparsity_vs_mu_{v}.csv"), fig3_csv(res))?;
    }
    let profile = out.excitation.to_profile().map_err(|e| ReportError {
        path: "excitation.csv".into(),
        message: e.to_string(),
    })?;
    put("excitation.csv".into(), profile.to_csv())?;
    put("summary.md".into(), summary(out, top))?;
    for m in &out.models {
        put(format!("model_{}.json", m.variant.as_str()), m.to_json())?;
    }
    Ok(written)
}
