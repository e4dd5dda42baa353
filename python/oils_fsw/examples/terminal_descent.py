"""Terminal descent in Python: the same laws as onboard-stub/examples/c/terminal_descent.c.

Flies emulator/config/scenarios/terminal-descent.toml (2 km up, slow, over the site) to a
soft touchdown:

    oils run --no-stub --run-id 00000000000000aa \\
        --scenario emulator/config/scenarios/terminal-descent.toml &
    PYTHONPATH=python python -m oils_fsw.examples.terminal_descent --run-id 00000000000000aa
"""

import argparse
import math
import sys

from oils_fsw import ENGINE_COUNT, TLM_FLAG_FOOTPAD_CONTACT, Command, Telemetry, fly

MOON_MU_M3_S2 = 4.9028e12
MOON_ROTATION_RAD_S = 2.6617e-6  # sidereal: 2 pi / 27.321661 d, about mci +Z
ENGINE_MIN_N = 320.0  # 40 % of 800 N
ENGINE_MAX_N = 800.0
INERTIA_KG_M2 = 1000.0  # rough, every axis


def rotate(q, v, inverse=False):
    """R(q) v for q = [w, x, y, z] rotating body into mci (R(q)^T v when inverse)."""
    s = -1.0 if inverse else 1.0
    w, x, y, z = q[0], s * q[1], s * q[2], s * q[3]
    t = (2.0 * (y * v[2] - z * v[1]), 2.0 * (z * v[0] - x * v[2]), 2.0 * (x * v[1] - y * v[0]))
    return (
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    )


class TerminalDescent:
    """Descent-speed profile, horizontal velocity nulling, upright attitude hold."""

    def __init__(self, max_descent_speed_m_s=20.0, touchdown_speed_m_s=1.0, decel_m_s2=0.6):
        self.max_descent_speed_m_s = max_descent_speed_m_s
        self.touchdown_speed_m_s = touchdown_speed_m_s
        self.decel_m_s2 = decel_m_s2

    def step(self, tlm: Telemetry) -> Command:
        if tlm.header.flags & TLM_FLAG_FOOTPAD_CONTACT:
            return Command()  # on the legs: engines off, no torque
        nav = tlm.nav
        pos = nav.pos_mci_m
        # Velocity relative to the turning ground: v - omega x r, omega along mci +Z.
        w = MOON_ROTATION_RAD_S
        vel = (nav.vel_mci_m_s[0] + w * pos[1], nav.vel_mci_m_s[1] - w * pos[0], nav.vel_mci_m_s[2])
        r = math.sqrt(pos[0] ** 2 + pos[1] ** 2 + pos[2] ** 2)
        up = (pos[0] / r, pos[1] / r, pos[2] / r)
        g = MOON_MU_M3_S2 / (r * r)

        # Vertical: follow a descent-speed profile that brakes to touchdown speed.
        h = max(tlm.altitude_m, 0.0)
        v_ref = -max(min(self.max_descent_speed_m_s, math.sqrt(2.0 * self.decel_m_s2 * h)),
                     self.touchdown_speed_m_s)
        v_up = vel[0] * up[0] + vel[1] * up[1] + vel[2] * up[2]
        a_up = g + 1.0 * (v_ref - v_up)

        # Horizontal: null the velocity, tilting at most 10 degrees (3 near the ground).
        max_tilt = math.tan(math.radians(10.0 if h > 20.0 else 3.0))
        a_h = [-0.3 * (vel[i] - v_up * up[i]) for i in range(3)]
        a_h_norm = math.sqrt(a_h[0] ** 2 + a_h[1] ** 2 + a_h[2] ** 2)
        a_h_max = max_tilt * max(a_up, 0.1)
        scale = a_h_max / a_h_norm if a_h_norm > a_h_max else 1.0
        a = [a_up * up[i] + scale * a_h[i] for i in range(3)]
        a_norm = math.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2)

        cmd = Command()
        per_engine = min(max(tlm.mass_estimate_kg * a_norm / ENGINE_COUNT, ENGINE_MIN_N), ENGINE_MAX_N)
        for i in range(ENGINE_COUNT):
            cmd.thrust_cmd_n[i] = per_engine
            cmd.engine_on[i] = 1

        # Attitude: turn body +Z towards the demanded acceleration (PD, 1 rad/s, damping 0.8).
        q = nav.q_mci_from_body
        z = rotate(q, (0.0, 0.0, 1.0))
        d = (a[0] / a_norm, a[1] / a_norm, a[2] / a_norm)
        err_mci = (z[1] * d[2] - z[2] * d[1], z[2] * d[0] - z[0] * d[2], z[0] * d[1] - z[1] * d[0])
        err = rotate(q, err_mci, inverse=True)
        rate = nav.rate_body_rad_s
        for i in range(3):
            cmd.torque_cmd_body_nm[i] = INERTIA_KG_M2 * (1.0 * err[i] - 1.6 * rate[i])
        return cmd


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run-id", required=True, help="the run id (hex) oils run printed")
    p.add_argument("--startup-timeout-s", type=float, default=10.0)
    args = p.parse_args(argv)
    fsw = TerminalDescent()
    s = fly(fsw.step, int(args.run_id, 16), startup_timeout_s=args.startup_timeout_s)
    print(f"terminal_descent.py: served {s.commands} commands, last step {s.last_step}, wait {s.wait}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
