//! Sensor faults on the telemetry the flight software is about to see (the truth is
//! untouched): each entry a compiled [`SensorAction`] on a resolved [`TlmField`].

use super::action::{SensorAction, TlmField};
use oils_shared::Telemetry;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

#[derive(Debug, Clone)]
struct Entry {
    /// Position of the fault in the run's list (its bit in the masks).
    index: usize,
    action: SensorAction,
    field: TlmField,
    rng: ChaCha8Rng,
    /// Telemetry held by dropout / frozen faults.
    held: Telemetry,
}

/// The run's sensor faults, in declaration order.
#[derive(Debug, Clone, Default)]
pub struct SensorFaults {
    entries: Vec<Entry>,
    active: u64,
    /// The telemetry of the previous step, as the flight software saw it.
    last_tlm: Option<Telemetry>,
}

impl SensorFaults {
    pub(super) fn add(
        &mut self,
        index: usize,
        action: SensorAction,
        field: TlmField,
        rng: ChaCha8Rng,
    ) {
        self.entries.push(Entry {
            index,
            action,
            field,
            rng,
            held: Telemetry::default(),
        });
    }

    pub(super) fn set_active(&mut self, active: u64) {
        self.active = active;
    }

    /// Applies the active sensor faults to `tlm`. `fired` is the mask of faults that
    /// fired this step. Without a sensor fault declared, the telemetry is never touched
    /// or kept.
    pub fn apply(&mut self, tlm: &mut Telemetry, fired: u64) {
        if self.entries.is_empty() {
            return;
        }
        let before = *tlm;
        for e in &mut self.entries {
            let bit = 1u64 << e.index;
            if self.active & bit == 0 {
                continue;
            }
            match e.action {
                SensorAction::Bias { value } => {
                    for x in e.field.values_mut(tlm) {
                        *x += value;
                    }
                }
                SensorAction::Noise { sigma } => {
                    for x in e.field.values_mut(tlm) {
                        *x += sigma * e.rng.sample::<f64, _>(StandardNormal);
                    }
                }
                SensorAction::Dropout | SensorAction::Frozen => {
                    if fired & bit != 0 {
                        // Dropout repeats the last value seen before; frozen sticks at
                        // the value of the step it fired.
                        e.held = match (e.action, self.last_tlm) {
                            (SensorAction::Dropout, Some(last)) => last,
                            _ => before,
                        };
                    }
                    let mut held = [0.0; 4];
                    let src = e.field.values_mut(&mut e.held);
                    let n = src.len();
                    held[..n].copy_from_slice(src);
                    e.field.values_mut(tlm).copy_from_slice(&held[..n]);
                }
            }
        }
        self.last_tlm = Some(*tlm);
    }
}
