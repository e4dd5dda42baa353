"""The Python client's iceoryx2 domain follows oils_shared::domain's rules.

``test_same_domain_as_rust`` needs OILS_DOMAIN_BIN (the `domain_json` example of
oils-shared, which opens the domain as every Rust participant does); tools/python-e2e.sh
sets it.
"""

import glob
import json
import os
import re
import stat
import subprocess
import tempfile
import unittest

from oils_fsw import domain

RUST_DOMAIN = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "src", "domain.rs")


def remove_segments(prefix: str) -> None:
    for f in glob.glob(os.path.join(domain.SHM_DIR, prefix + "*")):
        os.unlink(f)


class DomainTest(unittest.TestCase):
    def test_same_constants_as_rust(self):
        with open(RUST_DOMAIN) as f:
            rust = f.read()
        tail = re.search(r'GLOBAL_SEGMENT_TAIL: &str =\s*"([^"]+)"', rust).group(1)
        self.assertEqual(domain.GLOBAL_SEGMENT_TAIL, tail)
        self.assertIn(f"TOKEN_LEN: usize = {domain.TOKEN_LEN};", rust)
        self.assertIn(f'TOKEN_FILE: &str = "{domain.TOKEN_FILE}";', rust)
        self.assertIn(f'PREFIX_CONTEXT: &str = "{domain.PREFIX_CONTEXT}";', rust)
        self.assertIn(f"PREFIX_HASH_LEN: usize = {domain.PREFIX_HASH_LEN};", rust)
        # The Rust unit test pins the same vector.
        self.assertEqual(domain.prefix_of("0123456789ab"), "oils_c15e6d5b3339_")
        self.assertIn('prefix_of("0123456789ab"), "oils_c15e6d5b3339_"', rust)

    def test_same_domain_as_rust(self):
        """Rust and Python, given the same environment, open the same root and prefix."""
        rust_bin = os.environ["OILS_DOMAIN_BIN"]

        def rust(env):
            out = subprocess.run([rust_bin], env=env, capture_output=True, text=True, check=True)
            got = json.loads(out.stdout)
            return got["root"].rstrip("/") + "/", got["prefix"]

        def python(env):
            saved = dict(os.environ)
            os.environ.clear()
            os.environ.update(env)
            try:
                return domain.open_domain()
            finally:
                os.environ.clear()
                os.environ.update(saved)

        base = {k: v for k, v in os.environ.items() if k not in (domain.ROOT_ENV, "XDG_RUNTIME_DIR")}
        with tempfile.TemporaryDirectory() as tmp:
            xdg = os.path.join(tmp, "xdg")
            os.mkdir(xdg, 0o700)
            wide = os.path.join(tmp, "wide")
            os.mkdir(wide)
            os.chmod(wide, 0o755)
            cases = {
                "OILS_IOX2_ROOT": dict(base, OILS_IOX2_ROOT=os.path.join(tmp, "root")),
                "OILS_IOX2_ROOT with a trailing slash": dict(base, OILS_IOX2_ROOT=os.path.join(tmp, "root") + "/"),
                "empty OILS_IOX2_ROOT, private XDG_RUNTIME_DIR": dict(base, OILS_IOX2_ROOT="", XDG_RUNTIME_DIR=xdg),
                "private XDG_RUNTIME_DIR": dict(base, XDG_RUNTIME_DIR=xdg),
            }
            for name, env in cases.items():
                with self.subTest(name):
                    first = rust(env)
                    self.assertEqual(python(env), first)
                    self.assertEqual(rust(env), first, "the token is kept")
                    remove_segments(first[1])
            # A runtime directory others can enter is not used: both fall back alike.
            env = dict(base, XDG_RUNTIME_DIR=wide)
            fallback = rust(env)
            self.assertEqual(fallback[0], f"/tmp/oils-{os.geteuid()}/")
            self.assertEqual(python(env), fallback)
            # Python first, then Rust: the same again.
            env = dict(base, OILS_IOX2_ROOT=os.path.join(tmp, "python-first"))
            first = python(env)
            self.assertEqual(rust(env), first)
            remove_segments(first[1])

    def test_private_root_token_and_0600_segment(self):
        with tempfile.TemporaryDirectory() as tmp:
            root = os.path.join(tmp, "domain")
            cfg = domain.config(root)
            self.assertEqual(stat.S_IMODE(os.lstat(root).st_mode), 0o700)
            with open(os.path.join(root, "token")) as f:
                token = f.read().strip()
            prefix = domain.prefix_of(token)
            self.assertNotIn(token, prefix)
            self.assertIn(f'"{prefix}"', str(cfg.global_cfg.prefix))
            seg = os.path.join(domain.SHM_DIR, prefix + domain.GLOBAL_SEGMENT_TAIL)
            try:
                self.assertEqual(stat.S_IMODE(os.lstat(seg).st_mode), 0o600)
                # Widened and damaged: narrowed and made again.
                os.chmod(seg, 0o666)
                with open(seg, "wb") as f:
                    f.write(b"garbage garbage!")
                domain.config(root)
                self.assertEqual(stat.S_IMODE(os.lstat(seg).st_mode), 0o600)
                with open(seg, "rb") as f:
                    self.assertEqual(f.read(), (10 << 16).to_bytes(8, "little") + bytes(8))
            finally:
                os.unlink(seg)

    def test_refuses_a_root_others_can_enter(self):
        with tempfile.TemporaryDirectory() as tmp:
            root = os.path.join(tmp, "wide")
            os.mkdir(root)
            os.chmod(root, 0o755)
            with self.assertRaisesRegex(domain.DomainError, "mode 0755"):
                domain.config(root)


if __name__ == "__main__":
    unittest.main()
