//! How a compiled submodel reads its features: positions in the history window,
//! envelope clamp and scaling, phase indicators and ignition features.

use crate::surrogate::runtime::valve::NOT_IGNITED;
use oils_shared::ENGINE_COUNT;

/// One feature an active term uses, compiled to a read of the history window (see
/// [`super::ring::Ring`]) at a fixed `offset`: the record `lag` steps back, component
/// `comp` (for a per-engine feature, engine 0's; the four engines' values follow it),
/// then clamped to the envelope and scaled.
#[derive(Debug, Clone, Copy)]
pub(super) struct Gather {
    pub(super) offset: usize,
    pub(super) scaling: FeatureScaling,
}

/// A phase indicator an active term uses: 1 when the engine's switch is `on` and has been
/// for exactly `run` steps.
#[derive(Debug, Clone, Copy)]
pub(super) struct PhaseGather {
    pub(super) slot: usize,
    pub(super) on: bool,
    pub(super) run: usize,
    pub(super) scaling: FeatureScaling,
}

/// An ignition feature an active term uses: the priming indicator (`hat` None) or hat
/// function `hat` of the time since ignition.
#[derive(Debug, Clone, Copy)]
pub(super) struct ClockGather {
    pub(super) slot: usize,
    pub(super) hat: Option<usize>,
    pub(super) scaling: FeatureScaling,
}

/// The engines' ignition clocks after the step being predicted (see
/// [`crate::surrogate::runtime::valve::IgnitionClock`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Clock {
    pub(super) since_ignition_s: [f64; ENGINE_COUNT],
    /// Engines whose ignition features may be non-zero: on, and not past the last hat.
    pub(super) active: [bool; ENGINE_COUNT],
    /// Some engine is active.
    pub(super) any: bool,
}

impl Clock {
    pub(super) const IDLE: Self = Self {
        since_ignition_s: [NOT_IGNITED; ENGINE_COUNT],
        active: [false; ENGINE_COUNT],
        any: false,
    };
}

#[derive(Debug, Clone, Copy)]
pub(super) struct FeatureScaling {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) mean: f64,
    pub(super) inv_std: f64,
}

impl FeatureScaling {
    /// Clamps to the envelope and scales one raw value; the second value is non-zero when
    /// it was outside. (Comparisons rather than `clamp`, which asserts lo <= hi on every
    /// call, or `max`/`min`, which spend instructions on NaN. A NaN feature stays NaN,
    /// makes the prediction non-finite, and the step's guard keeps the previous state and
    /// counts the step. "Outside" is "the clamp changed a bit": an integer OR to collect,
    /// cheaper than a floating comparison.)
    #[inline(always)]
    pub(super) fn apply(&self, raw: f64) -> (f64, u64) {
        let (v, out) = self.clamp(raw);
        ((v - self.mean) * self.inv_std, out)
    }

    /// Clamps only (for a submodel whose coefficients hold the scaling).
    #[inline(always)]
    pub(super) fn clamp(&self, raw: f64) -> (f64, u64) {
        let v = if raw < self.lo { self.lo } else { raw };
        let v = if v > self.hi { self.hi } else { v };
        (v, v.to_bits() ^ raw.to_bits())
    }
}

/// Per-engine switch phase at the latest step: the switch and how many consecutive steps
/// it has had that value, saturated at `cap + 1`. Kept incrementally so the phase
/// indicators cost a comparison; equal to scanning the history (`features::phase_age`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Phases {
    pub(super) on: [bool; ENGINE_COUNT],
    pub(super) run: [usize; ENGINE_COUNT],
    pub(super) cap: usize,
}

/// The per-engine reads of [`super::compiled::CompiledSub::gather`] in AVX2 vectors: a
/// feature's four engines are adjacent in the window, so each is one read, one clamp and
/// one scaling. Written with intrinsics because the compiler vectorised the portable loop
/// across four features at a time and transposed them back. The same IEEE operations per
/// lane as [`FeatureScaling::apply`] (see [`super::dense::Dense::chunks_avx2`] for the
/// clamp), so the same bits; tested against the portable path. Returns the bits the
/// clamps changed.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn gather_lanes_avx2(
    lanes: &[Gather],
    window: &[f64],
    x: &mut [[f64; 4]],
) -> u64 {
    use std::arch::x86_64::*;
    let mut changed = _mm256_setzero_pd();
    for (g, x) in lanes.iter().zip(x) {
        debug_assert!(g.offset + 4 <= window.len());
        // SAFETY: `compile` places every read and the engines after it in the window.
        let raw = unsafe { _mm256_loadu_pd(window.as_ptr().add(g.offset)) };
        let sc = g.scaling;
        let v = _mm256_min_pd(
            _mm256_set1_pd(sc.hi),
            _mm256_max_pd(_mm256_set1_pd(sc.lo), raw),
        );
        changed = _mm256_or_pd(changed, _mm256_xor_pd(v, raw));
        let scaled = _mm256_mul_pd(
            _mm256_sub_pd(v, _mm256_set1_pd(sc.mean)),
            _mm256_set1_pd(sc.inv_std),
        );
        // SAFETY: `x` holds four values.
        unsafe { _mm256_storeu_pd(x.as_mut_ptr(), scaled) };
    }
    let mut bits = [0u64; 4];
    // SAFETY: four 64-bit values.
    unsafe { _mm256_storeu_pd(bits.as_mut_ptr().cast(), changed) };
    bits[0] | bits[1] | bits[2] | bits[3]
}
