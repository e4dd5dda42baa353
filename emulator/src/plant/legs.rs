//! Four landing legs: each a stiff spring-damper in series with a crushable strut
//! (honeycomb, as the Apollo LM's), its footpad against the ground with Coulomb
//! friction, so the run goes on through touchdown until the vehicle rests, tips or
//! slides.
//!
//! For footpad `i` at `b_i + c_i z` (body axes, from the centre of mass; `c_i` the
//! crushed length of its strut, along body +Z), with the ground below it at radial
//! height `h_i < 0` (penetration `d_i = -h_i (n . u)`, `n` the surface normal, `u` the
//! radial up) and `v_i` its velocity relative to the Moon-fixed ground:
//!
//! ```text
//! F_n = min(F_crush, max(0, k d_i - c (v_i . n)))     normal, along n (c_i < stroke)
//! F_n = max(0, k d_i - c (v_i . n))                   once the stroke is used up
//! F_t = -k s_i - c v_t,   |F_t| <= mu F_n              tangential (stick-slip)
//! ```
//! The strut crushes where the load would pass `F_crush`: between sub-steps `c_i`
//! grows until the spring alone carries `F_crush` (`k d_i = F_crush`), up to the
//! stroke, and never shrinks: the energy `F_crush dc` is absorbed and the crushed length
//! kept, so the vehicle does not rebound.
//! `s_i` is the tangential stretch from the footpad's stick point (an anchor laid where
//! it first touched, dragged along when the friction cone is exceeded: the usual
//! "bristle" stick-slip model), so a pad on a slope gentler than `atan(mu)` holds still
//! instead of creeping as a regularised (velocity-only) friction law would. The anchor
//! is updated between contact sub-steps, not inside the Runge-Kutta stages, so the
//! derivative stays a smooth function of the state within a sub-step.
//!
//! Contact is stiff (default natural frequency about 5 Hz for the landed mass), so the
//! plant integrates the steps after first contact in sub-steps of at most
//! [`CONTACT_SUBSTEP_NS`].

use super::frames::MoonRotation;
use super::ground::Ground;
use super::rigid_body::StateVector;
use crate::config::LanderConfig;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Longest integration sub-step while a footpad may touch, nanoseconds (the leg mode at
/// ~32 rad/s is then resolved at 0.03 rad a sub-step).
pub const CONTACT_SUBSTEP_NS: u64 = 1_000_000;

/// Number of footpads.
pub const FOOTPADS: usize = 4;

/// Net load of the legs on the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactLoads {
    /// Force, `mci`, newtons.
    pub force_mci_n: Vector3<f64>,
    /// Torque about the centre of mass, body axes, N m.
    pub torque_body_nm: Vector3<f64>,
}

/// The legs, their crushed lengths and their stick points.
#[derive(Debug, Clone)]
pub struct Legs {
    /// Footpads (strut uncrushed) from the true centre of mass, body axes, metres.
    pads_body_m: [Vector3<f64>; FOOTPADS],
    stiffness_n_m: f64,
    damping_n_s_m: f64,
    friction: f64,
    crush_load_n: f64,
    stroke_m: f64,
    /// Crushed length of each strut, metres (0 to the stroke; never shrinks).
    crush_m: [f64; FOOTPADS],
    /// Stick point of each footpad on the ground while it touches, `mcmf`.
    anchors_mcmf: [Option<Vector3<f64>>; FOOTPADS],
    /// Distance each footpad slipped along the ground (its stick point dragged), metres.
    slip_m: [f64; FOOTPADS],
    /// Fastest footpad speed along the ground while slipping, m/s.
    slip_speed_max_m_s: f64,
    /// Farthest footpad from the centre of mass, metres.
    reach_m: f64,
    /// Tilt beyond which the centre of mass is outside the footprint, degrees.
    tip_over_deg: f64,
}

/// One footpad's state against the ground.
struct PadContact {
    /// Footpad position, `mcmf`.
    p_mcmf: Vector3<f64>,
    /// Surface normal, `mci`.
    n_mci: Vector3<f64>,
    /// Penetration along the normal, metres (> 0 in contact).
    depth_m: f64,
    /// Velocity relative to the ground, `mci`.
    v_rel_mci: Vector3<f64>,
    /// `mcmf` from `mci` at this instant, applied to vectors.
    to_mcmf: nalgebra::Rotation3<f64>,
}

impl Legs {
    /// The legs of `lander` (footpads measured from the true centre of mass).
    pub fn new(lander: &LanderConfig) -> Self {
        let com = Vector3::from(lander.com_offset_body_m);
        let pads_body_m = lander
            .footpad_positions_body_m
            .map(|p| Vector3::from(p) - com);
        let reach_m = pads_body_m.iter().map(|p| p.norm()).fold(0.0, f64::max);
        Self {
            pads_body_m,
            stiffness_n_m: lander.leg_stiffness_n_m,
            damping_n_s_m: lander.leg_damping_n_s_m,
            friction: lander.footpad_friction,
            crush_load_n: lander.leg_crush_load_n,
            stroke_m: lander.leg_stroke_m,
            crush_m: [0.0; FOOTPADS],
            anchors_mcmf: [None; FOOTPADS],
            slip_m: [0.0; FOOTPADS],
            slip_speed_max_m_s: 0.0,
            reach_m,
            tip_over_deg: tip_over_deg(&pads_body_m),
        }
    }

    /// Footpad `i` where its strut's crushed length puts it, body axes, metres.
    fn pad_body_m(&self, i: usize) -> Vector3<f64> {
        let mut b = self.pads_body_m[i];
        b.z += self.crush_m[i];
        b
    }

    /// Crushed length of each strut, metres.
    pub fn crush_m(&self) -> [f64; FOOTPADS] {
        self.crush_m
    }

    /// Farthest any footpad slipped along the ground since first contact, metres.
    pub fn slide_m(&self) -> f64 {
        self.slip_m.iter().copied().fold(0.0, f64::max)
    }

    /// Fastest footpad speed along the ground while slipping, m/s.
    pub fn slide_speed_m_s(&self) -> f64 {
        self.slip_speed_max_m_s
    }

    /// Farthest footpad from the centre of mass, metres.
    pub fn reach_m(&self) -> f64 {
        self.reach_m
    }

    /// Tilt from the ground normal past which the vehicle falls over, degrees.
    pub fn tip_over_deg(&self) -> f64 {
        self.tip_over_deg
    }

    /// Lowest footpad's radial height above the ground, metres, for the state `x` at
    /// time `t_s`.
    pub fn lowest_height_m(
        &self,
        x: &StateVector,
        t_s: f64,
        rotation: &MoonRotation,
        ground: &Ground,
    ) -> f64 {
        let (r, q) = position_attitude(x);
        let to_mcmf = rotation.mcmf_from_mci(t_s);
        (0..FOOTPADS)
            .map(|i| ground.height_m(&(to_mcmf * (r + q * self.pad_body_m(i)))))
            .fold(f64::INFINITY, f64::min)
    }

    /// How many footpads touch the ground in state `x` at `t_s`.
    pub fn pads_in_contact(
        &self,
        x: &StateVector,
        t_s: f64,
        rotation: &MoonRotation,
        ground: &Ground,
    ) -> u8 {
        (0..FOOTPADS)
            .filter(|&i| pad_contact(&self.pad_body_m(i), x, t_s, rotation, ground).depth_m > 0.0)
            .count() as u8
    }

    /// Largest footpad speed over the ground in state `x`, m/s.
    pub fn fastest_pad_m_s(
        &self,
        x: &StateVector,
        t_s: f64,
        rotation: &MoonRotation,
        ground: &Ground,
    ) -> f64 {
        (0..FOOTPADS)
            .map(|i| {
                pad_contact(&self.pad_body_m(i), x, t_s, rotation, ground)
                    .v_rel_mci
                    .norm()
            })
            .fold(0.0, f64::max)
    }

    /// The legs' load on the vehicle in state `x` at `t_s` (stick points held).
    pub fn loads(
        &self,
        x: &StateVector,
        t_s: f64,
        rotation: &MoonRotation,
        ground: &Ground,
    ) -> ContactLoads {
        let (_, q) = position_attitude(x);
        let mut force_mci_n = Vector3::zeros();
        let mut torque_body_nm = Vector3::zeros();
        for (i, anchor) in self.anchors_mcmf.iter().enumerate() {
            let b = self.pad_body_m(i);
            let c = pad_contact(&b, x, t_s, rotation, ground);
            if c.depth_m <= 0.0 {
                continue;
            }
            let f = self.pad_force_mci(i, &c, anchor.as_ref());
            force_mci_n += f;
            torque_body_nm += b.cross(&(q.inverse() * f));
        }
        ContactLoads {
            force_mci_n,
            torque_body_nm,
        }
    }

    /// After a sub-step: crush each strut whose spring would carry more than the crush
    /// load (the crushed length kept), then lay a stick point where a footpad has just
    /// touched, drag it along where friction slips (counting the slip), drop it where
    /// the pad left the ground.
    pub fn update_between_substeps(
        &mut self,
        x: &StateVector,
        t_s: f64,
        rotation: &MoonRotation,
        ground: &Ground,
    ) {
        let (_, q) = position_attitude(x);
        for i in 0..FOOTPADS {
            let mut c = pad_contact(&self.pad_body_m(i), x, t_s, rotation, ground);
            if c.depth_m <= 0.0 {
                self.anchors_mcmf[i] = None;
                continue;
            }
            let excess_m = c.depth_m - self.crush_load_n / self.stiffness_n_m;
            if excess_m > 0.0 && self.crush_m[i] < self.stroke_m {
                // Crushing along the strut (body +Z) lifts the pad off the ground by
                // that times the strut's cosine to the normal; past 60 deg the vehicle
                // has long tipped, the floor keeps the step finite.
                let cos = (q * Vector3::z()).dot(&c.n_mci).max(0.5);
                let crushed = (self.crush_m[i] + excess_m / cos).min(self.stroke_m);
                self.crush_m[i] = crushed;
                c = pad_contact(&self.pad_body_m(i), x, t_s, rotation, ground);
                if c.depth_m <= 0.0 {
                    continue;
                }
            }
            let Some(anchor) = self.anchors_mcmf[i] else {
                self.anchors_mcmf[i] = Some(c.p_mcmf);
                continue;
            };
            let n_mcmf = c.to_mcmf * c.n_mci;
            let stretch = c.p_mcmf - anchor;
            let stretch_t = stretch - n_mcmf * stretch.dot(&n_mcmf);
            let normal_n = self.normal_force_n(i, &c);
            let limit_m = self.friction * normal_n / self.stiffness_n_m;
            let s = stretch_t.norm();
            if s > limit_m {
                // Slipping: the stick point follows, keeping the spring at the cone.
                self.anchors_mcmf[i] = Some(c.p_mcmf - stretch_t * (limit_m / s));
                self.slip_m[i] += s - limit_m;
                let v_n = c.v_rel_mci.dot(&c.n_mci);
                let v_t = (c.v_rel_mci - c.n_mci * v_n).norm();
                self.slip_speed_max_m_s = self.slip_speed_max_m_s.max(v_t);
            }
        }
    }

    /// Normal force of footpad `i`: the spring-damper, held at the crush load while the
    /// strut has stroke left.
    fn normal_force_n(&self, i: usize, c: &PadContact) -> f64 {
        let f = (self.stiffness_n_m * c.depth_m - self.damping_n_s_m * c.v_rel_mci.dot(&c.n_mci))
            .max(0.0);
        if self.crush_m[i] < self.stroke_m {
            f.min(self.crush_load_n)
        } else {
            f
        }
    }

    fn pad_force_mci(
        &self,
        i: usize,
        c: &PadContact,
        anchor_mcmf: Option<&Vector3<f64>>,
    ) -> Vector3<f64> {
        let normal_n = self.normal_force_n(i, c);
        let n = c.n_mci;
        let v_t = c.v_rel_mci - n * c.v_rel_mci.dot(&n);
        let stretch_t = match anchor_mcmf {
            Some(a) => {
                let s = c.to_mcmf.inverse() * (c.p_mcmf - a);
                s - n * s.dot(&n)
            }
            None => Vector3::zeros(),
        };
        let mut f_t = -stretch_t * self.stiffness_n_m - v_t * self.damping_n_s_m;
        let limit = self.friction * normal_n;
        let f_t_norm = f_t.norm();
        if f_t_norm > limit {
            f_t *= limit / f_t_norm;
        }
        n * normal_n + f_t
    }
}

fn position_attitude(x: &StateVector) -> (Vector3<f64>, UnitQuaternion<f64>) {
    (
        x.fixed_rows::<3>(0).into_owned(),
        UnitQuaternion::from_quaternion(Quaternion::new(x[6], x[7], x[8], x[9])),
    )
}

fn pad_contact(
    b: &Vector3<f64>,
    x: &StateVector,
    t_s: f64,
    rotation: &MoonRotation,
    ground: &Ground,
) -> PadContact {
    let (r, q) = position_attitude(x);
    let v = x.fixed_rows::<3>(3).into_owned();
    let w = x.fixed_rows::<3>(10).into_owned();
    let to_mcmf = rotation.mcmf_from_mci(t_s);
    let p_mci = r + q * b;
    let p_mcmf = to_mcmf * p_mci;
    let h = ground.height_m(&p_mcmf);
    let n_mcmf = ground.normal_mcmf(&p_mcmf);
    let n_mci = to_mcmf.inverse() * n_mcmf;
    let up_mcmf = p_mcmf.normalize();
    let v_pad = v + q * w.cross(b);
    PadContact {
        p_mcmf,
        n_mci,
        depth_m: -h * n_mcmf.dot(&up_mcmf),
        v_rel_mci: rotation.surface_relative_mci(&p_mci, &v_pad),
        to_mcmf,
    }
}

/// The static stability angle: the tilt at which the centre of mass passes over the
/// nearest edge of the footprint (footpads projected on body X-Y), degrees.
fn tip_over_deg(pads: &[Vector3<f64>; FOOTPADS]) -> f64 {
    // Order the pads by azimuth so consecutive pads are the footprint's edges.
    let mut order: [usize; FOOTPADS] = [0, 1, 2, 3];
    order.sort_by(|&a, &b| {
        pads[a]
            .y
            .atan2(pads[a].x)
            .total_cmp(&pads[b].y.atan2(pads[b].x))
    });
    let height_m = -pads.iter().map(|p| p.z).sum::<f64>() / FOOTPADS as f64;
    let mut edge_m = f64::INFINITY;
    for k in 0..FOOTPADS {
        let a = pads[order[k]].xy();
        let b = pads[order[(k + 1) % FOOTPADS]].xy();
        let ab = b - a;
        // Distance from the origin (the centre of mass) to the edge line.
        let d = (a.x * ab.y - a.y * ab.x).abs() / ab.norm().max(1e-12);
        edge_m = edge_m.min(d);
    }
    edge_m.atan2(height_m.max(1e-9)).to_degrees()
}

/// The touchdown limits the legs allow, one rule for both (`docs/plant.md`, "One rule
/// for slope and tilt"): the tilt at rest may take the centre of mass at most
/// `1 / stability_factor` of the way to the footprint's nearest edge; the slope limit
/// is that tilt less the most the legs themselves can tilt the body off the ground, so
/// a vehicle at rest on a plane below the slope limit is within the tilt limit.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LandingLimits {
    /// Static stability angle of the design footprint on level ground, degrees.
    pub tip_over_deg: f64,
    /// Largest tilt of body +Z from the local vertical at rest, degrees:
    /// `atan(tan(tip_over_deg) / stability_factor)`.
    pub tilt_deg: f64,
    /// Most the legs can tilt the body off the ground's plane at rest, degrees: one
    /// strut crushed its whole stroke and its spring at the crush load, the others
    /// not at all, over the smallest height of a triangle of three footpads.
    pub legs_tilt_deg: f64,
    /// Largest slope of the ground under the footprint, degrees:
    /// `tilt_deg - legs_tilt_deg`.
    pub slope_deg: f64,
}

/// The limits `lander`'s legs allow with `stability_factor` (see [`LandingLimits`]);
/// from the design footprint (the footpads about the design centre of mass).
pub fn landing_limits(lander: &LanderConfig, stability_factor: f64) -> LandingLimits {
    let pads = lander.footpad_positions_body_m.map(Vector3::from);
    let tip_over = tip_over_deg(&pads);
    let tilt_deg = (tip_over.to_radians().tan() / stability_factor)
        .atan()
        .to_degrees();
    let height_m = smallest_triangle_height_m(&pads);
    let drop_m = lander.leg_stroke_m + lander.leg_crush_load_n / lander.leg_stiffness_n_m;
    let legs_tilt_deg = drop_m.atan2(height_m).to_degrees();
    LandingLimits {
        tip_over_deg: tip_over,
        tilt_deg,
        legs_tilt_deg,
        slope_deg: tilt_deg - legs_tilt_deg,
    }
}

/// Smallest height of a triangle of three footpads (projected on body X-Y), metres: a
/// body resting on three pads tilts off their plane by at most `atan(dz / height)`
/// when one of them is `dz` shorter.
fn smallest_triangle_height_m(pads: &[Vector3<f64>; FOOTPADS]) -> f64 {
    let mut smallest = f64::INFINITY;
    for skip in 0..FOOTPADS {
        let mut tri = [Vector3::zeros(); 3];
        let mut k = 0;
        for (i, p) in pads.iter().enumerate() {
            if i != skip {
                tri[k] = Vector3::new(p.x, p.y, 0.0);
                k += 1;
            }
        }
        let twice_area = (tri[1] - tri[0]).cross(&(tri[2] - tri[0])).norm();
        let longest = (tri[1] - tri[0])
            .norm()
            .max((tri[2] - tri[1]).norm())
            .max((tri[0] - tri[2]).norm());
        smallest = smallest.min(twice_area / longest.max(1e-12));
    }
    smallest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_footprint_tips_past_46_7_degrees() {
        let legs = Legs::new(&LanderConfig::default());
        // Pads at 1.8 m on the axes: the edges are 1.8/sqrt(2) = 1.273 m away, the
        // centre of mass 1.2 m up: atan(1.273 / 1.2) = 46.69 deg.
        let expect = (1.8 / 2f64.sqrt()).atan2(1.2).to_degrees();
        assert!((legs.tip_over_deg() - expect).abs() < 1e-9);
        assert!((expect - 46.69).abs() < 0.01);
    }

    #[test]
    fn default_limits_follow_from_the_footprint_and_the_stroke() {
        let lander = LanderConfig::default();
        let lim = landing_limits(&lander, 3.0);
        // tan 46.69 deg = 1.273 / 1.2 = 1.0607; a third of it: atan(0.3536) = 19.47 deg.
        let tilt = ((1.8 / 2f64.sqrt()) / 1.2 / 3.0).atan().to_degrees();
        assert!((lim.tilt_deg - tilt).abs() < 1e-9, "{lim:?}");
        assert!((tilt - 19.47).abs() < 0.01);
        // Any three pads of the square make a right triangle 1.8 m high over its
        // hypotenuse: one strut down by the stroke plus the spring at the crush load.
        let drop_m = lander.leg_stroke_m + lander.leg_crush_load_n / lander.leg_stiffness_n_m;
        let legs = drop_m.atan2(1.8).to_degrees();
        assert!((lim.legs_tilt_deg - legs).abs() < 1e-9, "{lim:?}");
        assert!((lim.slope_deg - (tilt - legs)).abs() < 1e-12);
        // A softer margin or a longer stroke moves the limits the way they should.
        assert!(landing_limits(&lander, 2.0).slope_deg > lim.slope_deg);
        let mut long = lander.clone();
        long.leg_stroke_m *= 2.0;
        assert!(landing_limits(&long, 3.0).slope_deg < lim.slope_deg);
    }
}
