//! One self-contained HTML page per campaign (`DIR/report.html`) or run
//! (`PLOTS/report.html`): the summary, every figure embedded as a base64 PNG (no
//! network, no script library: the page opens from a mail attachment), the worst cases
//! each with the command that flies it again, the drivers of the failures, the spec.
//!
//! A short inline script marks in the page itself whether every figure loaded and
//! whether anything reported an error (`#page-check`), so a headless browser's
//! `--dump-dom` tells a test both; the page reads the same without it.

use crate::campaign::case::CaseResult;
use crate::campaign::drivers::{self, Driver};
use crate::campaign::plots::REFERENCE_POINT;
use crate::campaign::spec::CampaignSpec;
use crate::campaign::summary::{FigureStats, Merged};
use oils_emulator::report::RunReport;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The page's file name, at the top of a campaign directory or in a run's plots folder.
pub const PAGE: &str = "report.html";

/// Most failures listed on a page (all are in `summary.json` and `cases.csv`).
const MAX_FAILURES_LISTED: usize = 50;

/// Most drivers in the page's table.
const MAX_DRIVERS_LISTED: usize = 40;

/// A page could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PageError {
    /// A figure could not be read or the page written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> PageError + '_ {
    move |source| PageError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Standard base64 (RFC 4648, padded): a data URI's payload.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for (i, shift) in [18, 12, 6, 0].into_iter().enumerate() {
            if i <= c.len() {
                out.push(A[(n >> shift & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// `text` safe inside HTML text and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for ch in text.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A number for a table: four significant digits, empty when absent or not finite.
fn num(x: Option<f64>) -> String {
    match x.filter(|x| x.is_finite()) {
        Some(x) => crate::plot::tick_label(x),
        None => String::new(),
    }
}

const STYLE: &str = "body{font-family:'DejaVu Sans',Helvetica,Arial,sans-serif;margin:2em auto;max-width:1250px;color:#222;line-height:1.4}\
h1{font-size:1.6em;margin-bottom:0.2em}h2{margin-top:1.6em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;margin:0.6em 0}td,th{border:1px solid #ccc;padding:0.2em 0.6em;text-align:right}\
th{background:#f3f3f3}td.l,th.l{text-align:left}code,pre{font-family:'DejaVu Sans Mono',monospace;font-size:0.9em}\
pre{background:#f7f7f7;padding:0.8em;overflow-x:auto}figure{margin:1.2em 0}img{max-width:100%;border:1px solid #ddd}\
figcaption{color:#555;font-size:0.9em}.note{color:#555}.bad{color:#b00}";

/// The inline check: marks each image loaded or not and collects errors (resource
/// failures, script errors, `console.error`) into `#page-check` once the page loaded.
const CHECK_SCRIPT: &str = r#"<script>
(function () {
  var errors = [];
  window.addEventListener('error', function (e) {
    var t = e.target;
    errors.push(t && t.tagName ? 'failed to load ' + t.tagName.toLowerCase() + ' ' + (t.alt || '') : String(e.message));
  }, true);
  var ce = console.error;
  console.error = function () { errors.push(Array.prototype.join.call(arguments, ' ')); ce.apply(console, arguments); };
  window.addEventListener('load', function () {
    var imgs = document.images, failed = 0;
    for (var i = 0; i < imgs.length; i++) {
      var ok = imgs[i].complete && imgs[i].naturalWidth > 0;
      imgs[i].setAttribute('data-loaded', ok ? 'yes' : 'no');
      if (!ok) { failed++; }
    }
    var c = document.getElementById('page-check');
    c.setAttribute('data-images', String(imgs.length));
    c.setAttribute('data-failed', String(failed));
    c.setAttribute('data-errors', String(errors.length));
    c.textContent = errors.join('\n');
    c.setAttribute('data-done', 'yes');
  });
})();
</script>"#;

fn head(out: &mut String, title: &str) {
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n{CHECK_SCRIPT}\n</head>\n<body>\n<div id=\"page-check\" hidden></div>\n",
        escape(title)
    );
}

/// Embeds the PNGs at `figures` (a caption each from its file name).
fn figures_section(out: &mut String, figures: &[PathBuf]) -> Result<(), PageError> {
    out.push_str("<h2 id=\"figures\">Figures</h2>\n");
    for f in figures {
        let bytes = std::fs::read(f).map_err(io(f))?;
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let _ = writeln!(
            out,
            "<figure><img alt=\"{n}\" src=\"data:image/png;base64,{}\"><figcaption>{n}</figcaption></figure>",
            base64(&bytes),
            n = escape(&name)
        );
    }
    Ok(())
}

fn write_page(path: &Path, html: &str) -> Result<(), PageError> {
    let tmp = path.with_extension("html.tmp");
    std::fs::write(&tmp, html).map_err(io(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io(path))
}

/// The figures' units, by `summary.json` name.
fn unit(name: &str) -> &'static str {
    if name.ends_with("_mps") {
        "m/s"
    } else if name.ends_with("_deg") {
        "deg"
    } else if name.ends_with("_kg") {
        "kg"
    } else if name.ends_with("_m") {
        "m"
    } else if name.ends_with("_s") {
        "s"
    } else {
        ""
    }
}

fn stats_row(out: &mut String, name: &str, s: &FigureStats) {
    let _ = writeln!(
        out,
        "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td class=\"l\">{}</td></tr>",
        escape(name),
        s.count,
        num(Some(s.mean)),
        num(Some(s.std)),
        num(Some(s.min)),
        num(Some(s.p1)),
        num(Some(s.p50)),
        num(Some(s.p99)),
        num(Some(s.max)),
        unit(name)
    );
}

fn drivers_table(out: &mut String, d: &[Driver]) {
    out.push_str("<h2 id=\"drivers\">What drives the failures</h2>\n<p class=\"note\">Spearman rank correlation of each applied value with failure (1: the case did not land) over the cases that flew, and with each touchdown figure over the cases that touched down; a fault enters as struck (1) or not (0). Ranked by |rho| with failure. p: two-sided, under no association.</p>\n<table>\n<tr><th>rank</th><th class=\"l\">applied value</th><th class=\"l\">kind</th><th>rho with failure</th><th>p</th><th>cases</th>");
    for f in drivers::FIGURES {
        let _ = write!(out, "<th>rho {}</th>", escape(f));
    }
    out.push_str("</tr>\n");
    for (i, x) in d.iter().take(MAX_DRIVERS_LISTED).enumerate() {
        let _ = write!(
            out,
            "<tr><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td>",
            i + 1,
            escape(&x.name),
            escape(&x.kind),
            x.failure_rho.map_or(String::new(), |r| format!("{r:.3}")),
            num(x.failure_p),
            x.cases
        );
        for f in drivers::FIGURES {
            let _ = write!(
                out,
                "<td>{}</td>",
                x.figures
                    .get(f)
                    .map_or(String::new(), |r| format!("{r:.3}"))
            );
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table>\n");
    if d.len() > MAX_DRIVERS_LISTED {
        let _ = writeln!(
            out,
            "<p class=\"note\">{} more in <code>summary.json</code> (<code>drivers</code>).</p>",
            d.len() - MAX_DRIVERS_LISTED
        );
    }
}

/// The command that flies case `index` of the campaign in `dir` again, with a log and
/// its figures.
pub fn case_command(dir: &Path, index: u64) -> String {
    format!(
        "oils mc case {} --index {index} --log case-{index}.mcap --plots case-{index}",
        dir.display()
    )
}

fn case_value(r: &CaseResult, nominal: &CaseResult, figure: &str) -> Option<f64> {
    drivers::figure(r, nominal, figure)
}

/// Writes `DIR/report.html` of the campaign merged in `dir` (its figures from `plots`,
/// `timing_json` from `DIR/timing.json` if there is one). Returns the page's path.
pub fn write_campaign(
    spec: &CampaignSpec,
    merged: &Merged,
    dir: &Path,
    figures: &[PathBuf],
) -> Result<PathBuf, PageError> {
    let s = &merged.summary;
    let mut out = String::new();
    let title = format!("Campaign {}: {} cases, {}", s.name, s.merged, s.propulsion);
    head(&mut out, &title);
    let _ = writeln!(
        out,
        "<h1>{}</h1>\n<p>Master seed {}; landed <b>{} of {}</b> ({:.1} %); nominal run {} (digest <code>{}</code>). Positions are about {}.</p>",
        escape(&title),
        s.seed,
        s.landed,
        s.merged,
        100.0 * s.landed_fraction,
        escape(&s.nominal.outcome),
        escape(&s.nominal.digest),
        escape(REFERENCE_POINT)
    );
    out.push_str("<p><a href=\"#summary\">summary</a> | <a href=\"#figures\">figures</a> | <a href=\"#drivers\">drivers</a> | <a href=\"#worst\">worst cases</a> | <a href=\"#failures\">failures</a> | <a href=\"#spec\">spec</a></p>\n");

    // Summary.
    out.push_str("<h2 id=\"summary\">Summary</h2>\n<table>\n<tr><th class=\"l\">outcome</th><th>cases</th><th>fraction</th></tr>\n");
    for (o, n) in &s.outcomes {
        let _ = writeln!(
            out,
            "<tr><td class=\"l\">{}</td><td>{n}</td><td>{:.1} %</td></tr>",
            escape(o),
            100.0 * *n as f64 / s.merged.max(1) as f64
        );
    }
    out.push_str("</table>\n");
    if !s.crash_reasons.is_empty() {
        let reasons: Vec<String> = s
            .crash_reasons
            .iter()
            .map(|(why, n)| format!("{} {n}", escape(why)))
            .collect();
        let _ = writeln!(out, "<p>Crashed, by reason: {}.</p>", reasons.join(", "));
    }
    if !s.missing.is_empty() {
        let _ = writeln!(
            out,
            "<p class=\"bad\">{} cases have no result (merged with --partial).</p>",
            s.missing.len()
        );
    }
    out.push_str("<p class=\"note\">Touchdown figures over the cases that touched down; propellant over every case that flew.</p>\n<table>\n<tr><th class=\"l\">figure</th><th>cases</th><th>mean</th><th>std</th><th>min</th><th>p1</th><th>p50</th><th>p99</th><th>max</th><th class=\"l\">unit</th></tr>\n");
    for (name, st) in &s.figures {
        stats_row(&mut out, name, st);
    }
    out.push_str("</table>\n");
    let lim = &spec.base.scenario.touchdown;
    let legs = spec.base.scenario.landing_limits();
    let _ = writeln!(
        out,
        "<p>Landing limits: vertical speed {} m/s, horizontal speed {} m/s, tilt at rest {} deg, slope {} deg (both from the legs), slide {} m.",
        num(Some(lim.vertical_speed_mps)),
        num(Some(lim.horizontal_speed_mps)),
        num(Some(legs.tilt_deg)),
        num(Some(legs.slope_deg)),
        num(Some(lim.slide_limit_m))
    );
    if let Some(e) = &s.footprint_3sigma {
        let _ = write!(
            out,
            " Footprint of the landed cases, 3 sigma: {} m by {} m (full axes), major axis at {} deg from downrange, centred {} m downrange and {} m crossrange of the reference point.",
            num(Some(2.0 * e.semi_major_m)),
            num(Some(2.0 * e.semi_minor_m)),
            num(Some(e.angle_deg)),
            num(Some(e.centre_m[0])),
            num(Some(e.centre_m[1]))
        );
    }
    if let Some([a, b]) = spec.requirements.and_then(|r| r.footprint_m) {
        let inside = merged
            .results
            .iter()
            .filter(|r| r.outcome == "landed")
            .filter_map(|r| {
                let dx = r.downrange_m?;
                let dy = r.crossrange_m?;
                Some((dx / (0.5 * a)).powi(2) + (dy / (0.5 * b)).powi(2) <= 1.0)
            })
            .collect::<Vec<_>>();
        let n_in = inside.iter().filter(|x| **x).count();
        let _ = write!(
            out,
            " Requirement zone {} m by {} m: {} of {} landed cases inside.",
            num(Some(a)),
            num(Some(b)),
            n_in,
            inside.len()
        );
    }
    out.push_str("</p>\n");

    figures_section(&mut out, figures)?;
    drivers_table(&mut out, &s.drivers);

    // Worst cases, each with its command.
    let by_index: std::collections::BTreeMap<u64, &CaseResult> = merged
        .results
        .iter()
        .filter_map(|r| r.index.map(|i| (i, r)))
        .collect();
    out.push_str("<h2 id=\"worst\">Worst cases</h2>\n<p class=\"note\">The five largest of each figure among the cases that touched down; each command flies the case again alone (same digest), with an MCAP log for Foxglove and its figures and page.</p>\n<table>\n<tr><th class=\"l\">figure</th><th>case</th><th class=\"l\">outcome</th><th>value</th><th class=\"l\">command</th></tr>\n");
    for (figure, cases) in &s.worst {
        for i in cases {
            let r = by_index.get(i);
            let _ = writeln!(
                out,
                "<tr><td class=\"l\">{}</td><td>{i}</td><td class=\"l\">{}</td><td>{} {}</td><td class=\"l\"><code>{}</code></td></tr>",
                escape(figure),
                r.map_or(String::new(), |r| escape(&r.outcome)),
                num(r.and_then(|r| case_value(r, &merged.nominal, figure))),
                unit(figure),
                escape(&case_command(dir, *i))
            );
        }
    }
    out.push_str("</table>\n");

    // Failures.
    let _ = writeln!(
        out,
        "<h2 id=\"failures\">Failures</h2>\n<p>{} cases did not land{}.</p>",
        s.failure_count,
        if s.failure_count as usize > MAX_FAILURES_LISTED {
            format!(" (the first {MAX_FAILURES_LISTED} by index here; all in cases.csv)")
        } else {
            String::new()
        }
    );
    if !s.failures.is_empty() {
        out.push_str("<table>\n<tr><th>case</th><th class=\"l\">outcome</th><th class=\"l\">faults</th><th class=\"l\">why</th><th class=\"l\">command</th></tr>\n");
        for f in s.failures.iter().take(MAX_FAILURES_LISTED) {
            let faults = by_index
                .get(&f.index)
                .map(|r| r.faults.join("; "))
                .unwrap_or_default();
            let _ = writeln!(
                out,
                "<tr><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\"><code>{}</code></td></tr>",
                f.index,
                escape(&f.outcome),
                escape(&faults),
                escape(match (&f.outcome_reason, &f.error) {
                    (Some(why), _) => why.as_str(),
                    (None, Some(e)) => e.as_str(),
                    (None, None) => "",
                }),
                escape(&case_command(dir, f.index))
            );
        }
        out.push_str("</table>\n");
    }

    // The spec, as stored.
    let spec_text = spec.to_toml().unwrap_or_else(|e| e.to_string());
    let _ = writeln!(
        out,
        "<h2 id=\"spec\">The spec</h2>\n<p class=\"note\"><code>{}</code>, as the campaign ran it (flags applied).</p>\n<pre>{}</pre>",
        escape(&dir.join("campaign.toml").display().to_string()),
        escape(&spec_text)
    );
    if let Ok(t) = std::fs::read_to_string(dir.join("timing.json")) {
        let _ = writeln!(
            out,
            "<h2>Wall time</h2>\n<pre>{}</pre>",
            escape(t.trim_end())
        );
    }
    out.push_str("</body>\n</html>\n");
    let path = dir.join(PAGE);
    write_page(&path, &out)?;
    Ok(path)
}

/// Writes `dir/report.html` of one run: its report table, its figures, the command
/// that repeats it and its configuration. Returns the page's path.
pub fn write_run(
    report: &RunReport,
    dir: &Path,
    figures: &[PathBuf],
) -> Result<PathBuf, PageError> {
    let mut out = String::new();
    let s = &report.summary;
    let title = format!(
        "Run {}: {}, fsw {}, {:?}",
        report.run_id, report.propulsion, report.fsw, s.outcome
    );
    head(&mut out, &title);
    let _ = writeln!(out, "<h1>{}</h1>", escape(&title));
    let _ = writeln!(
        out,
        "<h2 id=\"summary\">Summary</h2>\n<pre>{}</pre>",
        escape(report.table().trim_end())
    );
    if !report.warnings.is_empty() {
        out.push_str("<ul>\n");
        for w in &report.warnings {
            let _ = writeln!(out, "<li class=\"bad\">{}</li>", escape(w));
        }
        out.push_str("</ul>\n");
    }
    figures_section(&mut out, figures)?;
    let config = serde_json::to_string_pretty(&report.config).unwrap_or_default();
    let _ = writeln!(
        out,
        "<h2 id=\"config\">Configuration</h2>\n<p class=\"note\">Saved as a file, <code>oils run --config-from FILE</code> flies this run again (the digest <code>{}</code> comes back in lockstep).</p>\n<pre>{}</pre>",
        escape(&s.digest),
        escape(&config)
    );
    out.push_str("</body>\n</html>\n");
    let path = dir.join(PAGE);
    write_page(&path, &out)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (raw, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(raw.as_bytes()), enc, "{raw}");
        }
        assert_eq!(base64(&[0xff, 0xfe, 0xfd]), "//79");
    }

    #[test]
    fn html_is_escaped() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
    }
}
