//! How the scheduler paces steps, as a [`StepClock`]:
//!
//! * [`LockstepClock`]: no pacing; step k+1 starts as soon as Command(k) is in. A command
//!   that does not come within the link timeout means the flight software is gone.
//! * [`RealtimeClock`]: step k starts at `t0 + k dt / speed` on the monotonic clock
//!   (absolute sleep, then a short spin); Command(k) is due `deadline_frac` of a period
//!   after the step's start, or it is a deadline miss.
//! * [`ReplayClock`]: no pacing, and a step without a recorded command is a miss, as it
//!   was in the recorded run.
//!
//! Simulated time never comes from here: it is the step count times the step. The
//! realtime clock reads and sleeps on a [`TimeSource`] (the monotonic clock in a run, a
//! simulated one in tests), so its schedule is tested without wall time.

use oils_shared::clock::{monotonic_ns, sleep_until_ns};
use std::sync::atomic::{AtomicBool, Ordering};

/// Longest single sleep while waiting for a step start: a stop request is seen within
/// this, whatever the period.
const STOP_CHECK_NS: u64 = 20_000_000;

/// Where a pacing clock reads the time and sleeps.
pub trait TimeSource {
    /// Now, monotonic nanoseconds.
    fn now_ns(&mut self) -> u64;
    /// Sleeps until `t_ns`, the last `spin_ns` of it spun rather than slept.
    fn sleep_until_ns(&mut self, t_ns: u64, spin_ns: u64);
}

/// The operating system's monotonic clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct Monotonic;

impl TimeSource for Monotonic {
    fn now_ns(&mut self) -> u64 {
        monotonic_ns()
    }
    fn sleep_until_ns(&mut self, t_ns: u64, spin_ns: u64) {
        sleep_until_ns(t_ns, spin_ns);
    }
}

/// Paces the scheduler's steps.
pub trait StepClock {
    /// Called once, just before step 0.
    fn start(&mut self);
    /// Waits until step `k` may start. Returns how late it started, nanoseconds, for a
    /// clock that schedules starts, `None` for one that does not. Returns early (with
    /// `None`) when `stop` is raised.
    fn wait_for_step(&mut self, k: u64, stop: &AtomicBool) -> Option<u64>;
    /// Monotonic time by which Command(k) must arrive, given when Telemetry(k) went out.
    fn command_deadline_ns(&self, k: u64, published_ns: u64) -> u64;
    /// Whether a command missing at its deadline is a deadline miss (the run goes on
    /// under the miss policy) rather than a dead flight software.
    fn misses_allowed(&self) -> bool;
    /// When the run's stepping started, monotonic nanoseconds (for wall time).
    fn started_ns(&self) -> u64;
    /// Whether cycle `k`'s work ended after cycle k+1 was due (a realtime overrun).
    fn cycle_overran(&mut self, _k: u64) -> bool {
        false
    }
    /// Whether this clock replays a recorded run (its misses are the record's).
    fn is_replay(&self) -> bool {
        false
    }
}

/// Lockstep: wait for every command, up to the link timeout.
pub struct LockstepClock {
    timeout_ns: u64,
    started_ns: u64,
}

impl LockstepClock {
    /// A lockstep clock declaring the flight software dead after `link_timeout_ms`.
    pub fn new(link_timeout_ms: u64) -> Self {
        Self {
            timeout_ns: link_timeout_ms.saturating_mul(1_000_000),
            started_ns: 0,
        }
    }
}

impl StepClock for LockstepClock {
    fn start(&mut self) {
        self.started_ns = monotonic_ns();
    }
    fn wait_for_step(&mut self, _k: u64, _stop: &AtomicBool) -> Option<u64> {
        None
    }
    fn command_deadline_ns(&self, _k: u64, published_ns: u64) -> u64 {
        published_ns.saturating_add(self.timeout_ns)
    }
    fn misses_allowed(&self) -> bool {
        false
    }
    fn started_ns(&self) -> u64 {
        self.started_ns
    }
}

/// Realtime: absolute monotonic step starts, commands due by a fraction of a period.
pub struct RealtimeClock<T: TimeSource = Monotonic> {
    period_ns: u64,
    deadline_ns: u64,
    wake_spin_ns: u64,
    t0_ns: u64,
    time: T,
}

impl RealtimeClock {
    /// Steps of `dt_ns` at `speed` times real time; commands due `deadline_frac` of a
    /// period after each start; the last `wake_spin_ns` before a start spun, not slept.
    pub fn new(dt_ns: u64, speed: f64, deadline_frac: f64, wake_spin_ns: u64) -> Self {
        Self::with_time_source(dt_ns, speed, deadline_frac, wake_spin_ns, Monotonic)
    }
}

impl<T: TimeSource> RealtimeClock<T> {
    /// [`RealtimeClock::new`] on another time source.
    pub fn with_time_source(
        dt_ns: u64,
        speed: f64,
        deadline_frac: f64,
        wake_spin_ns: u64,
        time: T,
    ) -> Self {
        let period_ns = ((dt_ns as f64) / speed).round().max(1.0) as u64;
        Self {
            period_ns,
            deadline_ns: (deadline_frac * period_ns as f64) as u64,
            wake_spin_ns,
            t0_ns: 0,
            time,
        }
    }

    /// The time source, for inspection.
    pub fn time_source(&self) -> &T {
        &self.time
    }

    fn scheduled_ns(&self, k: u64) -> u64 {
        self.t0_ns.saturating_add(k.saturating_mul(self.period_ns))
    }
}

impl<T: TimeSource> StepClock for RealtimeClock<T> {
    fn start(&mut self) {
        // Step 0 one period from now: the flight software has a whole period to settle.
        self.t0_ns = self.time.now_ns() + self.period_ns;
    }
    fn wait_for_step(&mut self, k: u64, stop: &AtomicBool) -> Option<u64> {
        let scheduled = self.scheduled_ns(k);
        // Sleep in slices so a stop request is acted on promptly even at slow speeds.
        loop {
            let now = self.time.now_ns();
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            if scheduled.saturating_sub(now) <= STOP_CHECK_NS {
                break;
            }
            self.time.sleep_until_ns(now + STOP_CHECK_NS, 0);
        }
        self.time.sleep_until_ns(scheduled, self.wake_spin_ns);
        Some(self.time.now_ns().saturating_sub(scheduled))
    }
    fn command_deadline_ns(&self, k: u64, _published_ns: u64) -> u64 {
        self.scheduled_ns(k).saturating_add(self.deadline_ns)
    }
    fn cycle_overran(&mut self, k: u64) -> bool {
        self.time.now_ns() > self.scheduled_ns(k + 1)
    }
    fn misses_allowed(&self) -> bool {
        true
    }
    fn started_ns(&self) -> u64 {
        self.t0_ns
    }
}

/// Replay: no pacing; the recorded run decides which steps had commands.
#[derive(Default)]
pub struct ReplayClock {
    started_ns: u64,
}

impl StepClock for ReplayClock {
    fn start(&mut self) {
        self.started_ns = monotonic_ns();
    }
    fn wait_for_step(&mut self, _k: u64, _stop: &AtomicBool) -> Option<u64> {
        None
    }
    fn command_deadline_ns(&self, _k: u64, published_ns: u64) -> u64 {
        published_ns
    }
    fn is_replay(&self) -> bool {
        true
    }
    fn misses_allowed(&self) -> bool {
        true
    }
    fn started_ns(&self) -> u64 {
        self.started_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Simulated time: a sleep jumps to its target (plus a fixed oversleep), and the
    /// sleeps are kept for the test to read. An optional stop is raised after a number
    /// of sleeps, as a signal handler would.
    struct SimTime<'a> {
        now_ns: u64,
        oversleep_ns: u64,
        sleeps: Vec<(u64, u64)>,
        stop_after: Option<(usize, &'a AtomicBool)>,
    }

    impl<'a> SimTime<'a> {
        fn new(oversleep_ns: u64) -> Self {
            Self {
                now_ns: 1_000,
                oversleep_ns,
                sleeps: Vec::new(),
                stop_after: None,
            }
        }
    }

    impl TimeSource for SimTime<'_> {
        fn now_ns(&mut self) -> u64 {
            self.now_ns
        }
        fn sleep_until_ns(&mut self, t_ns: u64, spin_ns: u64) {
            self.sleeps.push((t_ns, spin_ns));
            self.now_ns = self.now_ns.max(t_ns) + self.oversleep_ns;
            if let Some((n, stop)) = self.stop_after {
                if self.sleeps.len() == n {
                    stop.store(true, Ordering::Relaxed);
                }
            }
        }
    }

    #[test]
    fn realtime_wait_sleeps_in_slices_and_honours_a_stop_request_between_them() {
        // One step every 100 s: the stop raised during the third slice is seen before a
        // fourth, so the wait ends 60 ms (simulated) in, not 100 s.
        let stop = AtomicBool::new(false);
        let mut time = SimTime::new(0);
        time.stop_after = Some((3, &stop));
        let mut clock = RealtimeClock::with_time_source(10_000_000, 1e-4, 0.5, 0, time);
        clock.start();
        assert_eq!(clock.wait_for_step(0, &stop), None);
        let sleeps = &clock.time_source().sleeps;
        assert_eq!(sleeps.len(), 3);
        let mut from = 1_000;
        for &(until, spin) in sleeps {
            assert_eq!(until - from, STOP_CHECK_NS);
            assert_eq!(spin, 0);
            from = until;
        }
    }

    #[test]
    fn realtime_steps_start_on_the_absolute_schedule_and_report_how_late() {
        // 10 ms at 4x: a start every 2.5 ms from one period after start(); each sleep
        // overshoots by 30 us, which is the wake error reported, and never accumulates.
        let stop = AtomicBool::new(false);
        let mut clock =
            RealtimeClock::with_time_source(10_000_000, 4.0, 0.5, 50_000, SimTime::new(30_000));
        clock.start();
        let t0 = clock.started_ns();
        assert_eq!(t0, 1_000 + 2_500_000);
        for k in 0..100 {
            assert_eq!(clock.wait_for_step(k, &stop), Some(30_000), "step {k}");
        }
        let sleeps = &clock.time_source().sleeps;
        assert_eq!(sleeps.len(), 100);
        for (k, &(until, spin)) in sleeps.iter().enumerate() {
            assert_eq!(until, t0 + k as u64 * 2_500_000);
            assert_eq!(spin, 50_000);
        }
    }

    #[test]
    fn realtime_deadlines_follow_the_schedule() {
        let mut clock = RealtimeClock::new(10_000_000, 2.0, 0.5, 0);
        clock.start();
        let d0 = clock.command_deadline_ns(0, 0);
        let d1 = clock.command_deadline_ns(1, 0);
        assert_eq!(d1 - d0, 5_000_000);
        assert_eq!(d0 - clock.started_ns(), 2_500_000);
    }
}
