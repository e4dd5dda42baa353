//! Multi-rate time: one base tick (the plant's integration period, `dt_ms`) and named
//! rate groups, each with a period that is a whole multiple of it, all integer
//! nanoseconds and checked before tick 0. The flight-software cycle is the unit of
//! exchange (Telemetry(k) out, Command(k) in and held over the cycle); the plant steps
//! `ticks("fsw")` times per cycle. Sensor rate groups of a later issue are one more
//! [`Schedule::with_group`] each.
//!
//! The propulsion model keeps its own period (the surrogate's sample time, sampled and
//! held under a faster plant, sub-stepped under a slower one; hifi's internal steps):
//! it is reported here beside the groups, and checked where the model is built.

use serde::Serialize;

/// A periodic thing with its period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct RateGroup {
    /// Its name (`plant`, `fsw`, later each sensor).
    pub name: &'static str,
    /// Its period, nanoseconds.
    pub period_ns: u64,
}

/// A period that does not fit the base tick.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the {group} period {period_ns} ns ({period_ms} ms) is not a whole multiple of the base tick, the plant period {base_tick_ns} ns ({base_ms} ms); set --dt-ms or the {group} period so that it is", period_ms = *period_ns as f64 * 1e-6, base_ms = *base_tick_ns as f64 * 1e-6)]
pub struct ScheduleError {
    /// The group whose period does not fit.
    pub group: &'static str,
    /// Its period, nanoseconds.
    pub period_ns: u64,
    /// The base tick, nanoseconds.
    pub base_tick_ns: u64,
}

/// The run's rate groups on one base tick.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Schedule {
    /// The base tick: the plant's integration period, nanoseconds.
    pub base_tick_ns: u64,
    /// Every rate group, the plant's first.
    pub groups: Vec<RateGroup>,
}

impl Schedule {
    /// A schedule on the plant period `plant_period_ns` (the base tick).
    pub fn new(plant_period_ns: u64) -> Self {
        Self {
            base_tick_ns: plant_period_ns,
            groups: vec![RateGroup {
                name: "plant",
                period_ns: plant_period_ns,
            }],
        }
    }

    /// Adds a rate group; its period must be a positive whole multiple of the base tick.
    pub fn with_group(mut self, name: &'static str, period_ns: u64) -> Result<Self, ScheduleError> {
        if period_ns == 0 || self.base_tick_ns == 0 || !period_ns.is_multiple_of(self.base_tick_ns)
        {
            return Err(ScheduleError {
                group: name,
                period_ns,
                base_tick_ns: self.base_tick_ns,
            });
        }
        self.groups.push(RateGroup { name, period_ns });
        Ok(self)
    }

    /// The period of a group, nanoseconds.
    pub fn period_ns(&self, name: &str) -> Option<u64> {
        self.groups
            .iter()
            .find(|g| g.name == name)
            .map(|g| g.period_ns)
    }

    /// Base ticks per period of a group.
    pub fn ticks(&self, name: &str) -> Option<u64> {
        Some(self.period_ns(name)? / self.base_tick_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_period_that_is_not_a_multiple_of_the_base_tick_is_refused_naming_both() {
        let e = Schedule::new(10_000_000)
            .with_group("fsw", 15_000_000)
            .unwrap_err()
            .to_string();
        assert!(e.contains("fsw period 15000000 ns (15 ms)"), "{e}");
        assert!(e.contains("plant period 10000000 ns (10 ms)"), "{e}");
        assert!(Schedule::new(10_000_000).with_group("fsw", 0).is_err());
        let s = Schedule::new(1_000_000)
            .with_group("fsw", 16_000_000)
            .unwrap();
        assert_eq!(s.ticks("fsw"), Some(16));
        assert_eq!(s.ticks("plant"), Some(1));
        assert_eq!(s.period_ns("imu"), None);
    }
}
