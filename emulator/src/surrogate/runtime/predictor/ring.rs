//! The predictor's history: a ring of records, each stored twice so that the
//! latest `depth` records are always one contiguous window.

use super::aligned::AlignedValues;
use crate::surrogate::runtime::features::{
    command_sum_of, lambda_of, InputVec, StateVec, INPUT_DIM, STATE_DIM, STATE_MF, STATE_MO,
};
use crate::surrogate::runtime::valve::valve_sum_of;
use oils_shared::ENGINE_COUNT;

/// Components of a ring record: the step's inputs, its command sum and the change of
/// the valve sum from the step before, the four valve-filtered commands after it and
/// their sum over the engines that are on, then the state at its end and lambda of that
/// state (each computed once when stored, not per read). Every per-engine group (the
/// commands, the switches, the valves, the thrusts) starts at a multiple of four values
/// and a record is a multiple of four long, so in the 32-byte aligned buffer each is
/// one aligned vector read (unused values pad the gaps).
pub(super) const REC_SUM: usize = INPUT_DIM;
pub(super) const REC_VALVE_SUM_CHANGE: usize = REC_SUM + 1;
pub(super) const REC_VALVE: usize = 12;
pub(super) const REC_VALVE_SUM: usize = REC_VALVE + ENGINE_COUNT;
pub(super) const REC_STATE: usize = 20;
pub(super) const REC_LAMBDA: usize = REC_STATE + STATE_DIM;
pub(super) const REC_DIM: usize = 28;

// The layout above: groups in order without overlap, engine groups and records on
// four-value boundaries (the switches follow the four commands, so the engine count
// must keep them there too).
const _: () = {
    assert!(REC_VALVE_SUM_CHANGE < REC_VALVE && REC_VALVE_SUM < REC_STATE);
    assert!(REC_LAMBDA < REC_DIM);
    assert!(REC_VALVE.is_multiple_of(4) && REC_STATE.is_multiple_of(4));
    assert!(ENGINE_COUNT.is_multiple_of(4));
    assert!(REC_DIM.is_multiple_of(4) && INPUT_DIM.is_multiple_of(4));
};

/// The history: the last `depth` records, each stored twice (at `i` and `i + depth`), so
/// that the records from `depth - 1` steps back to the latest always lie in one
/// contiguous window. A feature is then a fixed offset into the window, found when the
/// model is compiled, instead of a wrap-around computation per read.
#[derive(Debug, Clone)]
pub(super) struct Ring {
    pub(super) buf: AlignedValues,
    pub(super) depth: usize,
    /// Record index of the step being predicted, `0..depth`.
    pub(super) head: usize,
}

impl Ring {
    pub(super) fn new(depth: usize) -> Self {
        Self {
            buf: AlignedValues::zeros(2 * depth * REC_DIM),
            depth,
            head: 0,
        }
    }

    /// Where component `comp` of the record `lag` steps back lies in the window.
    pub(super) fn offset(depth: usize, lag: usize, comp: usize) -> usize {
        (depth - 1 - lag) * REC_DIM + comp
    }

    /// The window: record `head - depth + 1` (wrapped) first, `head` last.
    #[inline(always)]
    pub(super) fn window(&self) -> &[f64] {
        let start = (self.head + 1) * REC_DIM;
        &self.buf[start..start + self.depth * REC_DIM]
    }

    /// The record `lag` steps back.
    pub(super) fn rec(&self, lag: usize) -> &[f64] {
        let i = self.head + self.depth - lag;
        &self.buf[i * REC_DIM..(i + 1) * REC_DIM]
    }

    /// Moves `head` on by one record (a compare, not the division of `%`, on the step
    /// path) and returns it.
    #[inline(always)]
    pub(super) fn advance(&mut self) -> usize {
        self.head += 1;
        if self.head == self.depth {
            self.head = 0;
        }
        self.head
    }

    /// Index of the record `lag` steps back.
    pub(super) fn index(&self, lag: usize) -> usize {
        (self.head + self.depth - lag) % self.depth
    }

    /// Writes `values` from component `comp` of record `i`, in both copies, then
    /// `last` after them. `last` is written on its own rather than assembled with the
    /// values into one array first: such an array, written value by value and then read
    /// back wide, waits for the narrow writes (a store-forwarding stall that profiled
    /// among the step's hottest instructions). `N` is a constant so that the copy is a
    /// few moves: over a slice of run-time length it compiled to a call to `memcpy`, and
    /// removing those calls took the probe's step from about 225 to about 195 ns.
    #[inline(always)]
    pub(super) fn write<const N: usize>(
        &mut self,
        i: usize,
        comp: usize,
        values: &[f64; N],
        last: Option<f64>,
    ) {
        for copy in [i, i + self.depth] {
            let at = copy * REC_DIM + comp;
            let r: &mut [f64; N] = (&mut self.buf[at..at + N])
                .try_into()
                .expect("a slice of N values");
            *r = *values;
            if let Some(v) = last {
                self.buf[at + N] = v;
            }
        }
    }

    pub(super) fn set_state(&mut self, i: usize, s: &StateVec) {
        let lambda = lambda_of(s[STATE_MF], s[STATE_MO]);
        self.write(i, REC_STATE, s, Some(lambda));
    }

    /// The valve positions after step `i`, whose inputs were `u`; `sum_before` is what
    /// the engines drew after the step before ([`valve_sum_of`]).
    pub(super) fn set_valve(
        &mut self,
        i: usize,
        valve_n: &[f64; ENGINE_COUNT],
        u: &InputVec,
        sum_before: f64,
    ) {
        let sum = valve_sum_of(u, valve_n);
        self.write(i, REC_VALVE, valve_n, Some(sum));
        self.write(i, REC_VALVE_SUM_CHANGE, &[sum - sum_before], None);
    }

    /// What the engines drew after the step `lag` steps back ([`valve_sum_of`]).
    #[inline(always)]
    pub(super) fn valve_sum(&self, lag: usize) -> f64 {
        self.rec(lag)[REC_VALVE_SUM]
    }

    pub(super) fn set_input(&mut self, i: usize, u: &InputVec) {
        self.write(i, 0, u, Some(command_sum_of(u)));
    }

    /// The latest state.
    pub(super) fn state(&self) -> StateVec {
        self.state_at(0)
    }

    /// The state `lag` steps back.
    pub(super) fn state_at(&self, lag: usize) -> StateVec {
        let r = self.rec(lag);
        std::array::from_fn(|k| r[REC_STATE + k])
    }
}
