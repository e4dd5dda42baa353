"""End to end with real processes: `oils run --no-stub` and the Python example flight
software on the run's iceoryx2 services.

Needs OILS_BIN (the `oils` executable); tools/python-e2e.sh sets it, installs the package
(`pip install ./python`) and sets OILS_FSW_EXPECT_INSTALLED: then the package under test
must be the installed one, not the checkout's source tree.
"""

import os
import subprocess
import sys
import tempfile
import tomllib
import unittest
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "emulator/config/scenarios/terminal-descent.toml"
PYTHON_DIR = REPO / "python"


def fly(tmp: Path, name: str, run_id: str, extra=()):
    """One run: the emulator waits (--no-stub), the Python example flies it."""
    report = tmp / f"{name}.json"
    emulator = subprocess.Popen(
        [os.environ["OILS_BIN"], "run", "--no-stub", "--no-log", "--run-id", run_id,
         "--scenario", str(SCENARIO), "--seed", "5", "--report", str(report), *extra],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    client = subprocess.run(
        [sys.executable, "-m", "oils_fsw.examples.terminal_descent", "--run-id", run_id],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, cwd=tmp, timeout=300)
    out, err = emulator.communicate(timeout=300)
    assert client.returncode == 0, f"client: {client.stderr}"
    assert emulator.returncode == 0, f"oils run: {out}\n{err}"
    import json
    return json.loads(report.read_text()), client.stderr


class PythonFlightSoftware(unittest.TestCase):
    @unittest.skipUnless(os.environ.get("OILS_FSW_EXPECT_INSTALLED"), "run by tools/python-e2e.sh")
    def test_the_package_under_test_is_the_installed_one(self):
        import oils_fsw
        import oils_fsw.examples.terminal_descent as example

        for module in (oils_fsw, example):
            where = Path(module.__file__).resolve()
            self.assertNotIn(PYTHON_DIR, where.parents, f"{module.__name__} from the checkout: {where}")
            self.assertIn("site-packages", where.parts, where)
            self.assertIn(Path(sys.prefix).resolve(), where.parents, where)

    def test_lands_the_terminal_descent_with_a_repeatable_digest(self):
        limits = tomllib.loads(SCENARIO.read_text())["touchdown"]
        base = os.getpid() << 16
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            a, a_log = fly(tmp, "a", f"{base | 0xa1:016x}")
            self.assertEqual(a["outcome"], "landed", a)
            td = a["touchdown"]
            self.assertLessEqual(td["vertical_speed_mps"], limits["vertical_speed_mps"])
            self.assertLessEqual(td["horizontal_speed_mps"], limits["horizontal_speed_mps"])
            self.assertLessEqual(td["tilt_deg"], td["tilt_limit_deg"])
            self.assertEqual(a["timing"]["stub_compute_ns"]["count"], a["steps"])
            self.assertGreater(a["timing"]["stub_compute_ns"]["p50"], 0)
            self.assertIn("wait busy", a_log)
            b, _ = fly(tmp, "b", f"{base | 0xa2:016x}")
            self.assertEqual(a["digest"], b["digest"], "same inputs, same digest")
            # With an event-waiting emulator the client notifies after every command;
            # the exchange (and so the digest) is the same.
            c, c_log = fly(tmp, "c", f"{base | 0xa3:016x}", ["--wait", "event"])
            self.assertIn("wait event", c_log)
            self.assertEqual(c["wait"], "event")
            self.assertEqual(a["digest"], c["digest"])


if __name__ == "__main__":
    unittest.main()
