//! `oils plot LOG --out DIR` and `oils run --plots DIR`: a run's figures from its log.

use anyhow::{Context, Result};
use oils_emulator::report::RunReport;
use oils_lab::mcap_log::{is_mcap, read_any, read_mcap_timing};
use std::path::Path;

/// The figures' common title: run id, propulsion model, flight software, from the
/// log's header.
fn title_of(header_json: &str) -> String {
    let h: serde_json::Value = serde_json::from_str(header_json).unwrap_or_default();
    let c = &h["config"];
    let text = |v: &serde_json::Value| {
        v.as_str()
            .map(str::to_string)
            .unwrap_or_else(|| v.to_string())
    };
    format!(
        "run {}, {}, fsw {}, seed {}",
        text(&h["run_id"]),
        text(&c["propulsion"]),
        text(&c["fsw"]),
        c["seed"]
    )
}

/// Draws the figures of the run logged at `log` into `dir`.
pub fn run(log: &Path, dir: &Path) -> Result<()> {
    draw(log, dir).map(|_| ())
}

/// Draws the figures of the run logged at `log` into `dir`; returns their paths.
fn draw(log: &Path, dir: &Path) -> Result<Vec<std::path::PathBuf>> {
    let data = read_any(log).with_context(|| format!("reading {}", log.display()))?;
    if !data.damaged_records.is_empty() {
        eprintln!(
            "oils plot: {} damaged records skipped (first at position {})",
            data.damaged_records.len(),
            data.damaged_records[0]
        );
    }
    let timing = if is_mcap(log) {
        Some(read_mcap_timing(log)?)
    } else {
        None
    };
    let written =
        oils_lab::run_plots::write_all(&data, timing.as_deref(), dir, &title_of(&data.header_json))
            .with_context(|| format!("plotting {}", log.display()))?;
    eprintln!(
        "oils plot: {} figures of {} records in {}",
        written.len(),
        data.records.len(),
        dir.display()
    );
    Ok(written)
}

/// `oils run --plots DIR`: the figures of the run just finished, from its log, and its
/// page `DIR/report.html`.
pub fn after_run(report: &RunReport, dir: &Path) -> Result<()> {
    let log = report
        .log
        .as_deref()
        .context("--plots: the run wrote no log")?;
    let figures = draw(Path::new(log), dir)?;
    let page = oils_lab::report_page::write_run(report, dir, &figures)
        .context("writing the run's page")?;
    eprintln!("oils run: report page {}", page.display());
    Ok(())
}
