//! Subcommands of the `oils` binary.

pub mod excitation;
pub mod export_fmu;
pub mod hifi;
pub mod map;
pub mod mc;
pub mod plot;
pub mod run;
pub mod stub;
pub mod stub_process;
pub mod train;
pub mod validate;

/// Whether two paths name the same file: the same inode when both exist, else the same
/// canonical folder and file name (an output not yet written). Hand-written over
/// `same-file` because an output that does not exist yet must compare too.
pub fn same_file(a: &std::path::Path, b: &std::path::Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
        return ma.dev() == mb.dev() && ma.ino() == mb.ino();
    }
    let canonical = |p: &std::path::Path| {
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => std::path::Path::new("."),
        };
        Some((std::fs::canonicalize(dir).ok()?, p.file_name()?.to_owned()))
    };
    match (canonical(a), canonical(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// Refuses a set of named paths where two name the same file (an output that would
/// overwrite the input it is made from, or another output).
pub fn refuse_aliases(paths: &[(&str, &std::path::Path)]) -> anyhow::Result<()> {
    for (i, (na, pa)) in paths.iter().enumerate() {
        for (nb, pb) in &paths[i + 1..] {
            if same_file(pa, pb) {
                anyhow::bail!(
                    "{na} and {nb} name the same file ({}): one would overwrite the other; give them different paths",
                    pb.display()
                );
            }
        }
    }
    Ok(())
}
