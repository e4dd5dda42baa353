//! An untimed run (`session::Extras::untimed`, what a campaign case asks for) reads no
//! wall clock per exchange: no round trip, no flight-software compute time, no rate-group
//! time is recorded. It is the same run otherwise: the same digest, outcome and touchdown
//! as the timed one. Only a lockstep run in process may be untimed.

use oils_emulator::report::RunReport;
use oils_emulator::run_config::{LinkKind, RunConfig};
use oils_emulator::scheduler::Mode;
use oils_emulator::session;
use std::sync::atomic::AtomicBool;

fn config() -> RunConfig {
    let mut cfg = RunConfig {
        link: LinkKind::Inproc,
        // Through powered descent into rough braking: every rate group runs.
        duration_s: 60.0,
        // Lost commands and telemetry: steps with no command (misses), which the
        // scheduler handles apart.
        faults: vec![
            "command-drop@t=0,for=0.5".parse().unwrap(),
            "telemetry-drop@t=20,for=1".parse().unwrap(),
        ],
        ..Default::default()
    };
    cfg.log.enabled = false;
    cfg
}

fn fly(cfg: &RunConfig, untimed: bool) -> Result<RunReport, session::SessionError> {
    let run_id = session::fresh_run_id();
    let fsw =
        oils_onboard_stub::build::build_fsw(&cfg.fsw, None, None, run_id, None, cfg.gnc.clone())
            .unwrap();
    session::run(
        cfg,
        run_id,
        &AtomicBool::new(false),
        session::Onboard::InProcess(fsw),
        session::Extras {
            untimed,
            ..Default::default()
        },
    )
}

#[test]
fn an_untimed_run_is_the_same_run_with_nothing_timed() {
    let cfg = config();
    let timed = fly(&cfg, false).unwrap().summary;
    let untimed = fly(&cfg, true).unwrap().summary;
    assert_eq!(untimed.digest, timed.digest);
    assert_eq!(untimed.outcome, timed.outcome);
    assert_eq!(untimed.steps, timed.steps);
    assert_eq!(untimed.touchdown, timed.touchdown);
    assert_eq!(untimed.timing.deadline_misses, timed.timing.deadline_misses);
    assert!(timed.timing.deadline_misses > 0, "the faults made no miss");
    // The timed run measured its exchanges (all but those whose telemetry was lost);
    // the untimed one none.
    assert!(timed.timing.round_trip_ns.count + timed.timing.deadline_misses >= timed.steps);
    assert_eq!(
        timed.timing.stub_compute_ns.count,
        timed.timing.round_trip_ns.count
    );
    assert_eq!(untimed.timing.round_trip_ns.count, 0);
    assert_eq!(untimed.timing.stub_compute_ns.count, 0);
    // The reference GNC's rate groups ran as often, each reported as 1 ns ("ran", not
    // timed), and no cycle slip was counted.
    let (t, u) = (timed.fsw_report.unwrap(), untimed.fsw_report.unwrap());
    assert_eq!(u.group_compute_ns.len(), 3);
    for (g, (t, u)) in t
        .group_compute_ns
        .iter()
        .zip(&u.group_compute_ns)
        .enumerate()
    {
        assert_eq!(u.count, t.count, "group {g}");
        assert!(u.count > 0 && u.max == 1, "group {g}: {u:?}");
    }
    assert_eq!(u.cycle_slips, 0);
}

#[test]
fn only_a_lockstep_run_in_process_may_be_untimed() {
    let mut cfg = config();
    cfg.mode = Mode::Realtime;
    cfg.duration_s = 0.1;
    cfg.faults.clear();
    let err = fly(&cfg, true).unwrap_err().to_string();
    assert!(err.contains("lockstep and in process"), "{err}");
}
