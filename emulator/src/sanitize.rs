//! The link's guard: command values from the onboard computer are checked before they
//! reach the plant. Non-finite or out-of-range values are replaced by safe values and
//! counted; the plant only ever sees finite, in-range actuator commands.
//!
//! Safe values: a non-finite thrust switches its engine off; a negative thrust becomes
//! 0 N, one above rating becomes the rating; an on/off word other than 0 or 1 means off;
//! a non-finite torque component becomes 0; an attitude mode other than 0 (ideal torque)
//! or 1 (thrusters) means ideal torque with zero torque; a thruster on-time longer than
//! the cycle becomes the cycle. (Thrust between zero and the minimum throttle is not an
//! error: the engine clamps it, as the real one does; nor is an on-time below the
//! thrusters' minimum impulse bit: the thruster model decides what it fires.)

use crate::plant::ActuatorCommand;
use crate::propulsion::EngineCommand;
use oils_shared::{Command, ATTITUDE_MODE_IDEAL_TORQUE, ATTITUDE_MODE_THRUSTERS, ENGINE_COUNT};

/// Checks and converts one command, issued for the cycle that starts at
/// `cycle_start_ns` and lasts `cycle_ns`. Returns the actuator command and how many
/// values were replaced (0 for a clean command).
pub fn sanitize(
    cmd: &Command,
    max_thrust_n: f64,
    cycle_start_ns: i64,
    cycle_ns: u64,
) -> (ActuatorCommand, u32) {
    let mut rejected = 0u32;
    let mut engines = EngineCommand::default();
    for i in 0..ENGINE_COUNT {
        let on = match cmd.engine_on[i] {
            0 => false,
            1 => true,
            _ => {
                rejected += 1;
                false
            }
        };
        let thrust = cmd.thrust_cmd_n[i];
        let (thrust_n, on) = if !thrust.is_finite() {
            rejected += 1;
            (0.0, false)
        } else if thrust < 0.0 {
            rejected += 1;
            (0.0, on)
        } else if thrust > max_thrust_n {
            rejected += 1;
            (max_thrust_n, on)
        } else {
            (thrust, on)
        };
        engines.thrust_cmd_n[i] = thrust_n;
        engines.on[i] = on;
    }
    let mut torque_cmd_body_nm = [0.0; 3];
    for (out, t) in torque_cmd_body_nm.iter_mut().zip(cmd.torque_cmd_body_nm) {
        if t.is_finite() {
            *out = t;
        } else {
            rejected += 1;
        }
    }
    let use_thrusters = match cmd.attitude_mode {
        ATTITUDE_MODE_IDEAL_TORQUE => false,
        ATTITUDE_MODE_THRUSTERS => true,
        _ => {
            rejected += 1;
            torque_cmd_body_nm = [0.0; 3];
            false
        }
    };
    let mut thruster_on_time_ns = cmd.thruster_on_time_ns;
    for t in thruster_on_time_ns.iter_mut() {
        if *t > cycle_ns {
            rejected += 1;
            *t = cycle_ns;
        }
    }
    (
        ActuatorCommand {
            engines,
            torque_cmd_body_nm,
            use_thrusters,
            thruster_on_time_ns,
            cycle_start_ns,
        },
        rejected,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clean_command_passes_unchanged() {
        let cmd = Command {
            thrust_cmd_n: [800.0, 320.0, 0.0, 500.0],
            engine_on: [1, 1, 0, 1],
            torque_cmd_body_nm: [1.0, -2.0, 1e6],
            ..Default::default()
        };
        let (a, rejected) = sanitize(&cmd, 800.0, 0, 10_000_000);
        assert_eq!(rejected, 0);
        assert_eq!(a.engines.thrust_cmd_n, cmd.thrust_cmd_n);
        assert_eq!(a.engines.on, [true, true, false, true]);
        assert_eq!(a.torque_cmd_body_nm, [1.0, -2.0, 1e6]);
    }

    #[test]
    fn bad_values_never_reach_the_plant() {
        let cmd = Command {
            thrust_cmd_n: [f64::NAN, f64::INFINITY, -5.0, 1e9],
            engine_on: [1, 1, 1, 7],
            torque_cmd_body_nm: [f64::NEG_INFINITY, 0.5, f64::NAN],
            ..Default::default()
        };
        let (a, rejected) = sanitize(&cmd, 800.0, 0, 10_000_000);
        // Four bad thrusts, one bad on/off word, two bad torque components.
        assert_eq!(rejected, 4 + 1 + 2);
        assert_eq!(a.engines.thrust_cmd_n, [0.0, 0.0, 0.0, 800.0]);
        assert_eq!(a.engines.on, [false, false, true, false]);
        assert_eq!(a.torque_cmd_body_nm, [0.0, 0.5, 0.0]);
        assert!(a.engines.thrust_cmd_n.iter().all(|t| t.is_finite()));
    }

    #[test]
    fn thruster_commands_are_checked() {
        let cmd = Command {
            attitude_mode: ATTITUDE_MODE_THRUSTERS,
            thruster_on_time_ns: [0, 5_000_000, 20_000_000, 0, 0, 0, 0, 1],
            ..Default::default()
        };
        let (a, rejected) = sanitize(&cmd, 800.0, 30_000_000, 10_000_000);
        assert_eq!(rejected, 1);
        assert!(a.use_thrusters);
        assert_eq!(a.cycle_start_ns, 30_000_000);
        assert_eq!(a.thruster_on_time_ns[1], 5_000_000);
        assert_eq!(a.thruster_on_time_ns[2], 10_000_000);
        let bad = Command {
            attitude_mode: 9,
            torque_cmd_body_nm: [1.0, 2.0, 3.0],
            ..Default::default()
        };
        let (a, rejected) = sanitize(&bad, 800.0, 0, 10_000_000);
        assert_eq!(rejected, 1);
        assert!(!a.use_thrusters);
        assert_eq!(a.torque_cmd_body_nm, [0.0; 3]);
    }
}
