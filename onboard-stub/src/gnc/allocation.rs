//! Thrust allocation: total thrust and x/y torque onto the main engines, the rest of the
//! torque onto the attitude thrusters.
//!
//! `[F, Mx, My]^T = B T`, with `B` rows `1`, `y_i`, `-x_i` (each engine at body
//! `(x_i, y_i, z_i)` thrusts along +Z, so its torque is `r_i x F_i = (y_i F_i, -x_i F_i, 0)`).
//! The total thrust is shared equally and clipped to the engines' throttle range; the
//! differential part `d = B^+ [0, Mx, My]` (minimum norm, zero net force) is scaled down
//! by the largest factor in [0, 1] that keeps every engine inside 40-100 %: thrust has
//! priority, and whatever torque the engines cannot give goes to the attitude thrusters,
//! up to 80 % of their limit. Beyond that, torque has priority: the total thrust is
//! lowered (or raised, at the floor) until the engines can give the excess.
//! With the diagonal pair only, `B` has rank 2: the pair can only twist about the axis
//! perpendicular to its diagonal, and the other torque axis goes to the thrusters.

use super::GncConfig;
use nalgebra::{Matrix3x4, Matrix4x3, Vector3, Vector4};
use oils_shared::ENGINE_COUNT;

/// Which main engines fly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EngineSet {
    /// All four.
    Four,
    /// The diagonal pair named in [`GncConfig::two_engine_pair`].
    DiagonalPair,
    /// The other diagonal pair (flown after an engine of the first pair fails).
    OtherPair,
}

/// Output of one allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Allocation {
    /// Thrust command per engine, newtons (0 for engines off).
    pub thrust_cmd_n: [f64; ENGINE_COUNT],
    /// Engine switches.
    pub on: [bool; ENGINE_COUNT],
    /// Torque the engines give if they follow the command, body axes, N m.
    pub engine_torque_body_nm: Vector3<f64>,
    /// Torque left for the attitude thrusters (clamped to their limit), body axes, N m.
    pub rcs_torque_body_nm: Vector3<f64>,
}

/// Per-engine-set matrices, built once.
#[derive(Debug, Clone, Copy)]
struct SetMatrices {
    b: Matrix3x4<f64>,
    b_pinv: Matrix4x3<f64>,
    on: [bool; ENGINE_COUNT],
}

/// The allocator.
#[derive(Debug, Clone)]
pub struct ThrustAllocator {
    four: SetMatrices,
    pair: SetMatrices,
    other_pair: SetMatrices,
    max_thrust_n: f64,
    min_thrust_n: f64,
    rcs_max_torque_nm: Vector3<f64>,
}

impl ThrustAllocator {
    /// Builds the allocation matrices for both engine sets. `None` if the engine layout
    /// cannot produce x/y torque (a degenerate configuration).
    pub fn new(cfg: &GncConfig) -> Option<Self> {
        let build = |on: [bool; ENGINE_COUNT]| -> Option<SetMatrices> {
            let mut b = Matrix3x4::zeros();
            for (i, p) in cfg.engine_positions_body_m.iter().enumerate() {
                if on[i] {
                    b[(0, i)] = 1.0;
                    b[(1, i)] = p[1];
                    b[(2, i)] = -p[0];
                }
            }
            let b_pinv = b.pseudo_inverse(1e-9).ok()?;
            Some(SetMatrices { b, b_pinv, on })
        };
        let mut pair_on = [false; ENGINE_COUNT];
        for &i in &cfg.two_engine_pair {
            pair_on[i.min(ENGINE_COUNT - 1)] = true;
        }
        Some(Self {
            four: build([true; ENGINE_COUNT])?,
            pair: build(pair_on)?,
            other_pair: build(pair_on.map(|on| !on))?,
            max_thrust_n: cfg.max_thrust_n,
            min_thrust_n: cfg.max_thrust_n * cfg.throttle_min_frac,
            rcs_max_torque_nm: Vector3::from(cfg.rcs_max_torque_nm),
        })
    }

    /// The pair that flies without `failed`: the diagonal pair not containing it.
    pub fn pair_without(&self, failed: usize) -> EngineSet {
        if self.pair.on.get(failed).copied().unwrap_or(false) {
            EngineSet::OtherPair
        } else {
            EngineSet::DiagonalPair
        }
    }

    /// Number of engines in a set.
    pub fn engine_count(&self, set: EngineSet) -> usize {
        self.matrices(set).on.iter().filter(|&&on| on).count()
    }

    /// Largest total thrust of a set, newtons.
    pub fn max_total_n(&self, set: EngineSet) -> f64 {
        self.engine_count(set) as f64 * self.max_thrust_n
    }

    /// Smallest total thrust of a set with every engine lit, newtons.
    pub fn min_total_n(&self, set: EngineSet) -> f64 {
        self.engine_count(set) as f64 * self.min_thrust_n
    }

    fn matrices(&self, set: EngineSet) -> &SetMatrices {
        match set {
            EngineSet::Four => &self.four,
            EngineSet::DiagonalPair => &self.pair,
            EngineSet::OtherPair => &self.other_pair,
        }
    }

    /// Allocates a total thrust and a body torque.
    pub fn allocate(
        &self,
        set: EngineSet,
        force_n: f64,
        torque_body_nm: Vector3<f64>,
    ) -> Allocation {
        let m = self.matrices(set);
        let n = self.engine_count(set) as f64;
        let mut total_n = force_n.clamp(n * self.min_thrust_n, n * self.max_thrust_n);
        let diff = self.differential(m, torque_body_nm);
        // Torque the thrusters cannot give (beyond `RCS_SHARE` of their limit, kept
        // for the attitude loop's transients) must come from the engines, whatever it
        // costs in thrust: thrust lost costs range, attitude lost costs the vehicle (a
        // weak engine at full throttle with a centre-of-mass offset tumbled it).
        let beyond_rcs = (torque_body_nm
            - torque_body_nm.zip_map(&self.rcs_max_torque_nm, |t, max| {
                t.clamp(-RCS_SHARE * max, RCS_SHARE * max)
            }))
        .xy();
        if beyond_rcs != nalgebra::Vector2::zeros() {
            let need = self.differential(m, Vector3::new(beyond_rcs.x, beyond_rcs.y, 0.0));
            let (mut hi, mut lo) = (self.max_thrust_n, self.min_thrust_n);
            for i in 0..ENGINE_COUNT {
                if m.on[i] {
                    hi = hi.min(self.max_thrust_n - need[i]);
                    lo = lo.max(self.min_thrust_n - need[i]);
                }
            }
            if lo <= hi {
                total_n = total_n.clamp(n * lo, n * hi);
            }
        }
        let mut base = Vector4::zeros();
        for i in 0..ENGINE_COUNT {
            if m.on[i] {
                base[i] = total_n / n;
            }
        }
        // Largest scale keeping every lit engine in range.
        let mut scale: f64 = 1.0;
        for i in 0..ENGINE_COUNT {
            if !m.on[i] || diff[i] == 0.0 {
                continue;
            }
            let room = if diff[i] > 0.0 {
                self.max_thrust_n - base[i]
            } else {
                self.min_thrust_n - base[i]
            };
            scale = scale.min((room / diff[i]).max(0.0));
        }
        let thrust = base + diff * scale;
        let achieved = m.b * thrust;
        let engine_torque = Vector3::new(achieved[1], achieved[2], 0.0);
        let rcs = (torque_body_nm - engine_torque)
            .zip_map(&self.rcs_max_torque_nm, |t, max| t.clamp(-max, max));
        Allocation {
            thrust_cmd_n: thrust.into(),
            on: m.on,
            engine_torque_body_nm: engine_torque,
            rcs_torque_body_nm: rcs,
        }
    }

    /// The minimum-norm engine differential (zero net force) for an x/y torque; exactly
    /// zero on unlit engines.
    fn differential(&self, m: &SetMatrices, torque_body_nm: Vector3<f64>) -> Vector4<f64> {
        let mut diff = m.b_pinv * Vector3::new(0.0, torque_body_nm.x, torque_body_nm.y);
        for i in 0..ENGINE_COUNT {
            if !m.on[i] {
                // The SVD leaves round-off (~1e-31) on unlit engines: make them exactly off.
                diff[i] = 0.0;
            }
        }
        diff
    }
}

/// The share of the attitude thrusters' torque limit the allocator counts on before it
/// lowers the total thrust to twist with the engines.
const RCS_SHARE: f64 = 0.8;

#[cfg(test)]
mod tests {
    use super::*;

    fn alloc() -> ThrustAllocator {
        ThrustAllocator::new(&GncConfig::default()).unwrap()
    }

    #[test]
    fn four_engines_give_force_and_torque_exactly_when_in_range() {
        let a = alloc();
        let out = a.allocate(EngineSet::Four, 2000.0, Vector3::new(30.0, -20.0, 5.0));
        let sum: f64 = out.thrust_cmd_n.iter().sum();
        assert!((sum - 2000.0).abs() < 1e-9);
        assert!((out.engine_torque_body_nm.x - 30.0).abs() < 1e-9);
        assert!((out.engine_torque_body_nm.y + 20.0).abs() < 1e-9);
        // Only yaw is left for the thrusters.
        assert!(out.rcs_torque_body_nm.xy().norm() < 1e-9);
        assert_eq!(out.rcs_torque_body_nm.z, 5.0);
    }

    #[test]
    fn full_thrust_leaves_torque_to_the_thrusters_and_stays_in_range() {
        let a = alloc();
        let out = a.allocate(EngineSet::Four, 5000.0, Vector3::new(50.0, 0.0, 0.0));
        for t in out.thrust_cmd_n {
            assert!((320.0 - 1e-9..=800.0 + 1e-9).contains(&t), "{t}");
        }
        assert!((out.thrust_cmd_n.iter().sum::<f64>() - 3200.0).abs() < 1e-9);
        assert!((out.rcs_torque_body_nm.x - 50.0).abs() < 1e-9);
        // Near full thrust the engines give what headroom allows, the thrusters the rest.
        let near = a.allocate(EngineSet::Four, 3100.0, Vector3::new(100.0, 0.0, 0.0));
        let given = near.engine_torque_body_nm.x;
        assert!(given > 0.0 && given < 100.0);
        assert!((given + near.rcs_torque_body_nm.x - 100.0).abs() < 1e-9);
        assert!(near.thrust_cmd_n.iter().all(|&t| t <= 800.0 + 1e-9));
    }

    #[test]
    fn diagonal_pair_twists_about_one_axis_only() {
        let a = alloc();
        let out = a.allocate(
            EngineSet::DiagonalPair,
            1400.0,
            Vector3::new(20.0, 20.0, 0.0),
        );
        assert_eq!(out.on, [true, false, true, false]);
        assert_eq!(out.thrust_cmd_n[1], 0.0);
        assert!((out.thrust_cmd_n[0] + out.thrust_cmd_n[2] - 1400.0).abs() < 1e-9);
        // Engines 0 (0.6, 0.6) and 2 (-0.6, -0.6) twist about (1, -1) only: the demanded
        // (1, 1) torque is perpendicular to it and goes to the thrusters entirely.
        assert!(out.engine_torque_body_nm.norm() < 1e-9);
        assert!((out.rcs_torque_body_nm.x - 20.0).abs() < 1e-9);
        let along = a.allocate(
            EngineSet::DiagonalPair,
            1400.0,
            Vector3::new(20.0, -20.0, 0.0),
        );
        assert!((along.engine_torque_body_nm.x - 20.0).abs() < 1e-9);
        assert!(along.rcs_torque_body_nm.norm() < 1e-9);
    }

    #[test]
    fn torque_beyond_the_thrusters_lowers_the_thrust_instead_of_being_dropped() {
        let a = alloc();
        // At full thrust, 150 N m about x: the thrusters give at most 116 N m.
        let out = a.allocate(EngineSet::Four, 3200.0, Vector3::new(150.0, 0.0, 0.0));
        let sum: f64 = out.thrust_cmd_n.iter().sum();
        assert!(sum < 3200.0, "{sum}");
        for t in out.thrust_cmd_n {
            assert!((320.0 - 1e-9..=800.0 + 1e-9).contains(&t), "{t}");
        }
        // The engines give at least the excess over 80 % of the thrusters' limit, and
        // engines plus thrusters give the whole demand.
        let engines = out.engine_torque_body_nm.x;
        assert!(engines >= 150.0 - 0.8 * 116.0 - 1e-9, "{engines}");
        assert!((engines + out.rcs_torque_body_nm.x - 150.0).abs() < 1e-9);
        // Within the thrusters' share, thrust keeps priority (as before).
        let small = a.allocate(EngineSet::Four, 3200.0, Vector3::new(90.0, 0.0, 0.0));
        assert!((small.thrust_cmd_n.iter().sum::<f64>() - 3200.0).abs() < 1e-9);
    }

    #[test]
    fn thrust_below_the_throttle_floor_is_raised() {
        let a = alloc();
        let out = a.allocate(EngineSet::Four, 100.0, Vector3::zeros());
        assert_eq!(out.thrust_cmd_n, [320.0; 4]);
    }
}
