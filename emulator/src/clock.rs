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
//! Simulated time never comes from here: it is the step count times the step.

use oils_shared::clock::{monotonic_ns, sleep_until_ns};
use std::sync::atomic::{AtomicBool, Ordering};

/// Longest single sleep while waiting for a step start: a stop request is seen within
/// this, whatever the period.
const STOP_CHECK_NS: u64 = 20_000_000;

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
pub struct RealtimeClock {
    period_ns: u64,
    deadline_ns: u64,
    wake_spin_ns: u64,
    t0_ns: u64,
}

impl RealtimeClock {
    /// Steps of `dt_ns` at `speed` times real time; commands due `deadline_frac` of a
    /// period after each start; the last `wake_spin_ns` before a start spun, not slept.
    pub fn new(dt_ns: u64, speed: f64, deadline_frac: f64, wake_spin_ns: u64) -> Self {
        let period_ns = ((dt_ns as f64) / speed).round().max(1.0) as u64;
        Self {
            period_ns,
            deadline_ns: (deadline_frac * period_ns as f64) as u64,
            wake_spin_ns,
            t0_ns: 0,
        }
    }

    fn scheduled_ns(&self, k: u64) -> u64 {
        self.t0_ns.saturating_add(k.saturating_mul(self.period_ns))
    }
}

impl StepClock for RealtimeClock {
    fn start(&mut self) {
        // Step 0 one period from now: the flight software has a whole period to settle.
        self.t0_ns = monotonic_ns() + self.period_ns;
    }
    fn wait_for_step(&mut self, k: u64, stop: &AtomicBool) -> Option<u64> {
        let scheduled = self.scheduled_ns(k);
        // Sleep in slices so a stop request is acted on promptly even at slow speeds.
        loop {
            let now = monotonic_ns();
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            if scheduled.saturating_sub(now) <= STOP_CHECK_NS {
                break;
            }
            sleep_until_ns(now + STOP_CHECK_NS, 0);
        }
        sleep_until_ns(scheduled, self.wake_spin_ns);
        Some(monotonic_ns().saturating_sub(scheduled))
    }
    fn command_deadline_ns(&self, k: u64, _published_ns: u64) -> u64 {
        self.scheduled_ns(k).saturating_add(self.deadline_ns)
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

    #[test]
    fn realtime_wait_honours_a_stop_request_within_a_slice() {
        // One step every 100 s: without slices the wait would take 100 s.
        let mut clock = RealtimeClock::new(10_000_000, 1e-4, 0.5, 0);
        clock.start();
        let stop = AtomicBool::new(false);
        let t = std::time::Instant::now();
        std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(std::time::Duration::from_millis(50));
                stop.store(true, Ordering::Relaxed);
            });
            assert_eq!(clock.wait_for_step(0, &stop), None);
        });
        assert!(t.elapsed() < std::time::Duration::from_secs(5));
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
