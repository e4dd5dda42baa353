"""The oils iceoryx2 domain: the same rules as ``oils_shared::domain`` (docs/protocol.md,
"Domain"), so a Python client meets the emulator in the user's private domain.

* root: ``$OILS_IOX2_ROOT``, else ``$XDG_RUNTIME_DIR/oils`` when that runtime directory is
  the user's (mode 0700), else ``/tmp/oils-<uid>``; created 0700, refused unless a real
  directory owned by the user with no group or other bits;
* token: 12 lowercase hex digits read from ``<root>/token`` (created 0600 if absent), the
  domain's secret, never part of a file name;
* prefix: ``oils_<h>_``, ``<h>`` the first 12 hex digits of SHA-256 of
  ``oils-iceoryx2-prefix:<token>`` (``prefix_of``), so /dev/shm names do not reveal the
  token;
* the global management segment ``/dev/shm/<prefix>GLOBAL_SEGMENT_TAIL`` is made 0600
  before iceoryx2 looks for it (iceoryx2 would create it world-writable).
"""

import hashlib
import os
import secrets
import stat
import struct
import time

import iceoryx2 as iox2

ROOT_ENV = "OILS_IOX2_ROOT"
TOKEN_FILE = "token"
TOKEN_LEN = 12
PREFIX_CONTEXT = "oils-iceoryx2-prefix:"
PREFIX_HASH_LEN = 12
SHM_DIR = "/dev/shm"
# iceoryx2 0.10.0: SHA-1 of the segment's type name, "_node", version, suffix.
GLOBAL_SEGMENT_TAIL = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt"
GLOBAL_SEGMENT_VERSION = 10 << 16  # iceoryx2's package version 0.10.0 as a u64
GLOBAL_SEGMENT_LEN = 16


class DomainError(RuntimeError):
    """The domain directory or its files are unsafe or unusable."""


def prefix_of(token: str) -> str:
    """The file-name prefix of the domain whose token is ``token`` (one-way)."""
    digest = hashlib.sha256((PREFIX_CONTEXT + token).encode()).hexdigest()
    return f"oils_{digest[:PREFIX_HASH_LEN]}_"


def default_root() -> str:
    root = os.environ.get(ROOT_ENV)
    if root:
        return root
    xdg = os.environ.get("XDG_RUNTIME_DIR")
    if xdg:
        try:
            st = os.lstat(xdg)
            if stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and st.st_mode & 0o077 == 0:
                return os.path.join(xdg, "oils")
        except OSError:
            pass
    return f"/tmp/oils-{os.geteuid()}"


def _refuse(path: str, why: str) -> DomainError:
    return DomainError(
        f"iceoryx2 domain {path}: {why}; refusing it (another user could read, disrupt or "
        f"hang runs). Remove it, or point {ROOT_ENV} at a directory of your own"
    )


def _ensure_private_dir(root: str) -> None:
    try:
        os.mkdir(root, 0o700)
    except FileExistsError:
        pass
    st = os.lstat(root)
    if stat.S_ISLNK(st.st_mode):
        raise _refuse(root, "is a symbolic link")
    if not stat.S_ISDIR(st.st_mode):
        raise _refuse(root, "is not a directory")
    if st.st_uid != os.geteuid():
        raise _refuse(root, f"belongs to uid {st.st_uid}, not to this user (uid {os.geteuid()})")
    if st.st_mode & 0o077:
        raise _refuse(root, f"has mode {st.st_mode & 0o7777:04o}; it must be 0700 (no group or other access)")


def _valid(token: str) -> bool:
    return len(token) == TOKEN_LEN and all(c in "0123456789abcdef" for c in token)


def _publish_token(root: str, token: str, replace: bool) -> bool:
    tmp = os.path.join(root, f".{TOKEN_FILE}.{os.getpid()}")
    target = os.path.join(root, TOKEN_FILE)
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    try:
        if replace:
            os.rename(tmp, target)
            return True
        try:
            os.link(tmp, target)
            return True
        except FileExistsError:
            return False
    finally:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass


def _token(root: str) -> str:
    path = os.path.join(root, TOKEN_FILE)
    for _ in range(2):
        try:
            with open(path) as f:
                token = f.read().strip()
        except FileNotFoundError:
            token = secrets.token_hex(TOKEN_LEN // 2)
            if _publish_token(root, token, replace=False):
                return token
            continue
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_uid != os.geteuid() or not _valid(token):
            raise _refuse(path, f"is not a token file of this user ({TOKEN_LEN} lowercase hex digits)")
        return token
    raise _refuse(path, "the token file could not be read or created")


def _secure_global_segment(root: str, token: str) -> str:
    """Returns the token to use (a new one if the segment's name was taken)."""
    for _ in range(8):
        path = os.path.join(SHM_DIR, prefix_of(token) + GLOBAL_SEGMENT_TAIL)
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o200)
            except FileExistsError:
                continue
            try:
                os.write(fd, struct.pack("=QQ", GLOBAL_SEGMENT_VERSION, 0))
                os.fchmod(fd, 0o600)
            finally:
                os.close(fd)
            return token
        if st.st_uid != os.geteuid():
            token = secrets.token_hex(TOKEN_LEN // 2)
            _publish_token(root, token, replace=True)
            continue
        mode = st.st_mode & 0o777
        if mode & 0o400 == 0 and st.st_size <= GLOBAL_SEGMENT_LEN and time.time() - st.st_mtime < 2:
            time.sleep(0.005)  # being created by another process
            continue
        damaged = not stat.S_ISREG(st.st_mode) or mode & 0o400 == 0
        if not damaged:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
            try:
                if mode != 0o600:
                    os.fchmod(fd, 0o600)
                data = os.read(fd, GLOBAL_SEGMENT_LEN + 1)
            finally:
                os.close(fd)
            damaged = len(data) != GLOBAL_SEGMENT_LEN or struct.unpack("=Q", data[:8])[0] != GLOBAL_SEGMENT_VERSION
        if not damaged:
            return token
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
    raise _refuse(path, "the global management segment could not be secured (it keeps changing)")


def open_domain(root: str = None) -> "tuple[str, str]":
    """Opens (creating and securing) the oils domain: its root path, as iceoryx2 gets it
    (absolute, ending in ``/``), and its prefix. ``root`` defaults to ``default_root()``."""
    root = os.path.abspath(root or default_root())
    _ensure_private_dir(root)
    token = _secure_global_segment(root, _token(root))
    return root.rstrip("/") + "/", prefix_of(token)


def config(root: str = None) -> "iox2.config.Config":
    """The iceoryx2 configuration of the oils domain (creating and securing it)."""
    root_path, prefix = open_domain(root)
    cfg = iox2.config.default()
    cfg.global_cfg.prefix = iox2.FileName.new(prefix)
    cfg.global_cfg.root_path = iox2.Path.new(root_path)
    cfg.global_cfg.node.cleanup_dead_nodes_on_creation = True
    cfg.global_cfg.node.cleanup_dead_nodes_on_destruction = True
    return cfg
