//! Issue #36: a campaign's merge trusts no file name, two runs on one campaign cannot
//! both run it, and a campaign that flew nothing is not a success. The real `oils`
//! binary on small campaigns of the ideal model.

mod common;

use common::{oils, run_oils, scratch, text};
use std::path::Path;

const SMALL: [&str; 8] = [
    "--cases",
    "4",
    "--seed",
    "9",
    "--propulsion",
    "ideal",
    "--jobs",
    "1",
];

fn mc_run(dir: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["mc", "run", "--out", dir.to_str().unwrap(), "--no-plots"];
    args.extend_from_slice(extra);
    run_oils(&args)
}

fn merge(dir: &Path) -> std::process::Output {
    run_oils(&["mc", "merge", dir.to_str().unwrap(), "--no-plots"])
}

fn case(dir: &Path, i: u64) -> std::path::PathBuf {
    dir.join("cases").join(format!("{i:07}.json"))
}

/// A case file copied over another merged as that case twice (`"cases": 40` with one
/// missing); an edited value merged silently; a case of another campaign too. Each is
/// now refused by name.
#[test]
fn a_merge_refuses_copied_edited_or_foreign_case_files() {
    let dir = scratch("mc-integrity");
    let o = mc_run(&dir, &SMALL);
    assert!(o.status.success(), "{}", text(&o));
    assert!(merge(&dir).status.success());
    let original = std::fs::read(case(&dir, 2)).unwrap();

    // Case 1 copied over case 2.
    std::fs::copy(case(&dir, 1), case(&dir, 2)).unwrap();
    let o = merge(&dir);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("holds case 1, not case 2"),
        "{}",
        text(&o)
    );

    // A value edited in place.
    let edited =
        String::from_utf8(original.clone())
            .unwrap()
            .replacen("\"seed\":", "\"seed\":1", 1);
    std::fs::write(case(&dir, 2), edited).unwrap();
    let o = merge(&dir);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("does not match its BLAKE3"),
        "{}",
        text(&o)
    );

    // The same case of another campaign (another seed).
    let other = scratch("mc-integrity-other");
    let mut args = SMALL;
    args[3] = "10";
    assert!(mc_run(&other, &args).status.success());
    std::fs::copy(case(&other, 2), case(&dir, 2)).unwrap();
    let o = merge(&dir);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("a case of another campaign"),
        "{}",
        text(&o)
    );

    // A missing case is named.
    std::fs::remove_file(case(&dir, 2)).unwrap();
    let o = merge(&dir);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("(first: 2)"), "{}", text(&o));

    // Restored, it merges again.
    std::fs::write(case(&dir, 2), original).unwrap();
    assert!(merge(&dir).status.success());
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&other);
}

/// Two `oils mc run` on one `--out` both ran every case. Now the second fails at once,
/// naming the first one's pid.
#[test]
fn a_second_run_on_one_campaign_fails_at_once_naming_the_holder() {
    let dir = scratch("mc-lock");
    let mut first = oils()
        .args(["mc", "run", "--out", dir.to_str().unwrap(), "--no-plots"])
        .args(["--cases", "40", "--propulsion", "ideal", "--jobs", "1"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lock = dir.join(".lock");
    while !std::fs::read_to_string(&lock).is_ok_and(|s| s.ends_with('\n')) {
        assert!(first.try_wait().unwrap().is_none(), "the first run ended");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let o = mc_run(&dir, &["--cases", "40", "--propulsion", "ideal"]);
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(first.id() as i32, libc::SIGINT) };
    let _ = first.wait();
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains(&format!("another `oils mc run` (pid {}", first.id())),
        "{}",
        text(&o)
    );
    assert!(!text(&o).contains("cases run"), "{}", text(&o));
    // Shards lock their own shard: two shards run side by side.
    let a = mc_run(
        &dir,
        &["--cases", "40", "--propulsion", "ideal", "--shard", "0/20"],
    );
    assert!(a.status.success(), "{}", text(&a));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A campaign whose every case is `invalid` exited 0.
#[test]
fn a_campaign_whose_every_case_is_invalid_fails() {
    let dir = scratch("mc-all-invalid");
    let spec = dir.join("invalid.toml");
    std::fs::write(
        &spec,
        "cases = 3\nseed = 1\n[base]\npropulsion = \"ideal\"\n[[dispersion]]\nname = \"dt\"\ntargets = [\"dt_ms\"]\ndist = { kind = \"normal\", mean = 500.0, std = 0.01 }\n",
    )
    .unwrap();
    let o = mc_run(&dir.join("c"), &["--spec", spec.to_str().unwrap()]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("every one of the 3 cases is invalid"),
        "{}",
        text(&o)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
