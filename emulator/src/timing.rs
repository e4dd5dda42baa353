//! The timing monitor: histograms of the four timing figures and the deadline count,
//! each with exactly the meaning DESIGN.md gives it:
//!
//! * wake error: when step k actually started minus when it was scheduled (realtime);
//! * round trip: Telemetry(k) published until Command(k) received by the emulator;
//! * stub compute: the flight software's own step time, carried in the command;
//! * transport: round trip minus stub compute, what the link itself costs;
//! * deadline miss: Command(k) not received by step k's deadline.
//!
//! Histograms are allocated once in `new`; recording never allocates.

use hdrhistogram::Histogram;
use serde::Serialize;

/// Largest value a histogram tracks exactly, nanoseconds (larger values saturate).
const HIGHEST_NS: u64 = 60_000_000_000;

/// Percentiles of one timing figure, nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Percentiles {
    /// Median.
    pub p50: u64,
    /// 99th percentile.
    pub p99: u64,
    /// 99.9th percentile.
    pub p999: u64,
    /// Largest value recorded.
    pub max: u64,
    /// Number of samples.
    pub count: u64,
}

/// Timing figures of a run, as reported.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct TimingSummary {
    /// Wake error (realtime only; empty in lockstep).
    pub wake_error_ns: Percentiles,
    /// Round trip.
    pub round_trip_ns: Percentiles,
    /// Stub compute.
    pub stub_compute_ns: Percentiles,
    /// Transport.
    pub transport_ns: Percentiles,
    /// Steps whose command missed its deadline.
    pub deadline_misses: u64,
    /// Commands that arrived after their deadline and were discarded.
    pub late_commands: u64,
    /// Wall-clock duration of the stepping loop, seconds.
    pub wall_s: f64,
    /// Simulated time over wall time.
    pub realtime_factor: f64,
}

/// Collects timing figures during a run.
pub struct TimingMonitor {
    wake_error: Histogram<u64>,
    round_trip: Histogram<u64>,
    stub_compute: Histogram<u64>,
    transport: Histogram<u64>,
    deadline_misses: u64,
    late_commands: u64,
}

fn histogram() -> Histogram<u64> {
    // 3 significant digits over 1 ns .. 60 s: about 200 kB per histogram, allocated once.
    Histogram::new_with_bounds(1, HIGHEST_NS, 3).expect("constant bounds are valid")
}

impl Default for TimingMonitor {
    fn default() -> Self {
        Self::new()
    }
}

impl TimingMonitor {
    /// Empty histograms.
    pub fn new() -> Self {
        Self {
            wake_error: histogram(),
            round_trip: histogram(),
            stub_compute: histogram(),
            transport: histogram(),
            deadline_misses: 0,
            late_commands: 0,
        }
    }

    /// Records how late step k started (realtime).
    pub fn record_wake_error(&mut self, late_ns: u64) {
        self.wake_error.saturating_record(late_ns);
    }

    /// Records one telemetry-command exchange over a link with a transport.
    pub fn record_exchange(&mut self, round_trip_ns: u64, stub_compute_ns: u64) {
        self.record_in_process(round_trip_ns, stub_compute_ns);
        self.transport
            .saturating_record(round_trip_ns.saturating_sub(stub_compute_ns));
    }

    /// Records one exchange with the flight software in the emulator's thread: there is
    /// no transport, so none is recorded (the figure stays absent, not zero-filled).
    pub fn record_in_process(&mut self, round_trip_ns: u64, stub_compute_ns: u64) {
        self.round_trip.saturating_record(round_trip_ns);
        self.stub_compute.saturating_record(stub_compute_ns);
    }

    /// Counts a step whose command missed its deadline.
    pub fn record_deadline_miss(&mut self) {
        self.deadline_misses += 1;
    }

    /// Counts a command that arrived after its deadline.
    pub fn record_late_command(&mut self) {
        self.late_commands += 1;
    }

    /// Deadline misses so far.
    pub fn deadline_misses(&self) -> u64 {
        self.deadline_misses
    }

    /// The summary, given the loop's wall time and the simulated time covered.
    pub fn summary(&self, wall_s: f64, sim_s: f64) -> TimingSummary {
        let p = |h: &Histogram<u64>| {
            if h.is_empty() {
                return Percentiles::default();
            }
            Percentiles {
                p50: h.value_at_quantile(0.50),
                p99: h.value_at_quantile(0.99),
                p999: h.value_at_quantile(0.999),
                max: h.max(),
                count: h.len(),
            }
        };
        TimingSummary {
            wake_error_ns: p(&self.wake_error),
            round_trip_ns: p(&self.round_trip),
            stub_compute_ns: p(&self.stub_compute),
            transport_ns: p(&self.transport),
            deadline_misses: self.deadline_misses,
            late_commands: self.late_commands,
            wall_s,
            realtime_factor: if wall_s > 0.0 { sim_s / wall_s } else { 0.0 },
        }
    }
}

/// Bounds a run must meet; a broken one makes the run exit non-zero.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct TimingThresholds {
    /// Largest allowed p99 wake error, nanoseconds.
    pub wake_error_p99_ns: Option<u64>,
    /// Largest allowed p99 round trip, nanoseconds.
    pub round_trip_p99_ns: Option<u64>,
    /// Largest allowed p99 transport, nanoseconds.
    pub transport_p99_ns: Option<u64>,
    /// Largest allowed number of deadline misses.
    pub deadline_misses: Option<u64>,
}

impl TimingThresholds {
    /// Every bound the summary breaks, as sentences.
    pub fn violations(&self, s: &TimingSummary) -> Vec<String> {
        let mut out = Vec::new();
        let mut check = |name: &str, bound: Option<u64>, value: u64| {
            if let Some(b) = bound {
                if value > b {
                    out.push(format!("{name} = {value} exceeds the threshold {b}"));
                }
            }
        };
        check(
            "wake_error p99 ns",
            self.wake_error_p99_ns,
            s.wake_error_ns.p99,
        );
        check(
            "round_trip p99 ns",
            self.round_trip_p99_ns,
            s.round_trip_ns.p99,
        );
        check(
            "transport p99 ns",
            self.transport_p99_ns,
            s.transport_ns.p99,
        );
        check("deadline_misses", self.deadline_misses, s.deadline_misses);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transport_is_round_trip_minus_compute() {
        let mut m = TimingMonitor::new();
        for i in 0..100 {
            m.record_exchange(10_000 + i, 4_000);
        }
        let s = m.summary(1.0, 2.0);
        assert!(
            (s.transport_ns.p50 as i64 - 6_050).abs() <= 10,
            "{:?}",
            s.transport_ns
        );
        // Values come back at the histogram's precision: 3 significant digits.
        assert!(
            (s.stub_compute_ns.max as i64 - 4_000).abs() <= 4,
            "{:?}",
            s.stub_compute_ns
        );
        assert_eq!(s.round_trip_ns.count, 100);
        assert_eq!(s.realtime_factor, 2.0);
        assert_eq!(s.wake_error_ns, Percentiles::default());
    }

    #[test]
    fn thresholds_name_what_broke() {
        let mut m = TimingMonitor::new();
        m.record_wake_error(50_000);
        m.record_deadline_miss();
        let s = m.summary(1.0, 1.0);
        let t = TimingThresholds {
            wake_error_p99_ns: Some(20_000),
            deadline_misses: Some(0),
            ..Default::default()
        };
        let v = t.violations(&s);
        assert_eq!(v.len(), 2, "{v:?}");
        assert!(v[0].contains("wake_error"));
        assert!(TimingThresholds::default().violations(&s).is_empty());
    }
}
