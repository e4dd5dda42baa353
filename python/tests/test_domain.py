"""The Python client's iceoryx2 domain follows oils_shared::domain's rules."""

import os
import re
import stat
import tempfile
import unittest

from oils_fsw import domain

RUST_DOMAIN = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "src", "domain.rs")


class DomainTest(unittest.TestCase):
    def test_same_global_segment_name_as_rust(self):
        with open(RUST_DOMAIN) as f:
            rust = f.read()
        tail = re.search(r'GLOBAL_SEGMENT_TAIL: &str =\s*"([^"]+)"', rust).group(1)
        self.assertEqual(domain.GLOBAL_SEGMENT_TAIL, tail)
        self.assertIn(f"TOKEN_LEN: usize = {domain.TOKEN_LEN};", rust)

    def test_private_root_token_and_0600_segment(self):
        with tempfile.TemporaryDirectory() as tmp:
            root = os.path.join(tmp, "domain")
            cfg = domain.config(root)
            self.assertEqual(stat.S_IMODE(os.lstat(root).st_mode), 0o700)
            with open(os.path.join(root, "prefix")) as f:
                token = f.read().strip()
            self.assertIn(f'"oils_{token}_"', str(cfg.global_cfg.prefix))
            seg = os.path.join(domain.SHM_DIR, f"oils_{token}_{domain.GLOBAL_SEGMENT_TAIL}")
            try:
                self.assertEqual(stat.S_IMODE(os.lstat(seg).st_mode), 0o600)
                # Widened and damaged: narrowed and made again.
                os.chmod(seg, 0o666)
                with open(seg, "wb") as f:
                    f.write(b"garbage garbage!")
                domain.config(root)
                self.assertEqual(stat.S_IMODE(os.lstat(seg).st_mode), 0o600)
                with open(seg, "rb") as f:
                    self.assertEqual(f.read()[:8], (10 << 16).to_bytes(8, "little"))
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
