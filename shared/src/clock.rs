//! The monotonic clock, for pacing and timing only (never for the plant or the flight
//! software, whose time is the step count).
//!
//! Written over `libc` by hand because pacing needs *absolute* `clock_nanosleep` on
//! `CLOCK_MONOTONIC` (relative sleeps accumulate drift), which `std` does not offer.

/// Nanoseconds on `CLOCK_MONOTONIC`.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid pointer to a timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// [`monotonic_ns`] when `timed`, else 0 without reading the clock: for the figures a run
/// may choose not to time (a campaign case's round trips and compute times).
pub fn monotonic_ns_if(timed: bool) -> u64 {
    if timed {
        monotonic_ns()
    } else {
        0
    }
}

/// Sleeps until the monotonic time `deadline_ns` (absolute), then spins for the last
/// `spin_ns`: the kernel wakes us tens of microseconds late, the spin absorbs that.
pub fn sleep_until_ns(deadline_ns: u64, spin_ns: u64) {
    let sleep_to = deadline_ns.saturating_sub(spin_ns);
    if monotonic_ns() < sleep_to {
        let ts = libc::timespec {
            tv_sec: (sleep_to / 1_000_000_000) as libc::time_t,
            tv_nsec: (sleep_to % 1_000_000_000) as libc::c_long,
        };
        // SAFETY: valid timespec; EINTR just ends the sleep early and the spin covers it.
        unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                core::ptr::null_mut(),
            )
        };
    }
    while monotonic_ns() < deadline_ns {
        core::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn never_wakes_early() {
        let target = monotonic_ns() + 2_000_000;
        sleep_until_ns(target, 100_000);
        assert!(monotonic_ns() >= target);
    }
}
