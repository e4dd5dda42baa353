//! One build for tests and runs: every dependency `cargo run --release` builds has the
//! features `cargo test --workspace --release` builds it with, so the README's second
//! command reuses the first's artefacts instead of compiling rayon, the lab and the
//! binary again. Reads the feature sets from `cargo tree` (the lock file, offline).

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

/// Package (`name vX.Y.Z`) to the feature sets it is built with, as `cargo tree` lists
/// them for `args`.
fn feature_sets(args: &[&str]) -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "tree",
            "--offline",
            "--locked",
            "--prefix",
            "none",
            "-f",
            "{p}|{f}",
        ])
        .args(args)
        .output()
        .expect("running cargo tree");
    assert!(
        out.status.success(),
        "cargo tree {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut sets: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let line = line.trim_end_matches(" (*)");
        if let Some((package, features)) = line.split_once('|') {
            // A path dependency's name carries its directory: the name and version suffice.
            let package = package.split(" (").next().unwrap_or(package).to_string();
            sets.entry(package)
                .or_default()
                .insert(features.to_string());
        }
    }
    sets
}

#[test]
fn the_run_build_is_part_of_the_test_build() {
    let run = feature_sets(&["-p", "oils", "-e", "normal,build"]);
    let test = feature_sets(&["--workspace", "-e", "normal,build,dev"]);
    assert!(
        run.len() > 100,
        "{} packages: cargo tree said too little",
        run.len()
    );
    let differ: Vec<String> = run
        .iter()
        .filter(|(p, sets)| test.get(*p).is_none_or(|t| !sets.is_subset(t)))
        .map(|(p, sets)| format!("{p}: run {sets:?}, test {:?}", test.get(p)))
        .collect();
    assert!(
        differ.is_empty(),
        "built with other features by `cargo run --release` than by the tests: {differ:#?}"
    );
}
