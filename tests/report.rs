//! What a GNC engineer reads, with the real `oils` binary: a campaign where one
//! dispersion is made to cause the failures names it first in `summary.json`'s
//! `drivers`; `oils mc report DIR` and `oils run --plots DIR` write one self-contained
//! page with every figure. The page in a real browser (headless Chromium: every figure
//! loads, no console error, a screenshot) is `#[ignore]`d here and run by
//! `tools/report-e2e.sh` in `.ci/run`, which installs Chromium.

mod common;

use common::{run_oils, scratch, text};
use std::path::{Path, PathBuf};

/// Ideal propulsion, no faults; `landing_limit` sets the vertical touchdown limit
/// around the speed the GNC lands at (0.93 m/s), so a case fails exactly when its draw
/// is below that; altitude, dry mass and navigation noise are dispersed alongside and
/// cause nothing.
const SPEC: &str = r#"
name = "made-to-fail"
cases = 24
seed = 11
[base]
propulsion = "ideal"
[[dispersion]]
name = "altitude_m"
targets = ["scenario.initial.altitude_m"]
dist = { kind = "normal", mean = 0.0, std = 100.0 }
[[dispersion]]
name = "landing_limit"
targets = ["scenario.touchdown.vertical_speed_mps"]
apply = "set"
dist = { kind = "uniform", min = 0.6, max = 1.3 }
[[dispersion]]
name = "dry_mass_kg"
targets = ["scenario.lander.dry_mass_kg"]
dist = { kind = "normal", mean = 0.0, std = 5.0 }
[[dispersion]]
name = "nav_noise_scale"
targets = ["scenario.nav_noise.position_m"]
apply = "scale"
dist = { kind = "uniform", min = 0.8, max = 1.2 }
[requirements]
footprint_m = [4000.0, 2400.0]
"#;

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Runs the made-to-fail campaign into `dir/c` with its figures and page.
fn made_to_fail(dir: &Path) -> PathBuf {
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, SPEC).unwrap();
    let out = dir.join("c");
    let o = run_oils(&[
        "mc",
        "run",
        "--spec",
        spec.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    out
}

/// The figure files a page should embed: every PNG in `plots`.
fn pngs(plots: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(plots)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    v.sort();
    v
}

fn assert_self_contained(html: &str, figures: usize) {
    assert_eq!(
        html.matches("<img ").count(),
        figures,
        "one <img> per figure"
    );
    assert_eq!(
        html.matches("src=\"data:image/png;base64,").count(),
        figures,
        "every figure embedded"
    );
    for outside in ["http://", "https://", "src=\"/", "href=\"/", "<link"] {
        assert!(
            !html.contains(outside),
            "the page refers outside: {outside}"
        );
    }
}

#[test]
fn the_dispersion_made_to_cause_the_failures_comes_out_on_top_and_the_page_has_it() {
    let dir = scratch("report-drivers");
    let c = made_to_fail(&dir);
    let summary: serde_json::Value = serde_json::from_str(&read(&c.join("summary.json"))).unwrap();
    let failed = summary["failure_count"].as_u64().unwrap();
    assert!(
        (3..=21).contains(&failed),
        "the limit's draws should fail some cases and land others: {failed}"
    );
    let drivers = summary["drivers"]
        .as_array()
        .expect("summary.json has drivers");
    assert_eq!(drivers[0]["name"], "landing_limit", "{drivers:#?}");
    // A lower limit, more failures.
    assert!(
        drivers[0]["failure_rho"].as_f64().unwrap() < -0.6,
        "{drivers:#?}"
    );
    assert!(drivers[0]["failure_p"].as_f64().unwrap() < 0.01);
    for d in &drivers[1..] {
        assert!(
            d["failure_rho"].as_f64().unwrap().abs() < 0.6,
            "a dispersion that causes nothing: {d}"
        );
    }

    // The page at the top of the campaign directory, with every figure.
    let figures = pngs(&c.join("plots"));
    assert_eq!(figures.len(), 7, "{figures:?}");
    let page = c.join("report.html");
    let html = read(&page);
    assert_self_contained(&html, figures.len());
    assert!(html.contains("landing_limit"));
    assert!(html.contains(&format!("oils mc case {} --index", c.display())));
    assert!(html.contains("[requirements]"), "the spec is on the page");

    // `oils mc report DIR` writes it again, the same.
    std::fs::remove_file(&page).unwrap();
    let o = run_oils(&["mc", "report", c.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(read(&page), html);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_with_plots_gets_its_page_with_every_figure_and_its_configuration() {
    let dir = scratch("report-run");
    let plots = dir.join("plots");
    let o = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--propulsion",
        "ideal",
        "--log",
        dir.join("run.oilslog").to_str().unwrap(),
        "--plots",
        plots.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let figures = pngs(&plots);
    assert_eq!(figures.len(), 8, "{figures:?}");
    for f in ["timing.png", "timing-timeline.png"] {
        assert!(plots.join(f).exists(), "{f}");
    }
    let html = read(&plots.join("report.html"));
    assert_self_contained(&html, figures.len());
    assert!(html.contains("--config-from"));
    assert!(html.contains("&quot;propulsion&quot;: &quot;ideal&quot;"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The attribute `name` of the element with id `page-check` in a dumped DOM.
fn check_attr<'a>(dom: &'a str, name: &str) -> Option<&'a str> {
    let at = dom.find("id=\"page-check\"")?;
    let start = dom[..at].rfind('<')?;
    let tag = &dom[start..start + dom[start..].find('>')?];
    let key = format!("{name}=\"");
    let i = tag.find(&key)? + key.len();
    Some(&tag[i..i + tag[i..].find('"')?])
}

#[test]
fn check_attributes_are_read_from_a_dumped_dom() {
    let dom = "<body><div id=\"page-check\" hidden=\"\" data-images=\"7\" data-failed=\"0\" data-done=\"yes\">x</div>";
    assert_eq!(check_attr(dom, "data-images"), Some("7"));
    assert_eq!(check_attr(dom, "data-done"), Some("yes"));
    assert_eq!(check_attr(dom, "data-errors"), None);
}

/// Headless Chromium on `page`: the DOM after load (stdout) and the browser's log
/// (stderr, where console messages go with --enable-logging).
fn chromium(browser: &str, page: &Path, extra: &[&str]) -> std::process::Output {
    let profile = scratch(&format!("chromium-{}", extra.len()));
    let o = std::process::Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=10000",
            &format!("--user-data-dir={}", profile.display()),
        ])
        .args(extra)
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap_or_else(|e| panic!("starting {browser}: {e}"));
    let _ = std::fs::remove_dir_all(&profile);
    o
}

fn browser_check(browser: &str, page: &Path, figures: usize, screenshot: &Path) {
    let o = chromium(browser, page, &["--dump-dom"]);
    assert!(o.status.success(), "{}", text(&o));
    let dom = String::from_utf8_lossy(&o.stdout);
    let log = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        check_attr(&dom, "data-done"),
        Some("yes"),
        "the page's check ran:\n{log}"
    );
    assert_eq!(
        check_attr(&dom, "data-images"),
        Some(figures.to_string().as_str())
    );
    assert_eq!(
        check_attr(&dom, "data-failed"),
        Some("0"),
        "every figure loads"
    );
    assert_eq!(
        check_attr(&dom, "data-errors"),
        Some("0"),
        "no error in the page:\n{dom}"
    );
    assert_eq!(dom.matches("data-loaded=\"yes\"").count(), figures);
    let console: Vec<&str> = log.lines().filter(|l| l.contains("CONSOLE")).collect();
    assert!(console.is_empty(), "console messages: {console:#?}");
    let o = chromium(
        browser,
        page,
        &[
            &format!("--screenshot={}", screenshot.display()),
            "--window-size=1300,3000",
            "--hide-scrollbars",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let png = std::fs::read(screenshot).unwrap_or_else(|e| panic!("{}: {e}", screenshot.display()));
    assert_eq!(&png[1..4], b"PNG");
    assert!(
        png.len() > 50_000,
        "a screenshot of a page, not a blank: {} bytes",
        png.len()
    );
}

/// The check itself can fail: the same page with one figure's data broken reports it.
fn broken_page_is_caught(browser: &str, page: &Path) {
    let html = read(page);
    let broken = html.replacen("data:image/png;base64,", "data:image/png;base64,AAAA", 1);
    let copy = page.with_file_name("broken.html");
    std::fs::write(&copy, broken).unwrap();
    let o = chromium(browser, &copy, &["--dump-dom"]);
    let dom = String::from_utf8_lossy(&o.stdout);
    assert_eq!(check_attr(&dom, "data-failed"), Some("1"), "{}", text(&o));
    assert_ne!(check_attr(&dom, "data-errors"), Some("0"));
    std::fs::remove_file(&copy).unwrap();
}

#[test]
#[ignore = "needs Chromium: tools/report-e2e.sh installs it and runs this with OILS_CHROMIUM"]
fn the_pages_load_in_a_real_browser_with_every_figure_and_no_console_error() {
    let browser = std::env::var("OILS_CHROMIUM")
        .expect("OILS_CHROMIUM: the Chromium binary (tools/report-e2e.sh sets it)");
    let shots = PathBuf::from(
        std::env::var("OILS_SCREENSHOTS").unwrap_or_else(|_| "target/report-e2e".into()),
    );
    std::fs::create_dir_all(&shots).unwrap();
    let dir = scratch("report-browser");
    let c = made_to_fail(&dir);
    let figures = pngs(&c.join("plots")).len();
    browser_check(
        &browser,
        &c.join("report.html"),
        figures,
        &shots.join("campaign.png"),
    );
    broken_page_is_caught(&browser, &c.join("report.html"));

    let plots = dir.join("run");
    let o = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--propulsion",
        "ideal",
        "--log",
        dir.join("run.oilslog").to_str().unwrap(),
        "--plots",
        plots.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let figures = pngs(&plots).len();
    browser_check(
        &browser,
        &plots.join("report.html"),
        figures,
        &shots.join("run.png"),
    );
    eprintln!("screenshots in {}", shots.display());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue #57: a lander sliding down a 45 deg slope was reported as `slope`, with no word
/// that it slid. The report now says `slid`, how far and how fast, in the printed
/// outcome and the JSON, beside the limits it was judged against.
#[test]
fn a_run_that_slid_says_how_far_and_how_fast() {
    let dir = scratch("report-slid");
    let scenario = dir.join("slope.toml");
    std::fs::write(
        &scenario,
        "[propulsion]\npropellant_kg = 300.0\n[initial]\nrange_to_site_m = 0.0\n\
         altitude_m = 2000.0\nhorizontal_speed_m_s = 0.0\nvertical_speed_m_s = -10.0\n\
         thrust_pitch_deg = 90.0\n[terrain]\nkind = \"synthetic\"\nextent_m = 400.0\n\
         spacing_m = 2.0\ncrater_density = 0.0\nregional_slope_deg = 45.0\n",
    )
    .unwrap();
    let json = dir.join("r.json");
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--propulsion",
        "ideal",
        "--no-log",
        "--scenario",
        scenario.to_str().unwrap(),
        "--report",
        json.to_str().unwrap(),
    ]);
    assert!(
        !out.status.success(),
        "a crash exits non-zero: {}",
        text(&out)
    );
    let r: serde_json::Value = serde_json::from_str(&read(&json)).unwrap();
    let td = &r["touchdown"];
    assert_eq!(td["reason"], "slid", "{td}");
    let slide_m = td["slide_m"].as_f64().unwrap();
    let speed_m_s = td["slide_speed_m_s"].as_f64().unwrap();
    // Down 45 deg for the 20 s settling limit at g (sin 45 - 0.6 cos 45) = 0.46 m/s^2.
    assert!(slide_m > 50.0 && speed_m_s > 5.0, "{td}");
    assert!(td["slope_deg"].as_f64().unwrap() > td["slope_limit_deg"].as_f64().unwrap());
    assert_eq!(td["leg_crush_m"].as_array().unwrap().len(), 4, "{td}");
    let line = format!("CRASHED (slid: {slide_m:.2} m, up to {speed_m_s:.2} m/s)");
    assert!(text(&out).contains(&line), "{line} not in {}", text(&out));
    let _ = std::fs::remove_dir_all(&dir);
}
