//! `/dev/shm` is listable by every user: the names of a run's shared memory must not show
//! the domain's token (its secret), only the prefix derived from it. Lists `/dev/shm`
//! while a real run (emulator and spawned stub) is flying.

mod common;
use common::*;
use std::collections::BTreeSet;
use std::process::Stdio;
use std::time::{Duration, Instant};

fn shm_names() -> BTreeSet<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}

/// Every name under `dir`, recursively.
fn names_under(dir: &std::path::Path, out: &mut Vec<String>) {
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        out.push(e.file_name().to_string_lossy().into_owned());
        if e.file_type().map(|t| t.is_dir()).unwrap_or(false) {
            names_under(&e.path(), out);
        }
    }
}

#[test]
fn no_shared_memory_name_shows_the_domain_token() {
    let dir = scratch("shm-names");
    let root = dir.join("domain");
    let mut run = oils()
        .args(["run", "--mode", "realtime", "--duration", "3", "--no-log"])
        .env("OILS_IOX2_ROOT", &root)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Everything /dev/shm shows while the run flies.
    let mut seen = BTreeSet::new();
    let until = Instant::now() + Duration::from_secs(60);
    let status = loop {
        seen.extend(shm_names());
        if let Some(s) = run.try_wait().unwrap() {
            break s;
        }
        assert!(Instant::now() < until, "the run did not end");
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(run.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");

    let token = std::fs::read_to_string(root.join("token")).expect("the domain's token file");
    let token = token.trim();
    assert_eq!(token.len(), oils_shared::domain::TOKEN_LEN, "{token}");
    let prefix = oils_shared::domain::prefix_of(token);
    let ours: Vec<&String> = seen.iter().filter(|n| n.starts_with(&prefix)).collect();
    // The global segment and the services' segments: the listing saw the run.
    assert!(ours.len() >= 3, "only {ours:?} of {seen:?} carry {prefix}");
    let shown: Vec<&String> = seen.iter().filter(|n| n.contains(token)).collect();
    assert!(shown.is_empty(), "the token {token} is in {shown:?}");
    // Nor in the names of the domain's own (private) directory, but for its token file.
    let mut private = Vec::new();
    names_under(&root, &mut private);
    assert!(
        private.iter().all(|n| !n.contains(token)),
        "{private:?} show {token}"
    );
    for n in &ours {
        let _ = std::fs::remove_file(std::path::Path::new("/dev/shm").join(n));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
