//! Descent guidance: the phase sequence and, in each phase, the thrust acceleration
//! (non-gravitational, `mci`, m/s^2) the vehicle should fly.
//!
//! 1. Rough braking: fixed high throttle; the thrust direction splits the available
//!    acceleration between a vertical channel that tracks an altitude-versus-horizontal-
//!    speed profile (linear from the start point to `rough_end_altitude_m` at
//!    `rough_end_speed_m_s`) and the rest, retrograde along the horizontal velocity.
//! 2. Attitude hold: the last rough-braking thrust direction, held in the local vertical
//!    frame, for `attitude_hold_s`.
//! 3. Fine braking: E-guidance `a = 6 (r_f - r - v t)/t^2 - 2 (v_f - v)/t - g` to
//!    `fine_target_altitude_m` above a landing site chosen at entry (see [`LandingSite`]),
//!    arriving with no horizontal speed and `fine_target_vertical_speed_m_s` vertical;
//!    the command is held once time-to-go drops below `fine_hold_tgo_s`.
//! 4. Terminal descent: vertical-speed profile `v = -min(v_max, sqrt(2 a (h - h_hover)))`
//!    to the hover altitude, horizontal velocity nulling and a gentle pull over the site.
//! 5. Hover: altitude hold at `hover_altitude_m` for `hover_s`.
//! 6. Final descent: `v = -sqrt(v_td^2 + 2 a_f (h - h_f))` down to `v_td` below `h_f`,
//!    horizontal velocity nulling, tilt limited so the legs meet the ground upright; the
//!    engines stay lit until contact (the plant ends the run).

use super::navigation::NavSolution;
use super::GncConfig;
use nalgebra::Vector3;

/// Phase of the descent; the number is the code the GNC reports (`FswReport::phase`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// High-thrust braking of the orbital speed with altitude managed.
    RoughBraking = 0,
    /// Thrust direction held while the vehicle settles (navigation update in flight).
    AttitudeHold = 1,
    /// E-guidance to rest above the landing site.
    FineBraking = 2,
    /// Vertical-speed profile down to the hover altitude.
    TerminalDescent = 3,
    /// Altitude hold above the site.
    Hover = 4,
    /// Slow vertical descent to contact.
    FinalDescent = 5,
}

/// The landing site, chosen when fine braking starts: on the current ground track,
/// `V T / 2` downrange, where `T` is the shortest time-to-go whose E-guidance thrust
/// stays within `fine_accel_fraction` of the maximum (and above the throttle floor) over
/// the whole nominal arc. `V T / 2` makes the nominal horizontal deceleration constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandingSite {
    /// Site on the surface (footpad level), `mci`, metres.
    pub surface_mci_m: Vector3<f64>,
    /// Fine-braking target point above it, `mci`, metres.
    pub target_mci_m: Vector3<f64>,
    /// Velocity to arrive with (vertical only), `mci`, m/s.
    pub target_vel_mci_m_s: Vector3<f64>,
    /// Time at which fine braking should reach the target, seconds.
    pub arrival_t_s: f64,
    /// Time the site was chosen, seconds: the `mci` vectors above are where the
    /// (turning) site was then.
    pub chosen_t_s: f64,
}

impl LandingSite {
    /// The site-fixed point that is at `p_now_mci` at `t_s`, as given at `chosen_t_s`
    /// (the inverse of [`Self::turned`]).
    pub fn unturned(&self, p_now_mci: &Vector3<f64>, t_s: f64, omega_rad_s: f64) -> Vector3<f64> {
        let angle = -omega_rad_s * (t_s - self.chosen_t_s);
        let (s, c) = angle.sin_cos();
        Vector3::new(
            c * p_now_mci.x - s * p_now_mci.y,
            s * p_now_mci.x + c * p_now_mci.y,
            p_now_mci.z,
        )
    }

    /// Where the Moon's rotation (`omega_rad_s` about `mci` +Z) has carried the
    /// site-fixed point `p_mci` (given at `chosen_t_s`) by `t_s`.
    pub fn turned(&self, p_mci: &Vector3<f64>, t_s: f64, omega_rad_s: f64) -> Vector3<f64> {
        let angle = omega_rad_s * (t_s - self.chosen_t_s);
        let (s, c) = angle.sin_cos();
        Vector3::new(
            c * p_mci.x - s * p_mci.y,
            s * p_mci.x + c * p_mci.y,
            p_mci.z,
        )
    }
}

/// The scenario's site seen from the vehicle, along the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteRange {
    /// Great-circle arc from below the vehicle to the site on the reference sphere, m.
    pub range_m: f64,
    /// Horizontal unit vector towards the site along that great circle, `mci`.
    pub to_site_mci: Vector3<f64>,
    /// `up x to_site`: the normal of that great circle, `mci`.
    pub normal_mci: Vector3<f64>,
    /// Ground-relative velocity across that great circle, m/s.
    pub cross_speed_m_s: f64,
}

/// What guidance asks for this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuidanceCommand {
    /// Thrust (non-gravitational) acceleration to fly, `mci`, m/s^2.
    pub accel_mci_m_s2: Vector3<f64>,
    /// `Some(frac)`: fly at this fraction of the maximum thrust instead of the
    /// magnitude of `accel_mci_m_s2` (rough braking and attitude hold).
    pub throttle_frac: Option<f64>,
}

/// The guidance state machine.
#[derive(Debug, Clone)]
pub struct Guidance {
    cfg: GncConfig,
    phase: Phase,
    phase_start_s: f64,
    started: bool,
    /// Rough braking: altitude and horizontal speed at its start.
    rough_start: (f64, f64),
    /// Horizontal acceleration of the last rough-braking step, m/s^2 (predicts dV/dt).
    rough_accel_h_m_s2: f64,
    /// Attitude hold: (up, downrange) components of the held unit thrust direction.
    hold_dir: (f64, f64),
    /// Rough braking: the throttle (fraction of the thrust available now) that the
    /// range predictor last found, and when.
    rough_throttle: f64,
    rough_solved_t_s: f64,
    /// The scenario's landing site, Moon-fixed unit vector (None: chosen on the track).
    target_mcmf_unit: Option<Vector3<f64>>,
    site: Option<LandingSite>,
    held_accel_mci_m_s2: Vector3<f64>,
    vertical_integral_m_s2: f64,
    last_t_s: f64,
    /// Hazard avoidance holds the hover (waiting for its map, or flying a divert).
    hover_hold: bool,
    /// A divert to a safe spot was commanded: the hover's position loop is stiffer.
    diverting: bool,
}

/// Unit vector along the horizontal velocity, or any horizontal unit vector at rest.
fn downrange_unit(nav: &NavSolution) -> Vector3<f64> {
    let vh = nav.horizontal_velocity_mci_m_s();
    let n = vh.norm();
    if n > 1e-6 {
        vh / n
    } else {
        let any = if nav.up_mci.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        (any - nav.up_mci * any.dot(&nav.up_mci)).normalize()
    }
}

impl Guidance {
    /// Guidance for the vehicle described by `cfg`; the phase is chosen on the first step.
    pub fn new(cfg: &GncConfig) -> Self {
        Self {
            cfg: cfg.clone(),
            phase: Phase::RoughBraking,
            phase_start_s: 0.0,
            hover_hold: false,
            diverting: false,
            started: false,
            rough_start: (0.0, 0.0),
            rough_accel_h_m_s2: 0.0,
            hold_dir: (0.0, 1.0),
            rough_throttle: cfg.rough_throttle_frac,
            rough_solved_t_s: f64::NEG_INFINITY,
            target_mcmf_unit: cfg.site.map(|s| s.unit_mcmf()),
            site: None,
            held_accel_mci_m_s2: Vector3::zeros(),
            vertical_integral_m_s2: 0.0,
            last_t_s: 0.0,
        }
    }

    /// Current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The landing site, once chosen.
    pub fn site(&self) -> Option<LandingSite> {
        self.site
    }

    /// Hazard avoidance holds the hover (at most `hover_max_s`) while `hold`.
    pub fn set_hover_hold(&mut self, hold: bool) {
        self.hover_hold = hold;
    }

    /// Moves the landing site to the ground point `surface_mci_m` (where it is at `t_s`):
    /// the safe spot hazard avoidance chose. The hover flies over it on a stiffer
    /// position loop (`divert_gain_position_1_s2`).
    pub fn divert_to(&mut self, surface_mci_m: &Vector3<f64>, t_s: f64) {
        let omega = self.cfg.moon_rotation_rad_s;
        if let Some(site) = &mut self.site {
            site.surface_mci_m = site.unturned(surface_mci_m, t_s, omega);
            self.diverting = true;
        }
    }

    /// Horizontal distance from the vehicle to the landing site's ground point, m.
    pub fn site_offset_m(&self, nav: &NavSolution) -> Option<f64> {
        let site = self.site?;
        let now = site.turned(&site.surface_mci_m, nav.t_s, self.cfg.moon_rotation_rad_s);
        let off = nav.pos_mci_m - now;
        Some((off - nav.up_mci * off.dot(&nav.up_mci)).norm())
    }

    fn enter(&mut self, phase: Phase, t_s: f64) {
        self.phase = phase;
        self.phase_start_s = t_s;
    }

    /// Guidance for one step. `max_accel_m_s2` / `min_accel_m_s2`: the thrust
    /// acceleration the engines can give now (with the measured thrust efficiency).
    pub fn update(
        &mut self,
        nav: &NavSolution,
        max_accel_m_s2: f64,
        min_accel_m_s2: f64,
    ) -> GuidanceCommand {
        let t_s = nav.t_s;
        let dt_s = if self.started {
            (t_s - self.last_t_s).max(0.0)
        } else {
            0.0
        };
        self.last_t_s = t_s;
        if !self.started {
            self.started = true;
            self.start(nav, max_accel_m_s2, min_accel_m_s2);
        }
        let h_speed = nav.horizontal_velocity_mci_m_s().norm();
        // Phase transitions first, so each step flies the law of its phase.
        match self.phase {
            Phase::RoughBraking => {
                if h_speed <= self.cfg.rough_end_speed_m_s
                    || nav.altitude_m <= self.cfg.rough_floor_altitude_m
                {
                    self.enter(Phase::AttitudeHold, t_s);
                }
            }
            Phase::AttitudeHold => {
                if t_s - self.phase_start_s >= self.cfg.attitude_hold_s {
                    self.choose_site(nav, max_accel_m_s2, min_accel_m_s2);
                    self.enter(Phase::FineBraking, t_s);
                }
            }
            Phase::FineBraking => {
                if self.site.is_none_or(|s| t_s >= s.arrival_t_s) {
                    self.enter(Phase::TerminalDescent, t_s);
                }
            }
            Phase::TerminalDescent => {
                if nav.altitude_m <= self.cfg.hover_altitude_m + self.cfg.hover_capture_m {
                    let next = if self.cfg.hover_s > 0.0 {
                        Phase::Hover
                    } else {
                        Phase::FinalDescent
                    };
                    self.enter(next, t_s);
                }
            }
            Phase::Hover => {
                let held = t_s - self.phase_start_s;
                if held >= self.cfg.hover_s && (!self.hover_hold || held >= self.cfg.hover_max_s) {
                    self.enter(Phase::FinalDescent, t_s);
                }
            }
            Phase::FinalDescent => {}
        }
        match self.phase {
            Phase::RoughBraking => self.rough_braking(nav, max_accel_m_s2),
            Phase::AttitudeHold => {
                let dir = nav.up_mci * self.hold_dir.0 - downrange_unit(nav) * self.hold_dir.1;
                GuidanceCommand {
                    accel_mci_m_s2: dir * max_accel_m_s2,
                    throttle_frac: Some(self.rough_throttle),
                }
            }
            Phase::FineBraking => self.fine_braking(nav, max_accel_m_s2, min_accel_m_s2),
            Phase::TerminalDescent | Phase::Hover | Phase::FinalDescent => {
                self.terminal(nav, dt_s, max_accel_m_s2, min_accel_m_s2)
            }
        }
    }

    /// First step: start in the phase that fits the initial state.
    fn start(&mut self, nav: &NavSolution, max_accel: f64, min_accel: f64) {
        let v = nav.horizontal_velocity_mci_m_s().norm();
        let h = nav.altitude_m;
        if v > self.cfg.rough_end_speed_m_s {
            self.rough_start = (h, v);
            self.enter(Phase::RoughBraking, nav.t_s);
        } else if h > self.cfg.fine_target_altitude_m + self.cfg.fine_min_drop_m {
            self.choose_site(nav, max_accel, min_accel);
            self.enter(Phase::FineBraking, nav.t_s);
        } else {
            self.site = Some(LandingSite {
                surface_mci_m: nav.pos_mci_m - nav.up_mci * h,
                target_mci_m: nav.pos_mci_m,
                target_vel_mci_m_s: Vector3::zeros(),
                arrival_t_s: nav.t_s,
                chosen_t_s: nav.t_s,
            });
            let phase = if h > self.cfg.hover_altitude_m + self.cfg.hover_capture_m {
                Phase::TerminalDescent
            } else {
                Phase::FinalDescent
            };
            self.enter(phase, nav.t_s);
        }
    }

    /// The site's unit vector (`mci`) at `t_s`: the Moon has turned it since `t = 0`.
    fn site_unit_mci(&self, t_s: f64) -> Option<Vector3<f64>> {
        let p = self.target_mcmf_unit?;
        let (s, c) = (self.cfg.moon_rotation_rad_s * t_s).sin_cos();
        Some(Vector3::new(c * p.x - s * p.y, s * p.x + c * p.y, p.z))
    }

    /// Where the scenario's site is seen from the vehicle (see [`SiteRange`]).
    pub fn site_range(&self, nav: &NavSolution) -> Option<SiteRange> {
        let site = self.site_unit_mci(nav.t_s)?;
        let up = nav.up_mci;
        let d = site - up * site.dot(&up);
        let dn = d.norm();
        let to_site = if dn > 1e-12 {
            d / dn
        } else {
            downrange_unit(nav)
        };
        let normal = up.cross(&to_site);
        Some(SiteRange {
            range_m: self.cfg.moon_radius_m * dn.atan2(site.dot(&up)),
            to_site_mci: to_site,
            normal_mci: normal,
            cross_speed_m_s: nav.horizontal_velocity_mci_m_s().dot(&normal),
        })
    }

    /// Range control: predicted overshoot (metres, > 0: the braking arc would carry the
    /// vehicle past its aim) of rough braking at a constant `throttle` (a fraction of
    /// `thrust_n`, the thrust available now), then the attitude hold, then fine braking
    /// covering `V T / 2` in its planned time `T` ([`RoughArc`]).
    fn rough_overshoot_m(
        &self,
        throttle: f64,
        nav: &NavSolution,
        thrust_n: f64,
        range_go_m: f64,
    ) -> f64 {
        let mut arc = RoughArc::new(self, throttle, nav, thrust_n);
        while arc.advance() {}
        arc.overshoot_m(range_go_m)
    }

    /// [`Guidance::rough_overshoot_m`] at two throttles, the two arcs flown side by side:
    /// each is a chain of divisions and a square root, each step waiting on the last, so
    /// two independent chains take about the time of one. Each arc does exactly what it
    /// does alone.
    fn rough_overshoot_pair_m(
        &self,
        throttles: [f64; 2],
        nav: &NavSolution,
        thrust_n: f64,
        range_go_m: f64,
    ) -> [f64; 2] {
        let [a, b] = throttles;
        let mut a = RoughArc::new(self, a, nav, thrust_n);
        let mut b = RoughArc::new(self, b, nav, thrust_n);
        loop {
            let more_a = a.advance();
            let more_b = b.advance();
            if !(more_a || more_b) {
                break;
            }
        }
        [a.overshoot_m(range_go_m), b.overshoot_m(range_go_m)]
    }

    /// The rough-braking throttle that puts fine braking's start `V T / 2` before the
    /// site (regula falsi on the predictor, within the throttle limits).
    fn solve_rough_throttle(&self, nav: &NavSolution, thrust_n: f64, range_go_m: f64) -> f64 {
        let c = &self.cfg;
        let (mut lo, mut hi) = (c.rough_min_throttle_frac, c.rough_max_throttle_frac);
        let [mut f_lo, mut f_hi] = self.rough_overshoot_pair_m([lo, hi], nav, thrust_n, range_go_m);
        if f_hi >= 0.0 {
            return hi; // even full thrust arrives long: brake as hard as allowed
        }
        if f_lo <= 0.0 {
            return lo;
        }
        let mut k = self.rough_throttle.clamp(lo, hi);
        let mut side = 0;
        for _ in 0..12 {
            k = if f_lo.is_finite() {
                (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
            } else {
                0.5 * (lo + hi)
            };
            let f = self.rough_overshoot_m(k, nav, thrust_n, range_go_m);
            if f.abs() < 10.0 || hi - lo < 1e-4 {
                break;
            }
            if f > 0.0 {
                lo = k;
                f_lo = f;
                if side == 1 {
                    f_hi *= 0.5; // Illinois: keep the bracket shrinking from both ends
                }
                side = 1;
            } else {
                hi = k;
                f_hi = f;
                if side == -1 {
                    f_lo *= 0.5;
                }
                side = -1;
            }
        }
        k
    }

    fn rough_braking(&mut self, nav: &NavSolution, accel_avail: f64) -> GuidanceCommand {
        let mut throttle = self.cfg.rough_throttle_frac;
        let mut cross_normal = Vector3::zeros();
        let mut cross_speed = 0.0;
        if let Some(geo) = self.site_range(nav) {
            if nav.t_s - self.rough_solved_t_s >= self.cfg.rough_solve_period_s {
                let mass = nav.mass_kg.max(self.cfg.dry_mass_kg);
                self.rough_throttle =
                    self.solve_rough_throttle(nav, accel_avail * mass, geo.range_m);
                self.rough_solved_t_s = nav.t_s;
            }
            throttle = self.rough_throttle;
            cross_normal = geo.normal_mci;
            cross_speed = geo.cross_speed_m_s;
        }
        let accel_avail = accel_avail * throttle;
        let c = &self.cfg;
        let (h0, v0) = self.rough_start;
        let (h_end, v_end) = (c.rough_end_altitude_m, c.rough_end_speed_m_s);
        let v = nav.horizontal_velocity_mci_m_s().norm();
        let r = nav.pos_mci_m.norm();
        let span = (v0 - v_end).max(1.0);
        let frac = ((v - v_end) / span).clamp(0.0, 1.0);
        let h_ref = h_end + (h0 - h_end) * frac;
        // dh/dt = dh/dV dV/dt with dV/dt = -(horizontal thrust acceleration).
        let v_up_ref = -(h0 - h_end) / span * self.rough_accel_h_m_s2;
        let v_up = nav.vertical_speed_m_s();
        let a_up = (nav.gravity_m_s2 - v * v / r)
            + c.rough_gain_vertical_speed_1_s * (v_up_ref - v_up)
            + c.rough_gain_altitude_1_s2 * (h_ref - nav.altitude_m);
        let a_up = a_up.clamp(
            -c.rough_max_down_frac * accel_avail,
            c.rough_max_up_frac * accel_avail,
        );
        // Across the great circle to the site: null the velocity across it.
        let cross_max = c.rough_max_cross_frac * accel_avail;
        let a_cross = (-c.rough_gain_cross_speed_1_s * cross_speed).clamp(-cross_max, cross_max);
        let a_h = (accel_avail * accel_avail - a_up * a_up - a_cross * a_cross)
            .max(0.0)
            .sqrt();
        self.rough_accel_h_m_s2 = a_h;
        if accel_avail > 0.0 {
            self.hold_dir = (a_up / accel_avail, a_h / accel_avail);
        }
        GuidanceCommand {
            accel_mci_m_s2: nav.up_mci * a_up - downrange_unit(nav) * a_h + cross_normal * a_cross,
            throttle_frac: Some(throttle),
        }
    }

    /// Picks the landing site and the fine-braking time-to-go (see [`LandingSite`]).
    fn choose_site(&mut self, nav: &NavSolution, max_accel: f64, min_accel: f64) {
        if let (Some(geo), Some(up_site)) = (self.site_range(nav), self.site_unit_mci(nav.t_s)) {
            // The scenario's site: the time-to-go that makes the nominal horizontal
            // deceleration constant (`T = 2 D / V`), within the time-to-go limits.
            let c = &self.cfg;
            let v = nav.horizontal_velocity_mci_m_s().norm();
            let tgo = if v > 1e-3 {
                2.0 * geo.range_m / v
            } else {
                c.fine_min_tgo_s
            }
            .clamp(c.fine_min_tgo_s, c.fine_max_tgo_s);
            // Out of reach (rough braking arrived too close: a thrust shortfall beyond
            // the range control's margin): no arc within the thrust limits ends there.
            // Safety first: land long, on the shortest feasible arc along the track.
            if v > 1e-3 && tgo < self.shortest_feasible_tgo(nav, max_accel, min_accel) {
                self.choose_site_on_track(nav, max_accel, min_accel);
                return;
            }
            let surface_r = nav.pos_mci_m.norm() - nav.altitude_m;
            self.site = Some(LandingSite {
                surface_mci_m: up_site * surface_r,
                target_mci_m: up_site * (surface_r + c.fine_target_altitude_m),
                target_vel_mci_m_s: up_site * c.fine_target_vertical_speed_m_s,
                arrival_t_s: nav.t_s + tgo,
                chosen_t_s: nav.t_s,
            });
            return;
        }
        self.choose_site_on_track(nav, max_accel, min_accel);
    }

    /// The shortest fine-braking time-to-go (1 s grid) whose nominal E-guidance arc
    /// stays within `fine_accel_fraction` of the maximum and above the throttle floor.
    fn shortest_feasible_tgo(&self, nav: &NavSolution, max_accel: f64, min_accel: f64) -> f64 {
        let c = &self.cfg;
        let v = nav.horizontal_velocity_mci_m_s().norm();
        let v_up = nav.vertical_speed_m_s();
        let dz = c.fine_target_altitude_m - nav.altitude_m;
        let g = nav.gravity_m_s2;
        let limit = c.fine_accel_fraction * max_accel;
        let floor = c.fine_min_accel_margin * min_accel;
        let mut tgo = c.fine_max_tgo_s;
        let mut candidate = c.fine_min_tgo_s;
        while candidate <= c.fine_max_tgo_s {
            let t = candidate;
            // Nominal E-guidance arc: thrust acceleration is linear in time, so its
            // extremes are at the ends. Horizontal: constant V / T (site at V T / 2).
            let a_h = v / t;
            let miss = dz - v_up * t;
            let dv = c.fine_target_vertical_speed_m_s - v_up;
            let a_up_start = 6.0 * miss / (t * t) - 2.0 * dv / t + g;
            let a_up_end = -6.0 * miss / (t * t) + 4.0 * dv / t + g;
            let start = a_h.hypot(a_up_start);
            let end = a_h.hypot(a_up_end);
            if start.max(end) <= limit
                && start.min(end) >= floor
                && a_up_start > 0.0
                && a_up_end > 0.0
            {
                tgo = t;
                break;
            }
            candidate += 1.0;
        }
        tgo
    }

    /// Without a reachable scenario site: a site `V T / 2` ahead on the shortest
    /// feasible arc, towards the scenario's site when it lies ahead (landing long but on
    /// the line to it, not wherever the track points), else along the ground track.
    fn choose_site_on_track(&mut self, nav: &NavSolution, max_accel: f64, min_accel: f64) {
        let c = &self.cfg;
        let v = nav.horizontal_velocity_mci_m_s().norm();
        let tgo = self.shortest_feasible_tgo(nav, max_accel, min_accel);
        let track = downrange_unit(nav);
        let down = match self.site_range(nav) {
            Some(geo) if geo.to_site_mci.dot(&track) > 0.0 => geo.to_site_mci,
            _ => track,
        };
        let ground = nav.pos_mci_m + down * (0.5 * v * tgo);
        let up_site = ground.normalize();
        let surface_r = nav.pos_mci_m.norm() - nav.altitude_m;
        self.site = Some(LandingSite {
            surface_mci_m: up_site * surface_r,
            target_mci_m: up_site * (surface_r + c.fine_target_altitude_m),
            target_vel_mci_m_s: up_site * c.fine_target_vertical_speed_m_s,
            arrival_t_s: nav.t_s + tgo,
            chosen_t_s: nav.t_s,
        });
    }

    fn fine_braking(
        &mut self,
        nav: &NavSolution,
        max_accel: f64,
        min_accel: f64,
    ) -> GuidanceCommand {
        let Some(site) = self.site else {
            return self.terminal(nav, 0.0, max_accel, min_accel);
        };
        let tgo = site.arrival_t_s - nav.t_s;
        if tgo > self.cfg.fine_hold_tgo_s {
            let r = nav.pos_mci_m;
            let v = nav.vel_mci_m_s;
            // The target turns with the Moon: where it will be at arrival, moving with
            // the ground (plus the planned vertical speed).
            let omega = self.cfg.moon_rotation_rad_s;
            let r_f = site.turned(&site.target_mci_m, site.arrival_t_s, omega);
            let v_f = site.turned(&site.target_vel_mci_m_s, site.arrival_t_s, omega)
                + Vector3::new(0.0, 0.0, omega).cross(&r_f);
            let mut a = (r_f - r - v * tgo) * (6.0 / (tgo * tgo))
                - (v_f - v) * (2.0 / tgo)
                - nav.gravity_mci_m_s2();
            if tgo < self.cfg.fine_velocity_only_tgo_s {
                // Near the end, horizontally only the velocity is flown to its target
                // (constant acceleration, `(v_f - v) / t`): a late shift of the position
                // estimate (a filter update, tens of metres) would otherwise be corrected
                // with `6 / t^2` in a few seconds, tilting the vehicle towards horizontal
                // (campaign case 47 on sensor navigation: 80 deg, 46 m/s sideways). What
                // is left of the position error, the terminal descent takes in.
                let up = nav.up_mci;
                let vertical = up * a.dot(&up);
                let dv = v_f - v;
                a = vertical + (dv - up * dv.dot(&up)) / tgo;
            }
            self.held_accel_mci_m_s2 = a;
        }
        GuidanceCommand {
            accel_mci_m_s2: self.held_accel_mci_m_s2,
            throttle_frac: None,
        }
    }

    fn terminal(
        &mut self,
        nav: &NavSolution,
        dt_s: f64,
        max_accel: f64,
        min_accel: f64,
    ) -> GuidanceCommand {
        let c = &self.cfg;
        let h = nav.altitude_m;
        let v_up_ref = match self.phase {
            Phase::Hover => (c.hover_gain_altitude_1_s * (c.hover_altitude_m - h))
                .clamp(-c.hover_max_speed_m_s, c.hover_max_speed_m_s),
            // Constant deceleration a_f down to the touchdown speed at h_f:
            // v^2 = v_td^2 + 2 a_f (h - h_f).
            Phase::FinalDescent => -(c.touchdown_speed_m_s * c.touchdown_speed_m_s
                + 2.0 * c.final_decel_m_s2 * (h - c.final_altitude_m).max(0.0))
            .sqrt()
            .min(c.final_max_speed_m_s),
            _ => -(2.0 * c.terminal_decel_m_s2 * (h - c.hover_altitude_m).max(0.0))
                .sqrt()
                .min(c.terminal_max_speed_m_s),
        };
        let err = v_up_ref - nav.vertical_speed_m_s();
        let a_up_raw = nav.gravity_m_s2
            + c.terminal_gain_vertical_speed_1_s * err
            + self.vertical_integral_m_s2;
        // The engines cannot go below their throttle floor nor above full thrust: clip,
        // and integrate only while the demand is achievable (anti-windup).
        let a_up = a_up_raw.clamp(min_accel, max_accel.max(min_accel));
        if a_up == a_up_raw {
            self.vertical_integral_m_s2 = (self.vertical_integral_m_s2
                + c.terminal_gain_vertical_integral_1_s2 * err * dt_s)
                .clamp(
                    -c.terminal_integral_limit_m_s2,
                    c.terminal_integral_limit_m_s2,
                );
        }

        let vh = nav.horizontal_velocity_mci_m_s();
        let mut a_h = -vh * c.terminal_gain_horizontal_speed_1_s;
        if self.phase != Phase::FinalDescent {
            if let Some(site) = self.site {
                let surface_now =
                    site.turned(&site.surface_mci_m, nav.t_s, self.cfg.moon_rotation_rad_s);
                let off = nav.pos_mci_m - surface_now;
                let mut off_h = off - nav.up_mci * off.dot(&nav.up_mci);
                let n = off_h.norm();
                if n > c.terminal_max_position_error_m {
                    off_h *= c.terminal_max_position_error_m / n;
                }
                let gain = if self.diverting && self.phase == Phase::Hover {
                    c.divert_gain_position_1_s2
                } else {
                    c.terminal_gain_position_1_s2
                };
                a_h -= off_h * gain;
            }
        }
        let max_tilt_deg = if h < c.final_upright_altitude_m {
            c.final_max_tilt_deg
        } else {
            c.terminal_max_tilt_deg
        };
        let a_h_max = a_up.max(0.0) * max_tilt_deg.to_radians().tan();
        let n = a_h.norm();
        if n > a_h_max {
            a_h *= a_h_max / n;
        }
        GuidanceCommand {
            accel_mci_m_s2: nav.up_mci * a_up + a_h,
            throttle_frac: None,
        }
    }
}

/// Rough braking's arc at a constant throttle, flown by [`Guidance::rough_overshoot_m`]
/// one fixed step at a time: planar point mass, horizontal speed relative to the
/// ground, altitude on the reference profile (the vertical channel tracks it, so the
/// vertical thrust is `g - V^2/r`), mass falling with the flow of the commanded thrust.
/// Allocation-free; at most an hour of braking is predicted (the loop must end).
struct RoughArc<'a> {
    cfg: &'a GncConfig,
    /// Reference profile: altitude and speed at its start and end, m and m/s.
    h0: f64,
    h_end: f64,
    v_end: f64,
    span: f64,
    force: f64,
    mdot: f64,
    /// Horizontal speed, m/s; mass, kg; ground distance covered, m.
    v: f64,
    m: f64,
    s: f64,
    /// The last step's horizontal deceleration, m/s^2.
    a_h: f64,
    /// Steps left before the hour is up.
    steps_left: usize,
    /// No horizontal deceleration is left: the arc never ends (overshoot infinite).
    stalled: bool,
    done: bool,
}

impl<'a> RoughArc<'a> {
    fn new(g: &'a Guidance, throttle: f64, nav: &NavSolution, thrust_n: f64) -> Self {
        let c = &g.cfg;
        let (h0, v0) = g.rough_start;
        let v_end = c.rough_end_speed_m_s;
        let force = throttle * thrust_n;
        RoughArc {
            cfg: c,
            h0,
            h_end: c.rough_end_altitude_m,
            v_end,
            span: (v0 - v_end).max(1.0),
            force,
            mdot: force / (c.isp_s * 9.806_65),
            v: nav.horizontal_velocity_mci_m_s().norm(),
            m: nav.mass_kg.max(c.dry_mass_kg),
            s: 0.0,
            a_h: 0.0,
            steps_left: (3600.0 / c.rough_predict_step_s) as usize,
            stalled: false,
            done: false,
        }
    }

    /// Horizontal deceleration at speed `v` and mass `m`, and the radius there.
    #[inline(always)]
    fn accel_h(&self, v: f64, m: f64) -> (f64, f64) {
        let c = self.cfg;
        let frac = ((v - self.v_end) / self.span).clamp(0.0, 1.0);
        let r = c.moon_radius_m + self.h_end + (self.h0 - self.h_end) * frac;
        let a_t = self.force / m;
        let a_up = (c.moon_mu_m3_s2 / (r * r) - v * v / r).clamp(0.0, c.rough_max_up_frac * a_t);
        ((a_t * a_t - a_up * a_up).max(0.0).sqrt(), r)
    }

    /// One step of the arc; false once it has ended (then it does nothing).
    #[inline(always)]
    fn advance(&mut self) -> bool {
        if self.done {
            return false;
        }
        if self.steps_left == 0 || self.v <= self.v_end {
            self.done = true;
            return false;
        }
        self.steps_left -= 1;
        let dt = self.cfg.rough_predict_step_s;
        let (ah, r) = self.accel_h(self.v, self.m);
        self.a_h = ah;
        if ah <= 1e-6 {
            self.stalled = true;
            self.done = true;
            return false;
        }
        let v = self.v;
        let v_next = v - ah * dt;
        let scale = self.cfg.moon_radius_m / r;
        if v_next <= self.v_end {
            let tau = (v - self.v_end) / ah;
            self.s += 0.5 * (v + self.v_end) * tau * scale;
            self.v = self.v_end;
            self.done = true;
            return false;
        }
        self.s += 0.5 * (v + v_next) * dt * scale;
        self.v = v_next;
        self.m = (self.m - self.mdot * dt).max(self.cfg.dry_mass_kg);
        true
    }

    /// The overshoot past `range_go_m` once the arc has ended: the attitude hold flies
    /// on at the same deceleration, then fine braking covers `V T / 2`.
    fn overshoot_m(&self, range_go_m: f64) -> f64 {
        if self.stalled {
            return f64::INFINITY;
        }
        let c = self.cfg;
        let hold = c.attitude_hold_s;
        let v_fine = (self.v - self.a_h * hold).max(0.0);
        let s = self.s + 0.5 * (self.v + v_fine) * hold;
        s + 0.5 * v_fine * c.fine_plan_tgo_s - range_go_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    fn nav_at(t_s: f64, r: Vector3<f64>, v: Vector3<f64>, cfg: &GncConfig) -> NavSolution {
        let radius = 1_737_400.0 + 1.2;
        let rn = r.norm();
        NavSolution {
            t_s,
            pos_mci_m: r,
            vel_mci_m_s: v,
            q_mci_from_body: UnitQuaternion::identity(),
            rate_body_rad_s: Vector3::zeros(),
            specific_force_body_m_s2: Vector3::zeros(),
            altitude_m: rn - radius,
            mass_kg: 1000.0,
            up_mci: r / rn,
            gravity_m_s2: cfg.moon_mu_m3_s2 / (rn * rn),
            omega_moon_mci: Vector3::new(0.0, 0.0, cfg.moon_rotation_rad_s),
        }
    }

    /// Fine braking alone on a point mass flying exactly the commanded acceleration:
    /// E-guidance must deliver the target state, within the planned acceleration.
    #[test]
    fn fine_braking_reaches_its_target_state_within_the_acceleration_limit() {
        // No scenario site: the site is chosen on the track at fine-braking start.
        let cfg = GncConfig {
            site: None,
            ..GncConfig::default()
        };
        let mut g = Guidance::new(&cfg);
        let radius = 1_737_400.0 + 1.2;
        let mut r = Vector3::new(radius + 6_800.0, 0.0, 0.0);
        let mut v = Vector3::new(-40.0, 340.0, 0.0);
        let (max_accel, min_accel) = (3.0, 1.2);
        let dt = 0.01;
        let mut t = 0.0;
        let mut peak: f64 = 0.0;
        loop {
            let nav = nav_at(t, r, v, &cfg);
            let cmd = g.update(&nav, max_accel, min_accel);
            if g.phase() != Phase::FineBraking {
                break;
            }
            peak = peak.max(cmd.accel_mci_m_s2.norm());
            let a = cmd.accel_mci_m_s2 - r * (cfg.moon_mu_m3_s2 / r.norm().powi(3));
            v += a * dt;
            r += v * dt;
            t += dt;
            assert!(t < 1_000.0, "fine braking never ended");
        }
        // The target turned with the Moon since it was chosen; the speeds that count
        // are over the (turning) ground.
        let site = g.site().unwrap();
        let omega = cfg.moon_rotation_rad_s;
        let target = site.turned(&site.target_mci_m, t, omega);
        let up = target.normalize();
        let v = v - Vector3::new(0.0, 0.0, omega).cross(&r);
        let v_h = (v - up * v.dot(&up)).norm();
        assert!((r - target).norm() < 5.0, "{}", (r - target).norm());
        assert!(v_h < 0.5, "horizontal {v_h}");
        assert!((v.dot(&up) - cfg.fine_target_vertical_speed_m_s).abs() < 0.5);
        // Planned within fine_accel_fraction of the maximum (a little slack for the
        // closed loop's replanning and the held command).
        assert!(
            peak <= 1.02 * cfg.fine_accel_fraction * max_accel,
            "peak {peak}"
        );
    }

    #[test]
    fn starts_in_the_phase_that_fits_the_initial_state() {
        let cfg = GncConfig::default();
        let radius = 1_737_400.0 + 1.2;
        let start = |h: f64, v_h: f64| {
            let mut g = Guidance::new(&cfg);
            let nav = nav_at(
                0.0,
                Vector3::new(radius + h, 0.0, 0.0),
                Vector3::new(0.0, v_h, 0.0),
                &cfg,
            );
            g.update(&nav, 3.0, 1.2);
            g.phase()
        };
        assert_eq!(start(30_000.0, 1_680.0), Phase::RoughBraking);
        assert_eq!(start(5_000.0, 200.0), Phase::FineBraking);
        assert_eq!(start(500.0, 0.0), Phase::TerminalDescent);
        assert_eq!(start(20.0, 0.0), Phase::FinalDescent);
    }
}
