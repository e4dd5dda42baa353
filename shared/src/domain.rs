//! The iceoryx2 domain oils runs in: a directory private to the user and a file-name
//! prefix of its own, so no other local user can read, disrupt or hang a run.
//!
//! iceoryx2's default domain (`/tmp/iceoryx2/`, files `/dev/shm/iox2_*`) is shared by
//! every user of the machine, and its global management segment is created
//! world-writable: anyone who overwrites it breaks every later node creation. oils
//! therefore puts every participant (emulator, Rust stub, Python client) in a domain of
//! its own:
//!
//! * **root path**: `$OILS_IOX2_ROOT` if set, else `$XDG_RUNTIME_DIR/oils` when the
//!   runtime directory exists and is the user's, else `/tmp/oils-<uid>`. Created with
//!   mode 0700; an existing one is refused unless it is a real directory (not a symlink)
//!   owned by the user with no group or other permission bits. iceoryx2 keeps its node
//!   and service files (monitor tokens, static service configs) under it.
//! * **token**: 12 random hex digits kept in the root's `token` file (mode 0600), the
//!   domain's secret. It never appears in a file name: `/dev/shm` is listable by every
//!   user.
//! * **prefix**: `oils_<h>_`, where `<h>` is the first 12 hex digits of the SHA-256 of
//!   `oils-iceoryx2-prefix:<token>` ([`prefix_of`]): a one-way function of the token, so
//!   the names reveal nothing of it. Every shared-memory object in `/dev/shm` carries the
//!   prefix; iceoryx2 creates them mode 0600, except the global management segment,
//!   which [`Domain::secure_global_segment`] creates 0600 itself before iceoryx2 looks for
//!   it (and repairs if it finds it wider, damaged, or taken by another user: then the
//!   domain draws a new token, and so a new prefix).
//! * Before oils derived the prefix, the token was the prefix itself, kept in a file
//!   named `prefix` ([`LEGACY_TOKEN_FILE`]), and so visible in `/dev/shm`. This version
//!   never reads that file: its token lives in `token`, drawn afresh. (The old file is
//!   left alone, so an older binary running beside this one is not disturbed.)
//!
//! Every participant must use the same domain: children inherit the environment, and a
//! client started by hand in the same login finds the same directory. `python/oils_fsw`
//! implements the same rules (docs/protocol.md, "Domain").

use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use std::ffi::CString;
use std::io::{Read, Write};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// Environment variable naming the domain's root directory.
pub const ROOT_ENV: &str = "OILS_IOX2_ROOT";
/// File in the root directory holding the domain's token.
pub const TOKEN_FILE: &str = "token";
/// Where older versions kept the token, which was then also the prefix (so it was
/// visible in `/dev/shm`): never read, its token never used.
pub const LEGACY_TOKEN_FILE: &str = "prefix";
/// Hex digits in a token.
pub const TOKEN_LEN: usize = 12;
/// Text hashed with the token into the prefix (domain separation: the prefix is a hash
/// of this use of the token only).
pub const PREFIX_CONTEXT: &str = "oils-iceoryx2-prefix:";
/// Hex digits of the hash in a prefix.
pub const PREFIX_HASH_LEN: usize = 12;
/// Where POSIX shared memory lives on Linux.
pub const SHM_DIR: &str = "/dev/shm";
/// The global management segment's name after the prefix, for iceoryx2 0.10.0: the SHA-1
/// of iceoryx2's segment type name (40 hex), `_node`, the version and the suffix. A test
/// checks that iceoryx2 creates exactly this name.
pub const GLOBAL_SEGMENT_TAIL: &str =
    "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt";
/// The global management segment's content: iceoryx2's package version (u64, 0.10.0 is
/// `0x000a_0000`), then the node counter (u32) and padding.
const GLOBAL_SEGMENT_VERSION: u64 = 10 << 16;
const GLOBAL_SEGMENT_LEN: usize = 16;

/// Why the domain cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum DomainError {
    /// The root directory (or the token file) is unsafe to use.
    #[error("iceoryx2 domain {path}: {why}; refusing it (another user could read, disrupt or hang runs). Remove it, or point {ROOT_ENV} at a directory of your own")]
    Unsafe {
        /// The offending path.
        path: PathBuf,
        /// What is wrong with it.
        why: String,
    },
    /// A file-system operation failed.
    #[error("iceoryx2 domain {path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// iceoryx2 refused the configuration (path too long, ...).
    #[error("iceoryx2 domain {root}: iceoryx2 refused the configuration: {detail}")]
    Config {
        /// The root.
        root: PathBuf,
        /// iceoryx2's error, printed.
        detail: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> DomainError + '_ {
    move |source| DomainError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn euid() -> u32 {
    // SAFETY: geteuid cannot fail and touches no memory.
    unsafe { libc::geteuid() }
}

/// An oils iceoryx2 domain: a private root directory and a prefix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Domain {
    root: PathBuf,
    token: String,
    notes: Vec<String>,
}

impl Domain {
    /// The root directory this environment selects (see the module documentation).
    pub fn default_root() -> PathBuf {
        if let Some(r) = std::env::var_os(ROOT_ENV).filter(|r| !r.is_empty()) {
            return PathBuf::from(r);
        }
        if let Some(xdg) = std::env::var_os("XDG_RUNTIME_DIR").filter(|r| !r.is_empty()) {
            let xdg = PathBuf::from(xdg);
            let ours = std::fs::symlink_metadata(&xdg)
                .map(|m| m.is_dir() && m.uid() == euid() && m.mode() & 0o077 == 0)
                .unwrap_or(false);
            if ours {
                return xdg.join("oils");
            }
        }
        PathBuf::from(format!("/tmp/oils-{}", euid()))
    }

    /// Opens (creating if need be) the domain this environment selects, and secures its
    /// global management segment.
    pub fn from_env() -> Result<Self, DomainError> {
        Self::open(&Self::default_root())
    }

    /// Opens (creating if need be) the domain rooted at `root`, and secures its global
    /// management segment.
    pub fn open(root: &Path) -> Result<Self, DomainError> {
        let root = if root.is_absolute() {
            root.to_path_buf()
        } else {
            std::env::current_dir().map_err(io(root))?.join(root)
        };
        ensure_private_dir(&root)?;
        let token = read_or_create_token(&root)?;
        let mut domain = Self {
            root,
            token,
            notes: Vec::new(),
        };
        domain.secure_global_segment()?;
        Ok(domain)
    }

    /// The root directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The prefix of every file of the domain: [`prefix_of`] its token.
    pub fn prefix(&self) -> String {
        prefix_of(&self.token)
    }

    /// What opening the domain had to repair (for the caller to report), if anything.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Path of the domain's global management segment.
    pub fn global_segment_path(&self) -> PathBuf {
        Path::new(SHM_DIR).join(format!("{}{GLOBAL_SEGMENT_TAIL}", self.prefix()))
    }

    /// The iceoryx2 configuration of the domain (dead-node cleanup on, as before).
    pub fn iceoryx2_config(&self) -> Result<Config, DomainError> {
        let bad = |detail: String| DomainError::Config {
            root: self.root.clone(),
            detail,
        };
        let mut config = Config::default();
        let mut root = self.root.as_os_str().as_bytes().to_vec();
        if root.last() != Some(&b'/') {
            root.push(b'/');
        }
        let root_path = iceoryx2::prelude::Path::new(&root).map_err(|e| bad(format!("{e:?}")))?;
        config.global.set_root_path(&root_path);
        config.global.prefix =
            FileName::new(self.prefix().as_bytes()).map_err(|e| bad(format!("{e:?}")))?;
        config.global.node.cleanup_dead_nodes_on_creation = true;
        config.global.node.cleanup_dead_nodes_on_destruction = true;
        Ok(config)
    }

    /// Makes sure the domain's global management segment exists, belongs to this user,
    /// has mode 0600 and holds what iceoryx2 wrote there:
    /// * absent: created here with mode 0600 from the start (iceoryx2 would create it
    ///   world-writable), with iceoryx2's content (version, node counter 0);
    /// * ours but wider than 0600 (made by a client that does not secure it): narrowed;
    /// * ours but damaged (another version, wrong size): removed and made again;
    /// * another user's: someone learnt the token and squats the name; the domain draws
    ///   a new token (noted in [`Domain::notes`]).
    pub fn secure_global_segment(&mut self) -> Result<(), DomainError> {
        for _ in 0..8 {
            let path = self.global_segment_path();
            match inspect_segment(&path)? {
                Segment::Good => return Ok(()),
                Segment::Absent => {
                    if create_segment(&path)? {
                        return Ok(());
                    }
                }
                Segment::Initialising => std::thread::sleep(std::time::Duration::from_millis(5)),
                Segment::Damaged(why) => {
                    self.notes
                        .push(format!("{}: {why}; made again", path.display()));
                    match std::fs::remove_file(&path) {
                        Ok(()) => {}
                        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                        Err(e) => return Err(io(&path)(e)),
                    }
                }
                Segment::Foreign(uid) => {
                    let token = new_token(&self.root)?;
                    self.notes.push(format!(
                        "{} belongs to uid {uid}, not to this user: the domain's name was taken; a new one was drawn ({})",
                        path.display(),
                        prefix_of(&token)
                    ));
                    self.token = token;
                }
            }
        }
        Err(DomainError::Unsafe {
            path: self.global_segment_path(),
            why: "the global management segment could not be secured (it keeps changing)".into(),
        })
    }
}

/// Creates `root` with mode 0700 if it does not exist, then checks it is a directory
/// (not a symlink) owned by this user with no group or other permission bits.
fn ensure_private_dir(root: &Path) -> Result<(), DomainError> {
    match std::fs::DirBuilder::new().mode(0o700).create(root) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io(root)(e)),
    }
    let unsafe_dir = |why: String| DomainError::Unsafe {
        path: root.to_path_buf(),
        why,
    };
    let meta = std::fs::symlink_metadata(root).map_err(io(root))?;
    if meta.file_type().is_symlink() {
        return Err(unsafe_dir("is a symbolic link".into()));
    }
    if !meta.is_dir() {
        return Err(unsafe_dir("is not a directory".into()));
    }
    if meta.uid() != euid() {
        return Err(unsafe_dir(format!(
            "belongs to uid {}, not to this user (uid {})",
            meta.uid(),
            euid()
        )));
    }
    if meta.mode() & 0o077 != 0 {
        return Err(unsafe_dir(format!(
            "has mode {:04o}; it must be 0700 (no group or other access)",
            meta.mode() & 0o7777
        )));
    }
    Ok(())
}

/// The file-name prefix of the domain whose token is `token`: `oils_`, the first
/// [`PREFIX_HASH_LEN`] lowercase hex digits of SHA-256(`PREFIX_CONTEXT` + token), `_`.
/// One-way: a name in `/dev/shm` does not reveal the token.
pub fn prefix_of(token: &str) -> String {
    use sha2::{Digest, Sha256};
    let digest = Sha256::new()
        .chain_update(PREFIX_CONTEXT.as_bytes())
        .chain_update(token.as_bytes())
        .finalize();
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    format!("oils_{}_", &hex[..PREFIX_HASH_LEN])
}

fn valid_token(t: &str) -> bool {
    t.len() == TOKEN_LEN
        && t.bytes()
            .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
}

fn random_token(path: &Path) -> Result<String, DomainError> {
    let mut bytes = [0u8; TOKEN_LEN / 2];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(io(Path::new("/dev/urandom")))
        .map_err(|e| match e {
            DomainError::Io { source, .. } => DomainError::Io {
                path: path.to_path_buf(),
                source,
            },
            other => other,
        })?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Writes `token` to a private temporary file in `root`, then gives it the token file's
/// name: by `link` (fails if the name exists: someone was first) or by `rename`
/// (replaces). Either way a reader never sees a half-written token.
fn publish_token(root: &Path, token: &str, replace: bool) -> Result<bool, DomainError> {
    let tmp = root.join(format!(".{TOKEN_FILE}.{}", std::process::id()));
    let target = root.join(TOKEN_FILE);
    let _ = std::fs::remove_file(&tmp);
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&tmp)
        .map_err(io(&tmp))?;
    f.write_all(format!("{token}\n").as_bytes())
        .and_then(|()| f.sync_all())
        .map_err(io(&tmp))?;
    drop(f);
    let result = if replace {
        std::fs::rename(&tmp, &target).map(|()| true)
    } else {
        match std::fs::hard_link(&tmp, &target) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(false),
            Err(e) => Err(e),
        }
    };
    let _ = std::fs::remove_file(&tmp);
    result.map_err(io(&target))
}

fn read_or_create_token(root: &Path) -> Result<String, DomainError> {
    let path = root.join(TOKEN_FILE);
    for _ in 0..2 {
        match std::fs::read_to_string(&path) {
            Ok(text) => {
                let meta = std::fs::symlink_metadata(&path).map_err(io(&path))?;
                let token = text.trim();
                if !meta.is_file() || meta.uid() != euid() || !valid_token(token) {
                    return Err(DomainError::Unsafe {
                        path,
                        why: format!(
                            "is not a token file of this user ({TOKEN_LEN} lowercase hex digits)"
                        ),
                    });
                }
                return Ok(token.to_string());
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                let token = random_token(&path)?;
                if publish_token(root, &token, false)? {
                    return Ok(token);
                }
                // Another process of ours published first: read theirs.
            }
            Err(e) => return Err(io(&path)(e)),
        }
    }
    Err(DomainError::Unsafe {
        path,
        why: "the token file could not be read or created".into(),
    })
}

fn new_token(root: &Path) -> Result<String, DomainError> {
    let token = random_token(&root.join(TOKEN_FILE))?;
    publish_token(root, &token, true)?;
    Ok(token)
}

enum Segment {
    Good,
    Absent,
    /// Being created by another process (still write-only): wait.
    Initialising,
    Damaged(String),
    Foreign(u32),
}

fn inspect_segment(path: &Path) -> Result<Segment, DomainError> {
    let meta = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Segment::Absent),
        Err(e) => return Err(io(path)(e)),
    };
    if meta.uid() != euid() {
        return Ok(Segment::Foreign(meta.uid()));
    }
    if !meta.is_file() {
        return Ok(Segment::Damaged("not a regular file".into()));
    }
    let mode = meta.mode() & 0o777;
    if mode & 0o400 == 0 && meta.len() <= GLOBAL_SEGMENT_LEN as u64 {
        // iceoryx2's (or our) creation protocol: write-only until initialised.
        if meta.modified().ok().and_then(|m| m.elapsed().ok())
            < Some(std::time::Duration::from_secs(2))
        {
            return Ok(Segment::Initialising);
        }
        return Ok(Segment::Damaged(format!(
            "left unfinished with mode {mode:04o}"
        )));
    }
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)
        .map_err(io(path))?;
    if mode != 0o600 {
        // Narrow before reading: from here on nobody else can open it.
        f.set_permissions(std::fs::Permissions::from_mode(0o600))
            .map_err(io(path))?;
    }
    let mut bytes = Vec::with_capacity(GLOBAL_SEGMENT_LEN);
    f.read_to_end(&mut bytes).map_err(io(path))?;
    if bytes.len() != GLOBAL_SEGMENT_LEN {
        return Ok(Segment::Damaged(format!(
            "{} bytes instead of {GLOBAL_SEGMENT_LEN}",
            bytes.len()
        )));
    }
    let version = u64::from_ne_bytes(bytes[..8].try_into().unwrap_or([0; 8]));
    if version != GLOBAL_SEGMENT_VERSION {
        return Ok(Segment::Damaged(format!(
            "version word {version:#x}, not iceoryx2 0.10.0's"
        )));
    }
    Ok(Segment::Good)
}

/// Creates the segment exclusively, write-only while it is filled (iceoryx2's own
/// protocol: openers wait for the read bit), then 0600. `false` if it already existed.
fn create_segment(path: &Path) -> Result<bool, DomainError> {
    let c_path = CString::new(path.as_os_str().as_bytes()).map_err(|_| DomainError::Unsafe {
        path: path.to_path_buf(),
        why: "contains a NUL byte".into(),
    })?;
    // SAFETY: a valid C string; the returned descriptor is owned below.
    let fd = unsafe {
        libc::open(
            c_path.as_ptr(),
            libc::O_RDWR | libc::O_CREAT | libc::O_EXCL | libc::O_NOFOLLOW | libc::O_CLOEXEC,
            0o200 as libc::c_uint,
        )
    };
    if fd < 0 {
        let e = std::io::Error::last_os_error();
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            return Ok(false);
        }
        return Err(io(path)(e));
    }
    // SAFETY: fd is a fresh descriptor that nothing else owns.
    let mut f = unsafe { <std::fs::File as std::os::fd::FromRawFd>::from_raw_fd(fd) };
    let mut content = [0u8; GLOBAL_SEGMENT_LEN];
    content[..8].copy_from_slice(&GLOBAL_SEGMENT_VERSION.to_ne_bytes());
    f.write_all(&content)
        .and_then(|()| f.set_permissions(std::fs::Permissions::from_mode(0o600)))
        .map_err(io(path))?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("oils-domain-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn the_prefix_is_a_hash_of_the_token_never_the_token() {
        // The documented derivation (docs/protocol.md, "Domain"; Python's hashlib agrees).
        assert_eq!(prefix_of("0123456789ab"), "oils_c15e6d5b3339_");
        let dir = scratch("prefix");
        let root = dir.join("domain");
        let d = Domain::open(&root).unwrap();
        let token = std::fs::read_to_string(root.join(TOKEN_FILE)).unwrap();
        let token = token.trim();
        assert!(valid_token(token), "{token}");
        assert_eq!(d.prefix(), prefix_of(token));
        assert!(!d.prefix().contains(token));
        let seg = d.global_segment_path();
        assert!(!seg.to_string_lossy().contains(token), "{}", seg.display());
        std::fs::remove_file(&seg).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_old_token_file_is_never_used() {
        let dir = scratch("legacy");
        let root = dir.join("domain");
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&root)
            .unwrap();
        // The old layout: the token, which was also the prefix, in `prefix`.
        std::fs::write(root.join(LEGACY_TOKEN_FILE), "0123456789ab\n").unwrap();
        let d = Domain::open(&root).unwrap();
        assert_ne!(d.token, "0123456789ab");
        assert_ne!(d.prefix(), prefix_of("0123456789ab"));
        std::fs::remove_file(d.global_segment_path()).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn refuses_a_directory_others_can_enter() {
        let dir = scratch("wide");
        let root = dir.join("domain");
        std::fs::create_dir(&root).unwrap();
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o755)).unwrap();
        let err = Domain::open(&root).unwrap_err().to_string();
        assert!(
            err.contains("mode 0755") && err.contains("refusing"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn refuses_a_symlink_and_a_bad_token() {
        let dir = scratch("link");
        let real = dir.join("real");
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&real)
            .unwrap();
        let link = dir.join("link");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let err = Domain::open(&link).unwrap_err().to_string();
        assert!(err.contains("symbolic link"), "{err}");
        std::fs::write(real.join(TOKEN_FILE), "not-hex\n").unwrap();
        let err = Domain::open(&real).unwrap_err().to_string();
        assert!(err.contains("token file"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn creates_a_private_root_a_token_and_a_0600_global_segment_and_repairs_it() {
        let dir = scratch("fresh");
        let root = dir.join("domain");
        let mut d = Domain::open(&root).unwrap();
        let meta = std::fs::metadata(&root).unwrap();
        assert_eq!(meta.mode() & 0o777, 0o700);
        assert!(valid_token(&d.token));
        assert_eq!(
            Domain::open(&root).unwrap().prefix(),
            d.prefix(),
            "token is kept"
        );
        let seg = d.global_segment_path();
        assert_eq!(std::fs::metadata(&seg).unwrap().mode() & 0o777, 0o600);
        // A node of the domain uses exactly this segment (and finds it good).
        let node = NodeBuilder::new()
            .config(&d.iceoryx2_config().unwrap())
            .create::<ipc::Service>()
            .unwrap();
        drop(node);
        assert_eq!(std::fs::metadata(&seg).unwrap().mode() & 0o777, 0o600);
        let bytes = std::fs::read(&seg).unwrap();
        assert_eq!(bytes.len(), GLOBAL_SEGMENT_LEN);
        assert_ne!(
            bytes[8..12],
            [0, 0, 0, 0],
            "iceoryx2 counted its node in our segment"
        );
        // Damaged and widened: made again, 0600, and noted.
        std::fs::set_permissions(&seg, std::fs::Permissions::from_mode(0o666)).unwrap();
        std::fs::write(&seg, b"garbage garbage!").unwrap();
        d.secure_global_segment().unwrap();
        assert!(
            d.notes().iter().any(|n| n.contains("made again")),
            "{:?}",
            d.notes()
        );
        assert_eq!(std::fs::metadata(&seg).unwrap().mode() & 0o777, 0o600);
        NodeBuilder::new()
            .config(&d.iceoryx2_config().unwrap())
            .create::<ipc::Service>()
            .unwrap();
        std::fs::remove_file(&seg).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
