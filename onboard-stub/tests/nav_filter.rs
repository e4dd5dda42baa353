//! The navigation filter (#34 item 1) on a recorded descent: the default scenario flown
//! in process with the reference GNC, ideal propulsion, `--telemetry both`, 300 s, logged
//! and read back; the filter runs on the logged telemetry and is compared with the logged
//! truth. One recording is shared by the tests of this binary.

use nalgebra::Vector3;
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::recorder::{read_log, Record};
use oils_emulator::run_config::{LinkKind, RunConfig, TelemetrySource};
use oils_emulator::session;
use oils_onboard_stub::gnc::nav_filter::{Channel, NavEstimate, NavFilter, NavFilterConfig};
use oils_shared::Telemetry;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::AtomicBool;
use std::sync::OnceLock;

/// The system allocator, counting this thread's allocations (the pattern of
/// `emulator/tests/common/mod.rs`).
struct CountingAlloc;
thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}
fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}
// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

const DURATION_S: f64 = 2000.0;

/// The recorded descent (flown once per test binary).
fn recording() -> &'static [Record] {
    static REC: OnceLock<Vec<Record>> = OnceLock::new();
    REC.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("oils-nav-filter-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("descent.oilslog");
        let mut cfg = RunConfig {
            link: LinkKind::Inproc,
            propulsion: PropulsionKind::Ideal,
            telemetry: TelemetrySource::Both,
            duration_s: DURATION_S,
            seed: 11,
            dt_ms: 5,
            ..Default::default()
        };
        cfg.log.enabled = true;
        cfg.log.path = Some(path.clone());
        let run_id = session::fresh_run_id();
        let fsw = oils_onboard_stub::build::build_fsw(
            &cfg.fsw,
            None,
            None,
            run_id,
            Some(oils_onboard_stub::gnc::SiteTarget {
                latitude_deg: cfg.scenario.site.latitude_deg,
                longitude_deg: cfg.scenario.site.longitude_deg,
            }),
            cfg.gnc.clone(),
        )
        .unwrap();
        session::run(
            &cfg,
            run_id,
            &AtomicBool::new(false),
            session::Onboard::InProcess(fsw),
            session::Extras::default(),
        )
        .unwrap();
        let log = read_log(&path).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        log.records
    })
}

/// The filter with an orbit-determination error drawn from its own initial sigmas.
fn filter(seed: u64) -> NavFilter {
    let mut cfg = NavFilterConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for i in 0..3 {
        let a: f64 = StandardNormal.sample(&mut rng);
        let b: f64 = StandardNormal.sample(&mut rng);
        cfg.init_pos_offset_m[i] = a * cfg.init_sigma_pos_m;
        cfg.init_vel_offset_m_s[i] = b * cfg.init_sigma_vel_m_s;
    }
    NavFilter::new(cfg)
}

struct Figures {
    n: usize,
    max_pos_err_m: f64,
    final_pos_err_m: f64,
    max_vel_err_m_s: f64,
    within_3sigma_frac: f64,
    nees_mean: f64,
    est: Vec<NavEstimate>,
}

fn fly(recs: &[Record], f: &mut NavFilter, edit: impl Fn(usize, &mut Telemetry)) -> Figures {
    let mut fig = Figures {
        n: 0,
        max_pos_err_m: 0.0,
        final_pos_err_m: 0.0,
        max_vel_err_m_s: 0.0,
        within_3sigma_frac: 0.0,
        nees_mean: 0.0,
        est: Vec::with_capacity(recs.len()),
    };
    let mut within = 0usize;
    let mut nees_sum = 0.0;
    for (k, rec) in recs.iter().enumerate() {
        let mut tlm = rec.telemetry;
        edit(k, &mut tlm);
        let e = f.step(&tlm);
        fig.est.push(e);
        let err = Vector3::from(e.pos_mci_m) - Vector3::from(rec.truth.pos_mci_m);
        let verr = Vector3::from(e.vel_mci_m_s) - Vector3::from(rec.truth.vel_mci_m_s);
        let p = f.covariance().fixed_view::<3, 3>(0, 0).into_owned();
        let nees = (err.transpose() * p.try_inverse().unwrap() * err)[(0, 0)];
        nees_sum += nees;
        // Per axis within 3 sigma.
        if (0..3).all(|i| err[i].abs() <= 3.0 * e.sigma_pos_m[i]) {
            within += 1;
        }
        fig.max_pos_err_m = fig.max_pos_err_m.max(err.norm());
        fig.max_vel_err_m_s = fig.max_vel_err_m_s.max(verr.norm());
        fig.final_pos_err_m = err.norm();
        fig.n += 1;
    }
    fig.within_3sigma_frac = within as f64 / fig.n as f64;
    fig.nees_mean = nees_sum / fig.n as f64;
    fig
}

/// Radial (altitude) error of the centre of mass, m (the truth's `altitude_m` is the
/// footpads', 1.17 m below it).
fn altitude_err(e: &NavEstimate, rec: &Record) -> f64 {
    let up = Vector3::from(rec.truth.pos_mci_m).normalize();
    (Vector3::from(e.pos_mci_m) - Vector3::from(rec.truth.pos_mci_m)).dot(&up)
}

/// (a) The whole descent (949 s, from 30 km to touchdown; altimeters from ~9 km,
/// velocimeter from ~5 km): two orbit-determination draws.
#[test]
fn nav_filter_on_a_recorded_descent_is_accurate_and_consistent() {
    let recs = recording();
    assert!(
        recs.len() > 60_000,
        "the descent should last > 300 s: {}",
        recs.len()
    );
    for seed in [1, 2] {
        let mut f = filter(seed);
        let fig = fly(recs, &mut f, |_, _| {});
        let last = fig.est.last().unwrap();
        let t = recs.last().unwrap();
        let alt_err = altitude_err(last, t);
        let vel_err = (Vector3::from(last.vel_mci_m_s) - Vector3::from(t.truth.vel_mci_m_s)).norm();
        let up = Vector3::from(t.truth.pos_mci_m).normalize();
        let pp = f.covariance().fixed_view::<3, 3>(0, 0).into_owned();
        let radial_sigma = (up.transpose() * pp * up)[(0, 0)].sqrt();
        let horizontal_sigma = (pp.trace() - radial_sigma.powi(2)).sqrt();
        let radial_err =
            (Vector3::from(last.pos_mci_m) - Vector3::from(t.truth.pos_mci_m)).dot(&up);
        eprintln!("seed {seed}: touchdown radial error {radial_err:.3} m, sigma {radial_sigma:.3} m, horizontal sigma {horizontal_sigma:.1} m");
        assert!(radial_sigma < 5.0, "radial sigma {radial_sigma} m");
        eprintln!(
            "seed {seed}: records {} t_end {:.1} s; max pos err {:.1} m, final {:.1} m (alt {:.2} m, vel {:.4} m/s), max vel err {:.3} m/s, within 3 sigma {:.4}, mean NEES {:.2}; final sigma pos {:.1?}; channels {:?}",
            fig.n,
            t.telemetry.header.t_ns as f64 * 1e-9,
            fig.max_pos_err_m,
            fig.final_pos_err_m,
            alt_err,
            vel_err,
            fig.max_vel_err_m_s,
            fig.within_3sigma_frac,
            fig.nees_mean,
            last.sigma_pos_m,
            last.channels
        );
        assert!(
            fig.max_pos_err_m < 1000.0,
            "max position error {} m",
            fig.max_pos_err_m
        );
        assert!(
            fig.final_pos_err_m < 300.0,
            "touchdown position error {} m",
            fig.final_pos_err_m
        );
        assert!(alt_err.abs() < 0.5, "touchdown altitude error {alt_err} m");
        assert!(vel_err < 0.05, "touchdown velocity error {vel_err} m/s");
        assert!(
            fig.within_3sigma_frac >= 0.95,
            "within 3 sigma {}",
            fig.within_3sigma_frac
        );
        assert!(
            fig.nees_mean < 6.0,
            "mean NEES {} (3 expected)",
            fig.nees_mean
        );
        // Every device channel (the terrain fixes need a map, which this run has not).
        for (c, ch) in last.channels.iter().enumerate() {
            if c == oils_onboard_stub::gnc::nav_filter::Channel::Terrain as usize {
                assert_eq!(ch.accepted, 0, "no map, no terrain fix");
                continue;
            }
            assert!(ch.accepted > 1000, "channel {c} used {} times", ch.accepted);
        }
    }
}

/// First record index at or below `alt` with a laser sample.
fn laser_record_below(recs: &[Record], alt: f64) -> usize {
    recs.iter()
        .position(|r| {
            r.truth.altitude_m < alt
                && r.telemetry.sensors.laser_altimeter_count > 0
                && r.telemetry.sensors.laser_altimeter[0].valid != 0
        })
        .unwrap()
}

/// (b) One laser sample +300 m at 2 km: rejected, and the estimate does not move.
#[test]
fn nav_filter_rejects_a_laser_altimeter_spike() {
    let recs = recording();
    let k0 = laser_record_below(recs, 2000.0);
    let clean = fly(recs, &mut filter(1), |_, _| {});
    let spiked = fly(recs, &mut filter(1), |k, t| {
        if k == k0 {
            t.sensors.laser_altimeter[0].range_m += 300.0;
        }
    });
    let c = clean.est.last().unwrap().channels[Channel::Laser as usize];
    let s = spiked.est.last().unwrap().channels[Channel::Laser as usize];
    assert_eq!(s.rejected, c.rejected + 1, "clean {c:?} spiked {s:?}");
    assert_eq!(s.reaccepted, c.reaccepted);
    // Rejected: exactly as if the sample had been lost.
    let dropped = fly(recs, &mut filter(1), |k, t| {
        if k == k0 {
            t.sensors.laser_altimeter[0].valid = 0;
        }
    });
    let (mut max_vs_dropped, mut max_alt_jump): (f64, f64) = (0.0, 0.0);
    for k in k0..recs.len() {
        let d = Vector3::from(spiked.est[k].pos_mci_m) - Vector3::from(dropped.est[k].pos_mci_m);
        max_vs_dropped = max_vs_dropped.max(d.norm());
        max_alt_jump = max_alt_jump.max((spiked.est[k].altitude_m - clean.est[k].altitude_m).abs());
    }
    eprintln!(
        "spike at record {k0}: position difference to the sample dropped {max_vs_dropped:.3e} m, altitude difference to the clean run {max_alt_jump:.3} m"
    );
    assert_eq!(max_vs_dropped, 0.0, "the spike moved the estimate");
    assert!(max_alt_jump < 0.5, "the altitude moved by {max_alt_jump} m");
}

/// (c) A terrain step under the laser beam (-200 m for 30 s from 3 km, a crater rim):
/// rejected `reaccept_after - 1` times, re-accepted at the `reaccept_after`-th sample as a
/// ground offset; the same when the step ends; the altitude stays within 5 m.
#[test]
fn nav_filter_reaccepts_a_genuine_terrain_step() {
    let recs = recording();
    let k0 = laser_record_below(recs, 3000.0);
    let k1 = k0 + 3000; // 30 s of 10 ms records
    let n = NavFilterConfig::default().reaccept_after as u64;
    let clean = fly(recs, &mut filter(1), |_, _| {});
    let mut f = filter(1);
    let step = fly(recs, &mut f, |k, t| {
        if (k0..k1).contains(&k) {
            for a in t
                .sensors
                .laser_altimeter
                .iter_mut()
                .take(t.sensors.laser_altimeter_count as usize)
            {
                a.range_m -= 200.0;
            }
        }
    });
    let c = clean.est.last().unwrap().channels[Channel::Laser as usize];
    let s = step.est.last().unwrap().channels[Channel::Laser as usize];
    // Right after the step started: n-1 rejections, then accepted again.
    let first_reaccept = (k0..k1)
        .find(|&k| step.est[k].channels[1].reaccepted > c.reaccepted)
        .unwrap();
    let laser_samples = (k0..=first_reaccept)
        .filter(|&k| recs[k].telemetry.sensors.laser_altimeter_count > 0)
        .count() as u64;
    let max_alt_err = (k0..recs.len())
        .map(|k| altitude_err(&step.est[k], &recs[k]).abs())
        .fold(0.0, f64::max);
    eprintln!("terrain step at record {k0}: clean {c:?}; step {s:?}; re-accepted at laser sample {laser_samples} of the step; max altitude error after {max_alt_err:.2} m");
    assert_eq!(laser_samples, n);
    assert_eq!(s.reaccepted, c.reaccepted + 2, "in and out of the step");
    assert_eq!(s.rejected, c.rejected + 2 * (n - 1));
    assert!(max_alt_err < 2.0, "altitude error {max_alt_err} m");
}

/// (d) `step` does not allocate: the whole descent.
#[test]
fn nav_filter_step_does_not_allocate() {
    let recs = recording();
    let mut f = filter(1);
    let mut sum = 0.0;
    let before = allocations();
    for rec in recs {
        let e = f.step(&rec.telemetry);
        sum += e.pos_mci_m[0];
    }
    let after = allocations();
    std::hint::black_box(sum);
    assert_eq!(after - before, 0, "step allocated {} times", after - before);
}

/// A sustained offset on one velocimeter beam (+0.3 m/s from 3 km on, 30 sigma) is not
/// locked out: rejected `reaccept_after - 1` times, then re-accepted and used again.
#[test]
fn nav_filter_never_locks_out_a_velocimeter_beam() {
    let recs = recording();
    let k0 = laser_record_below(recs, 3000.0);
    let n = NavFilterConfig::default().reaccept_after;
    let clean = fly(recs, &mut filter(1), |_, _| {});
    let off = fly(recs, &mut filter(1), |k, t| {
        if k >= k0 {
            for v in t.sensors.velocimeter.iter_mut() {
                v.los_velocity_m_s[0] += 0.3;
            }
        }
    });
    let c = clean.est[k0 - 1].channels[Channel::Velo0 as usize];
    let first = off.est[k0..]
        .iter()
        .position(|e| e.channels[Channel::Velo0 as usize].reaccepted > c.reaccepted)
        .map(|i| i + k0)
        .expect("never re-accepted");
    let at = off.est[first].channels[Channel::Velo0 as usize];
    let end = off.est.last().unwrap().channels[Channel::Velo0 as usize];
    let used_after = end.accepted - at.accepted;
    eprintln!(
        "velocimeter offset at record {k0}: re-accepted at record {first} {at:?}; end {end:?}"
    );
    assert_eq!(at.rejected - c.rejected, u64::from(n - 1));
    assert!(
        used_after > 500,
        "beam 0 used {used_after} times after the re-accept"
    );
}
