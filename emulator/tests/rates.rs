//! Multi-rate time (#32): a plant period, the propulsion model's own period and the
//! flight-software cycle on one base tick, in process.

mod fly;
use fly::{fly, try_fly};
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::run_config::{LinkKind, RunConfig};
use oils_emulator::scheduler::{Mode, Outcome};

fn config(model: PropulsionKind, dt_ms: u64, fsw_ms: Option<u64>, duration_s: f64) -> RunConfig {
    let mut cfg = RunConfig {
        link: LinkKind::Inproc,
        propulsion: model,
        dt_ms,
        fsw_period_ms: fsw_ms,
        duration_s,
        ..Default::default()
    };
    cfg.log.enabled = false;
    cfg
}

#[test]
fn a_flight_software_period_that_is_not_a_multiple_of_the_plant_period_is_refused() {
    let e = try_fly(&config(PropulsionKind::Ideal, 10, Some(15), 1.0))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("fsw_period_ms")
            && e.contains("15 ms")
            && e.contains("plant period")
            && e.contains("10 ms"),
        "{e}"
    );
}

#[test]
fn a_20_ms_cycle_over_a_10_ms_plant_exchanges_exactly_half_the_packets() {
    let r10 = fly(&config(PropulsionKind::Ideal, 10, None, 20.0)).summary;
    let r20 = fly(&config(PropulsionKind::Ideal, 10, Some(20), 20.0)).summary;
    assert_eq!(r10.outcome, Outcome::Completed);
    assert_eq!(r20.outcome, Outcome::Completed);
    assert_eq!(r10.steps, 2000);
    assert_eq!(r20.steps * 2, r10.steps);
    assert_eq!(
        r20.timing.round_trip_ns.count * 2,
        r10.timing.round_trip_ns.count
    );
    // The plant integrates the same 20 s on the same base tick.
    assert_eq!(r20.plant_steps, r10.plant_steps);
    assert_eq!(r10.plant_steps, 2000);
    assert_ne!(r10.digest, r20.digest);
}

/// Halving the plant period (10 ms -> 5 ms, the flight software at 10 ms in both)
/// changes only how finely the plant integrates a command held over each cycle. With a
/// fourth-order integrator and the command piecewise constant on the cycle the
/// integration error is tiny (measured: 1e-7 m/s on the touchdown speeds); what moves is
/// touchdown detection, at the end of a plant step: up to one coarse plant step (10 ms)
/// apart (measured: 5 ms). Bounds: touchdown time within one coarse plant step, 10 ms;
/// vertical and horizontal touchdown speed within 1e-4 m/s (1000x the measured change,
/// for floating-point differences between platforms, and still 1000x tighter than the
/// 0.1 m/s the touchdown limits are stated in).
#[test]
fn halving_the_plant_period_moves_the_touchdown_by_less_than_the_stated_tolerance() {
    let a = fly(&config(PropulsionKind::Ideal, 10, Some(10), 2000.0)).summary;
    let b = fly(&config(PropulsionKind::Ideal, 5, Some(10), 2000.0)).summary;
    assert_eq!(a.outcome, Outcome::Landed, "{:?}", a.error);
    assert_eq!(b.outcome, Outcome::Landed, "{:?}", b.error);
    // Two plant steps a cycle; touchdown may cut the last cycle after its first.
    assert!(
        b.plant_steps == 2 * b.steps || b.plant_steps == 2 * b.steps - 1,
        "{} plant steps in {} cycles",
        b.plant_steps,
        b.steps
    );
    let (ta, tb) = (a.touchdown.unwrap(), b.touchdown.unwrap());
    let dt = (a.sim_time_s - b.sim_time_s).abs();
    let dv = (ta.vertical_speed_mps - tb.vertical_speed_mps).abs();
    let dh = (ta.horizontal_speed_mps - tb.horizontal_speed_mps).abs();
    eprintln!("touchdown moved by {dt} s, vertical {dv} m/s, horizontal {dh} m/s");
    assert!(
        dt <= 0.010 + 1e-9,
        "{} s vs {} s",
        a.sim_time_s,
        b.sim_time_s
    );
    assert!(dv < 1e-4, "{dv} m/s");
    assert!(dh < 1e-4, "{dh} m/s");
}

/// `oils run --mode realtime --dt-ms 1` with the default (surrogate) propulsion: the
/// plant at 1 kHz, the surrogate sampled every 10 ms and held, the flight software at
/// 10 ms. Outcome and counts asserted, not time.
#[test]
fn realtime_at_1_ms_flies_the_surrogate() {
    let mut cfg = config(PropulsionKind::Surrogate, 1, None, 0.5);
    cfg.mode = Mode::Realtime;
    let r = fly(&cfg).summary;
    assert_eq!(r.outcome, Outcome::Completed, "{:?}", r.error);
    assert_eq!(r.steps, 50);
    assert_eq!(r.plant_steps, 500);
    assert_eq!(r.overruns.len(), 2);
    assert_eq!(r.overruns[0].group, "plant");
    assert_eq!(r.overruns[1].period_ns, 10_000_000);
}
