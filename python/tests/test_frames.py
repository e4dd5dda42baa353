"""Frames (protocol v4) end to end: `oils run --no-stub` with the test card on, and the
Python example flight software reading each frame as a numpy view of the shared memory
and checking its XXH3-64 hash and the card's counter (`oils_fsw.examples.frames`).

Needs OILS_BIN (tools/python-e2e.sh sets it) and numpy (the `data` extra).
"""

import json
import os
import re
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "emulator/config/scenarios/terminal-descent.toml"


class Frames(unittest.TestCase):
    def test_every_frame_is_read_in_place_and_its_hash_checked(self):
        run_id = f"{(os.getpid() << 16) | 0xf1:016x}"
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            scenario = tmp / "test-card.toml"
            scenario.write_text(SCENARIO.read_text() + "\n[sensors.test_card]\nenabled = true\n")
            report = tmp / "report.json"
            emulator = subprocess.Popen(
                [os.environ["OILS_BIN"], "run", "--no-stub", "--no-log", "--run-id", run_id,
                 "--scenario", str(scenario), "--report", str(report)],
                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            client = subprocess.run(
                [sys.executable, "-m", "oils_fsw.examples.frames", "--run-id", run_id],
                stdin=subprocess.DEVNULL, capture_output=True, text=True, cwd=tmp, timeout=300)
            out, err = emulator.communicate(timeout=300)
            self.assertEqual(client.returncode, 0, f"client: {client.stderr}")
            self.assertEqual(emulator.returncode, 0, f"oils run: {out}\n{err}")
            r = json.loads(report.read_text())
            self.assertEqual(r["outcome"], "landed")
            checked = int(re.search(r"frames: (\d+) checked", client.stderr).group(1))
            # One frame a second of flight, the last perhaps announced only by the
            # end-of-run telemetry (which is not answered).
            whole_s = int(r["sim_time_s"])
            self.assertIn(checked, (whole_s - 1, whole_s), client.stderr)
            self.assertGreater(checked, 10)


if __name__ == "__main__":
    unittest.main()
