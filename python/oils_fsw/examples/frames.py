"""The terminal-descent example flight software, plus a frame reader (protocol v4): each
frame the telemetry announces is read in place as a numpy view of the shared memory and
checked against its announcement (XXH3-64 of its bytes; for the test card, the frame
counter in its first four pixels). Prints ``frames: N checked`` at the end; a frame that
does not match ends it with status 1.

    PYTHONPATH=python python -m oils_fsw.examples.frames --run-id ID

beside ``oils run --no-stub --run-id ID --scenario S``, S with ``[sensors.test_card]
enabled = true``.
"""

import argparse
import sys

from oils_fsw import fly
from oils_fsw.examples.terminal_descent import TerminalDescent
from oils_fsw.frames import xxh3_64
from oils_fsw.packets import FRAME_DEVICE_TEST_CARD


class FrameCheck:
    """Counts the frames it is handed; raises on one that does not match."""

    def __init__(self):
        self.checked = 0

    def __call__(self, ann, pixels):
        if pixels.nbytes != ann.bytes or xxh3_64(pixels) != ann.hash:
            raise RuntimeError(f"frame {ann.seq} of device {ann.device} does not match its announcement")
        if ann.device == FRAME_DEVICE_TEST_CARD:
            # The card's counter: its first four u16 pixels, low word first.
            seq = sum(int(pixels[0, w]) << (16 * w) for w in range(4))
            if seq != ann.seq:
                raise RuntimeError(f"the test card says frame {seq}, announced {ann.seq}")
        self.checked += 1


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run-id", required=True, help="the run id (hex) oils run printed")
    p.add_argument("--startup-timeout-s", type=float, default=10.0)
    args = p.parse_args(argv)
    fsw = TerminalDescent()
    check = FrameCheck()
    s = fly(fsw.step, int(args.run_id, 16), startup_timeout_s=args.startup_timeout_s, frame=check)
    print(f"frames.py: served {s.commands} commands; frames: {check.checked} checked", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
