//! Rate groups of the reference GNC on simulated time: navigation and control every
//! 10 ms cycle, guidance every 100 ms (its output held in between). The default descent
//! still lands; the guidance group runs exactly on the cycles where `floor(t / 100 ms)`
//! changes; every group's compute time reaches the run report (printed with
//! `--nocapture`).

use oils_emulator::run_config::{LinkKind, RunConfig};
use oils_emulator::scheduler::Outcome;
use oils_emulator::session;
use oils_onboard_stub::build::gnc_config;
use oils_onboard_stub::fsw::FlightSoftware;
use oils_onboard_stub::gnc::{GncConfig, ReferenceGnc, SiteTarget};
use oils_shared::{Command, Telemetry};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// Per cycle flown: telemetry time and the three groups' compute times.
type Cycles = Arc<Mutex<Vec<(i64, [u32; 3])>>>;

struct Probe {
    gnc: ReferenceGnc,
    cycles: Cycles,
}

impl FlightSoftware for Probe {
    fn name(&self) -> &'static str {
        "gnc"
    }

    fn step(&mut self, tlm: &Telemetry) -> Command {
        let cmd = self.gnc.step(tlm);
        let g = cmd.fsw.group_compute_ns;
        if cmd.engine_on.contains(&1) {
            self.cycles
                .lock()
                .unwrap()
                .push((tlm.header.t_ns, [g[0], g[1], g[2]]));
        }
        cmd
    }
}

fn base() -> RunConfig {
    let mut cfg = RunConfig {
        link: LinkKind::Inproc,
        ..Default::default()
    };
    cfg.log.enabled = false;
    cfg
}

fn gnc(cfg: &RunConfig, guidance_period_s: f64) -> GncConfig {
    let site = SiteTarget {
        latitude_deg: cfg.scenario.site.latitude_deg,
        longitude_deg: cfg.scenario.site.longitude_deg,
    };
    GncConfig {
        guidance_period_s,
        ..gnc_config(Some(site), &cfg.gnc).unwrap()
    }
}

#[test]
fn guidance_at_100_ms_lands_and_every_group_is_timed() {
    let cfg = base();
    let cycles: Cycles = Arc::default();
    let probe = Probe {
        gnc: ReferenceGnc::new(gnc(&cfg, 0.1)).unwrap(),
        cycles: cycles.clone(),
    };
    let report = session::run(
        &cfg,
        session::fresh_run_id(),
        &AtomicBool::new(false),
        session::Onboard::InProcess(Box::new(probe)),
        session::Extras::default(),
    )
    .unwrap();
    let s = &report.summary;
    let td = s.touchdown.unwrap();
    println!(
        "guidance 100 ms: {:?} at {:.1} s, {:.2} m/s down, {:.3} m/s across, tilt {:.2} deg, \
         propellant {:.1} kg",
        s.outcome,
        td.t_s,
        td.vertical_speed_mps,
        td.horizontal_speed_mps,
        td.tilt_deg,
        s.propellant_used_kg
    );
    assert_eq!(s.outcome, Outcome::Landed);

    // The guidance group runs when floor(t / 100 ms) changes, and only then; navigation
    // and control run every cycle.
    let cycles = cycles.lock().unwrap();
    assert!(cycles.len() > 90_000, "{} powered cycles", cycles.len());
    let mut last_slot = None;
    let mut guidance_runs = 0;
    for &(t_ns, g) in cycles.iter() {
        let slot = t_ns.div_euclid(100_000_000);
        let ran = g[1] > 0;
        assert_eq!(ran, last_slot != Some(slot), "guidance at t = {t_ns} ns");
        last_slot = Some(slot);
        guidance_runs += usize::from(ran);
        assert!(g[0] > 0 && g[2] > 0, "navigation and control every cycle");
    }
    // One run per 100 ms of powered flight (10 cycles each).
    assert!(
        guidance_runs.abs_diff(cycles.len() / 10) <= 1,
        "{guidance_runs}"
    );

    // The run report's percentiles: all three groups, with their counts.
    let f = s.fsw_report.as_ref().expect("an fsw report");
    assert_eq!(f.group_compute_ns.len(), 3);
    for (name, p) in ["navigation", "guidance", "control"]
        .iter()
        .zip(&f.group_compute_ns)
    {
        println!(
            "{name}: {} runs, p50 {} ns, p99 {} ns, max {} ns",
            p.count, p.p50, p.p99, p.max
        );
        assert!(p.p50 > 0 && p.p50 <= p.p99 && p.p99 <= p.max);
    }
    let [nav, guid, ctrl] = [0, 1, 2].map(|i| f.group_compute_ns[i].count);
    assert_eq!(nav, ctrl);
    // Guidance ran on about a tenth of the cycles (powered flight; more cycles follow
    // touchdown, where only navigation and control report).
    assert!(
        guid >= guidance_runs as u64 && guid * 9 < nav,
        "{guid} of {nav}"
    );
    println!("cycle slips: {}", f.cycle_slips);
}

#[test]
fn a_guidance_period_that_is_not_a_whole_number_of_cycles_is_refused() {
    let cfg = base();
    for bad in [0.015, 0.005, 0.0, -0.1, f64::NAN] {
        let err = ReferenceGnc::new(gnc(&cfg, bad)).unwrap_err();
        assert_eq!(err.field, "guidance_period_s", "{bad}");
    }
    for good in [0.01, 0.02, 0.1, 1.0] {
        assert!(ReferenceGnc::new(gnc(&cfg, good)).is_ok(), "{good}");
    }
}
