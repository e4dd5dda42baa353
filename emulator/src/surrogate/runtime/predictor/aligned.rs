//! Storage whose four-value vectors never straddle a cache line: the gathered features
//! and the history ring.

/// 32 bytes, aligned to 32: one AVX2 vector.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(32))]
struct Block([f64; 4]);

/// The gathered features of a compiled submodel, one `[f64; LANES]` per slot, with the
/// first slot on a 32-byte boundary. Why: the term loops read a slot's four engine
/// lanes as one vector, and a `Vec<[f64; 4]>` is only 8-aligned (the allocator placed
/// it at 48 modulo 64 in the bench), so every other slot straddled two cache lines and
/// its read cost two. Aligned, a 32-byte slot lies within one line.
#[derive(Debug, Clone)]
pub(super) struct LaneSlots<const LANES: usize> {
    /// The slots' values, slot after slot.
    values: AlignedValues,
}

impl<const LANES: usize> LaneSlots<LANES> {
    /// Holds `values`, in order.
    pub(super) fn new(values: &[[f64; LANES]]) -> Self {
        let mut s = Self {
            values: AlignedValues::zeros(values.len() * LANES),
        };
        s.slots_mut().copy_from_slice(values);
        s
    }

    /// The slots.
    #[inline(always)]
    pub(super) fn slots(&self) -> &[[f64; LANES]] {
        // SAFETY: `values` holds `len * LANES` contiguous f64 and `[f64; LANES]` needs
        // only f64 alignment.
        unsafe {
            std::slice::from_raw_parts(self.values.as_ptr().cast(), self.values.len() / LANES)
        }
    }

    /// The slots, to write.
    #[inline(always)]
    pub(super) fn slots_mut(&mut self) -> &mut [[f64; LANES]] {
        let len = self.values.len() / LANES;
        // SAFETY: as in `slots`, and borrowed mutably through `self`.
        unsafe { std::slice::from_raw_parts_mut(self.values.as_mut_ptr().cast(), len) }
    }
}

/// `slots` regrouped as four-lane slots when `LANES` is 4 (a per-engine submodel, whose
/// AVX2 paths take one vector per slot), `None` otherwise: the same values, without an
/// unsafe cast at each use.
#[inline(always)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(super) fn four_lanes<const LANES: usize>(slots: &[[f64; LANES]]) -> Option<&[[f64; 4]]> {
    (LANES == 4).then_some(slots.as_flattened().as_chunks::<4>().0)
}

/// [`four_lanes`], to write.
#[inline(always)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(super) fn four_lanes_mut<const LANES: usize>(
    slots: &mut [[f64; LANES]],
) -> Option<&mut [[f64; 4]]> {
    (LANES == 4).then_some(slots.as_flattened_mut().as_chunks_mut::<4>().0)
}

/// `len` values from a 32-byte boundary: the history ring's buffer (its records, and
/// the engines' values within them, are laid out so that each engine vector is a
/// 32-byte aligned read, see [`super::ring`]) and [`LaneSlots`]' store.
#[derive(Debug, Clone)]
pub(super) struct AlignedValues {
    store: Vec<Block>,
    len: usize,
}

impl AlignedValues {
    /// `len` zeros.
    pub(super) fn zeros(len: usize) -> Self {
        Self {
            store: vec![Block::default(); len.div_ceil(4)],
            len,
        }
    }
}

impl std::ops::Deref for AlignedValues {
    type Target = [f64];

    #[inline(always)]
    fn deref(&self) -> &[f64] {
        // SAFETY: `store` holds at least `len` contiguous f64 (a `Block` is four f64
        // with no padding, `repr(C)`); f64 needs less alignment than a `Block`.
        unsafe { std::slice::from_raw_parts(self.store.as_ptr().cast(), self.len) }
    }
}

impl std::ops::DerefMut for AlignedValues {
    #[inline(always)]
    fn deref_mut(&mut self) -> &mut [f64] {
        // SAFETY: as in `deref`, borrowed mutably through `self`.
        unsafe { std::slice::from_raw_parts_mut(self.store.as_mut_ptr().cast(), self.len) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_hold_their_values_on_a_32_byte_boundary() {
        let four: Vec<[f64; 4]> = (0..5).map(|i| [i as f64, 1.0, 2.0, 3.0]).collect();
        let mut s = LaneSlots::new(&four);
        assert_eq!(s.slots(), &four[..]);
        assert_eq!(s.slots().as_ptr() as usize % 32, 0);
        s.slots_mut()[4][2] = 9.0;
        assert_eq!(s.slots()[4], [4.0, 1.0, 9.0, 3.0]);
        // One lane: three slots in one block, none lost.
        let one: Vec<[f64; 1]> = (0..3).map(|i| [i as f64]).collect();
        assert_eq!(LaneSlots::new(&one).slots(), &one[..]);
        assert!(LaneSlots::<4>::new(&[]).slots().is_empty());
    }

    /// Four-lane slots regroup as themselves (the same values, written through); other
    /// lane counts do not regroup.
    #[test]
    fn only_four_lane_slots_regroup_as_four_lanes() {
        let mut four: Vec<[f64; 4]> = (0..3).map(|i| [i as f64, 1.0, 2.0, 3.0]).collect();
        assert_eq!(four_lanes(&four), Some(&four.clone()[..]));
        four_lanes_mut(&mut four).expect("four lanes")[2][1] = 7.0;
        assert_eq!(four[2], [2.0, 7.0, 2.0, 3.0]);
        let mut one: Vec<[f64; 1]> = (0..8).map(|i| [i as f64]).collect();
        assert!(four_lanes(&one).is_none());
        assert!(four_lanes_mut(&mut one).is_none());
    }

    #[test]
    fn values_start_on_a_32_byte_boundary_and_hold_len_zeros() {
        let mut v = AlignedValues::zeros(7);
        assert_eq!(v.len(), 7);
        assert_eq!(v.as_ptr() as usize % 32, 0);
        assert!(v.iter().all(|&x| x == 0.0));
        v[6] = 1.5;
        assert_eq!(v[6], 1.5);
    }
}
