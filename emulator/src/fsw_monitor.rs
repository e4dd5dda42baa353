//! What the flight software says of itself ([`oils_shared::FswReport`] in every
//! command), checked against the truth: navigation error (estimate minus truth) and the
//! filter's consistency, its boots, and its rate groups' compute times and cycle slips.
//! The bench never acts on the report; it only measures it.
//!
//! Consistency: a record is "within 3 sigma" when every `mci` position axis error is at
//! most three of the filter's own sigmas on that axis; the mean normalised error squared
//! (NEES, position, 3 dof) of a consistent filter is about 3. Histograms are allocated in
//! `new`; recording never allocates.

use crate::plant::TruthState;
use hdrhistogram::Histogram;
use oils_shared::{
    Command, FswReport, NAV_FLAG_FROM_SENSORS, NAV_FLAG_TERRAIN_LOST, NAV_FLAG_TERRAIN_USED,
    NAV_FLAG_VALID, RATE_GROUPS,
};
use serde::Serialize;

/// Navigation error at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct NavErrorSample {
    /// Simulated time, seconds.
    pub t_s: f64,
    /// Position error norm, metres.
    pub position_m: f64,
    /// Its component along the local vertical, metres (estimate minus truth).
    pub radial_m: f64,
    /// Its component across the local vertical, metres.
    pub horizontal_m: f64,
    /// Velocity error norm, m/s.
    pub velocity_m_s: f64,
    /// Height above the ground, estimate minus truth, metres.
    pub altitude_m: f64,
    /// The filter's own position 1-sigma (root sum square of the axes), metres; 0: not
    /// reported.
    pub sigma_position_m: f64,
}

/// The flight software's report over a run.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct FswSelfReport {
    /// Whether it reported a navigation estimate at all.
    pub navigation_reported: bool,
    /// Whether that estimate came from the devices.
    pub from_sensors: bool,
    /// Navigation error at the last cycle with an estimate before the end (at touchdown
    /// for a landing).
    pub nav_error: Option<NavErrorSample>,
    /// Navigation error when the vehicle first came down through each of
    /// [`NAV_ERROR_GATES_M`] (true height above the ground), highest first: the error
    /// against altitude of a campaign's figure; `nav_error_50m` is the 50 m one.
    pub nav_error_by_altitude: Vec<(f64, NavErrorSample)>,
    /// Navigation error at 50 m above the ground (SLIM's obstacle-avoidance height).
    pub nav_error_50m: Option<NavErrorSample>,
    /// Largest position error over the run, metres.
    pub nav_error_max_position_m: f64,
    /// Share of the cycles with an estimate and a sigma whose position error was within
    /// 3 sigma on every axis.
    pub nav_within_3_sigma: Option<f64>,
    /// Mean position NEES over those cycles (about 3 when consistent).
    pub nav_nees_mean: Option<f64>,
    /// The last `nav_flags` reported.
    pub nav_flags: u32,
    /// When it first said a terrain-relative fix updated its filter
    /// (`NAV_FLAG_TERRAIN_USED`), s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terrain_first_fix_s: Option<f64>,
    /// When it first declared terrain navigation lost (`NAV_FLAG_TERRAIN_LOST`), s, and
    /// for how many cycles in all it said so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terrain_lost_s: Option<f64>,
    /// Cycles flagged `NAV_FLAG_TERRAIN_LOST`.
    pub terrain_lost_cycles: u64,
    /// Boots (1: never reset).
    pub boot_count: u32,
    /// Rate-group cycle slips it counted (wall clock).
    pub cycle_slips: u32,
    /// Per rate group that ran, its compute time, nanoseconds (wall clock).
    pub group_compute_ns: Vec<crate::timing::Percentiles>,
}

/// Heights above the ground at which the navigation error is kept, m, highest first.
pub const NAV_ERROR_GATES_M: [f64; 12] = [
    7000.0, 5000.0, 3000.0, 2000.0, 1000.0, 500.0, 200.0, 100.0, 50.0, 20.0, 10.0, 5.0,
];

/// Collects [`FswSelfReport`] during a run.
pub struct FswMonitor {
    report: FswSelfReport,
    within: u64,
    with_sigma: u64,
    nees_sum: f64,
    groups: Vec<Histogram<u64>>,
}

impl FswMonitor {
    /// An empty monitor (allocates its histograms).
    pub fn new() -> Self {
        let groups = (0..RATE_GROUPS)
            .map(|_| {
                Histogram::new_with_bounds(1, 60_000_000_000, 2)
                    .expect("static histogram bounds are valid")
            })
            .collect();
        Self {
            report: FswSelfReport {
                nav_error_by_altitude: Vec::with_capacity(NAV_ERROR_GATES_M.len()),
                ..FswSelfReport::default()
            },
            within: 0,
            with_sigma: 0,
            nees_sum: 0.0,
            groups,
        }
    }

    /// Folds in Command(k) as received and the truth at t_k.
    pub fn record(&mut self, cmd: &Command, truth: &TruthState, t_ns: i64) {
        let f: &FswReport = &cmd.fsw;
        for (h, &ns) in self.groups.iter_mut().zip(f.group_compute_ns.iter()) {
            if ns > 0 {
                h.saturating_record(u64::from(ns));
            }
        }
        self.report.boot_count = self.report.boot_count.max(f.boot_count);
        self.report.cycle_slips = self.report.cycle_slips.max(f.cycle_slips);
        if f.nav_flags & NAV_FLAG_VALID == 0 {
            return;
        }
        self.report.navigation_reported = true;
        self.report.from_sensors = f.nav_flags & NAV_FLAG_FROM_SENSORS != 0;
        self.report.nav_flags = f.nav_flags;
        let t_s = t_ns as f64 * 1e-9;
        if f.nav_flags & NAV_FLAG_TERRAIN_USED != 0 && self.report.terrain_first_fix_s.is_none() {
            self.report.terrain_first_fix_s = Some(t_s);
        }
        if f.nav_flags & NAV_FLAG_TERRAIN_LOST != 0 {
            self.report.terrain_lost_s.get_or_insert(t_s);
            self.report.terrain_lost_cycles += 1;
        }
        let mut e = [0.0; 3];
        let mut ev = [0.0; 3];
        for i in 0..3 {
            e[i] = f.nav_pos_mci_m[i] - truth.pos_mci_m[i];
            ev[i] = f.nav_vel_mci_m_s[i] - truth.vel_mci_m_s[i];
        }
        let norm = |v: &[f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let r = norm(&truth.pos_mci_m);
        let up = truth.pos_mci_m.map(|x| x / r);
        let radial = e[0] * up[0] + e[1] * up[1] + e[2] * up[2];
        let position = norm(&e);
        let sigma = f.nav_pos_sigma_m;
        let sample = NavErrorSample {
            t_s: t_ns as f64 * 1e-9,
            position_m: position,
            radial_m: radial,
            horizontal_m: (position * position - radial * radial).max(0.0).sqrt(),
            velocity_m_s: norm(&ev),
            altitude_m: f.nav_altitude_m - truth.altitude_m,
            sigma_position_m: norm(&sigma),
        };
        self.report.nav_error = Some(sample);
        // The gates passed since the last record (kept once each: capacity allocated).
        let kept = &mut self.report.nav_error_by_altitude;
        while let Some(&gate) = NAV_ERROR_GATES_M.get(kept.len()) {
            if truth.altitude_m > gate {
                break;
            }
            kept.push((gate, sample));
            if gate == 50.0 {
                self.report.nav_error_50m = Some(sample);
            }
        }
        self.report.nav_error_max_position_m = self.report.nav_error_max_position_m.max(position);
        if sigma.iter().all(|s| *s > 0.0) {
            self.with_sigma += 1;
            if (0..3).all(|i| e[i].abs() <= 3.0 * sigma[i]) {
                self.within += 1;
            }
            self.nees_sum += (0..3).map(|i| (e[i] / sigma[i]).powi(2)).sum::<f64>();
        }
    }

    /// The report at the end of the run.
    pub fn finish(mut self) -> FswSelfReport {
        if self.with_sigma > 0 {
            let n = self.with_sigma as f64;
            self.report.nav_within_3_sigma = Some(self.within as f64 / n);
            self.report.nav_nees_mean = Some(self.nees_sum / n);
        }
        self.report.group_compute_ns = self
            .groups
            .iter()
            .take_while(|h| !h.is_empty())
            .map(|h| crate::timing::Percentiles {
                p50: h.value_at_quantile(0.5),
                p99: h.value_at_quantile(0.99),
                p999: h.value_at_quantile(0.999),
                max: h.max(),
                count: h.len(),
            })
            .collect();
        self.report
    }
}

impl Default for FswMonitor {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth_at(pos: [f64; 3]) -> TruthState {
        TruthState {
            pos_mci_m: pos,
            altitude_m: 100.0,
            ..Default::default()
        }
    }

    #[test]
    fn error_is_estimate_minus_truth_split_about_the_vertical() {
        let mut m = FswMonitor::new();
        let mut c = Command::default();
        c.fsw.nav_flags = NAV_FLAG_VALID | NAV_FLAG_FROM_SENSORS;
        // 3 m up, 4 m across, sigma 2 m per axis: x within 3 sigma, y not.
        c.fsw.nav_pos_mci_m = [1_737_503.0, 4.0, 0.0];
        c.fsw.nav_pos_sigma_m = [2.0, 1.0, 2.0];
        c.fsw.nav_altitude_m = 97.5;
        m.record(&c, &truth_at([1_737_500.0, 0.0, 0.0]), 2_000_000_000);
        let r = m.finish();
        let e = r.nav_error.unwrap();
        assert!((e.position_m - 5.0).abs() < 1e-9, "{e:?}");
        assert!((e.radial_m - 3.0).abs() < 1e-9 && (e.horizontal_m - 4.0).abs() < 1e-6);
        assert_eq!(e.altitude_m, -2.5);
        assert_eq!(r.nav_within_3_sigma, Some(0.0));
        // NEES = (3/2)^2 + (4/1)^2 + 0 = 18.25.
        assert!((r.nav_nees_mean.unwrap() - 18.25).abs() < 1e-9);
        assert!(r.from_sensors);
    }

    #[test]
    fn no_estimate_no_error_and_compute_times_by_group() {
        let mut m = FswMonitor::new();
        let mut c = Command::default();
        c.fsw.group_compute_ns = [1000, 2000, 0, 0];
        c.fsw.boot_count = 2;
        m.record(&c, &truth_at([1_737_500.0, 0.0, 0.0]), 0);
        let r = m.finish();
        assert!(r.nav_error.is_none() && !r.navigation_reported);
        assert_eq!(r.boot_count, 2);
        assert_eq!(r.group_compute_ns.len(), 2);
        assert_eq!(r.group_compute_ns[1].count, 1);
    }
}
