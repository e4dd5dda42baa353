//! Hazard detection and avoidance: at the hover, one flash-lidar frame becomes a height
//! map of the ground below; every spot the lander could set down on is judged by the
//! plane its legs would meet (slope) and what stands out of it (rocks, holes); the
//! safest spot within the divert budget (nearer ones preferred) is chosen, and
//! guidance flies there before the final descent.
//!
//! Why at the hover (100 m): the lidar's 20 deg view spans 35 m there, with 0.27 m
//! pixels, finer than the smallest rock that matters (0.3 m) and wide enough for a
//! divert of a few leg spans; Chang'e-3 hovered at 100 m to scan with its laser imager
//! for the same reason, Chandrayaan-3 at about 150 m with its hazard camera
//! (`shared/reference/eyes-and-terrain.md`).
//!
//! The map (`docs/gnc.md`, "Hazard detection and avoidance"): every return becomes a
//! point in a local frame (east, north, up about the vehicle's ground point), the points
//! are binned into `cell_m` cells (mean height). For each candidate spot, on a
//! `candidate_step_m` grid: a least-squares plane over the cells within
//! `footprint_radius_m` (the footpads' circle); its tilt is the slope, the largest
//! residual the roughness. Safe: slope at most `max_slope_deg` and roughness at most
//! `max_roughness_m`, with at least `min_coverage` of the disk's cells seen. All buffers
//! are allocated when the navigation is built; nothing here allocates in flight.

use super::nav_filter::NavFilter;
use nalgebra::{Matrix3, Vector3};
use oils_shared::plane_fit::PlaneFit;
use oils_shared::{
    FrameAnnouncement, FRAME_DEVICE_LIDAR, FRAME_FLAG_FROZEN, FRAME_FLAG_OUTAGE,
    FRAME_FORMAT_F32_LE_M,
};

/// A judged candidate: its score, offset east and north (m), slope (deg), roughness (m).
type Pick = (f64, f64, f64, f64, f64);

/// The flash lidar as the flight software knows it (the emulator's defaults,
/// `docs/sensors.md`).
#[derive(Debug, Clone, PartialEq)]
pub struct LidarModel {
    /// Pixels per row.
    pub width_px: u32,
    /// Rows.
    pub height_px: u32,
    /// Full field of view across the width, degrees (no distortion).
    pub fov_deg: f64,
    /// Boresight, body axes.
    pub boresight_body: [f64; 3],
    /// Increasing column, body axes.
    pub image_right_body: [f64; 3],
    /// Optical centre relative to the centre of mass, body, m.
    pub position_body_m: [f64; 3],
}

impl Default for LidarModel {
    fn default() -> Self {
        Self {
            width_px: 128,
            height_px: 128,
            fov_deg: 20.0,
            boresight_body: [0.0, 0.0, -1.0],
            image_right_body: [0.0, 1.0, 0.0],
            position_body_m: [0.9, 0.3, -0.6],
        }
    }
}

/// What hazard detection assumes and how it judges a spot.
#[derive(Debug, Clone, PartialEq)]
pub struct HazardConfig {
    /// Detect and avoid at all (needs the lidar's frames).
    pub enabled: bool,
    /// The lidar.
    pub lidar: LidarModel,
    /// Height-map cell, m.
    pub cell_m: f64,
    /// Half the height map's side, m (the 20 deg view at 100 m spans 35 m).
    pub half_extent_m: f64,
    /// Radius of the circle the footpads stand on, plus their pads, m (the reference
    /// lander's pads at 1.8 m, `docs/plant.md`).
    pub footprint_radius_m: f64,
    /// Candidate spots every this many metres.
    pub candidate_step_m: f64,
    /// Largest slope of a safe spot, degrees (the legs' limit, 11.4 deg, with margin for
    /// the fit and the settling on crushed struts; assumed).
    pub max_slope_deg: f64,
    /// Largest rock or hole under the footprint of a safe spot, m (assumed: the body's
    /// clearance above the pads, 0.3 m).
    pub max_roughness_m: f64,
    /// Least share of a spot's cells with a return.
    pub min_coverage: f64,
    /// Farthest the lander diverts from where it was going, m.
    pub max_divert_m: f64,
}

impl Default for HazardConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            lidar: LidarModel::default(),
            cell_m: 0.5,
            half_extent_m: 20.0,
            footprint_radius_m: 2.2,
            candidate_step_m: 0.5,
            max_slope_deg: 8.0,
            max_roughness_m: 0.3,
            min_coverage: 0.8,
            max_divert_m: 15.0,
        }
    }
}

/// The spot hazard detection chose.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SpotChoice {
    /// The frame's time of validity, ns.
    pub t_ns: i64,
    /// The chosen spot's ground point, `mci` at `t_ns`, m.
    pub spot_mci_m: Vector3<f64>,
    /// How far it is from the aim point, m.
    pub divert_m: f64,
    /// Its slope, degrees, and roughness, m.
    pub slope_deg: f64,
    /// See `slope_deg`.
    pub roughness_m: f64,
    /// Whether it passed both limits (false: the least bad spot; nothing safe in reach).
    pub safe: bool,
    /// The aim point's own slope and roughness (what flying blind would have met).
    pub aim_slope_deg: f64,
    /// See `aim_slope_deg`.
    pub aim_roughness_m: f64,
    /// Candidates judged and those safe.
    pub candidates: u32,
    /// See `candidates`.
    pub safe_candidates: u32,
}

/// Hazard detection's state.
#[derive(Debug, Clone)]
pub struct HazardDetection {
    cfg: HazardConfig,
    ranges: Vec<f32>,
    pending: Option<i64>,
    /// Height-map cells: sum of heights and count.
    sum: Vec<f32>,
    count: Vec<u16>,
    side: usize,
    armed: bool,
    choice: Option<SpotChoice>,
    frames_seen: u32,
}

impl HazardDetection {
    /// Allocates the frame and the height map (nothing when disabled).
    pub fn new(cfg: HazardConfig) -> Self {
        let on = usize::from(cfg.enabled);
        let side = ((2.0 * cfg.half_extent_m / cfg.cell_m).ceil() as usize).max(1);
        Self {
            ranges: vec![0.0; on * (cfg.lidar.width_px * cfg.lidar.height_px) as usize],
            sum: vec![0.0; on * side * side],
            count: vec![0; on * side * side],
            side,
            pending: None,
            armed: false,
            choice: None,
            frames_seen: 0,
            cfg,
        }
    }

    /// Forgets what it found (a computer reset), keeping its buffers.
    pub fn reset(&mut self) {
        self.pending = None;
        self.armed = false;
        self.choice = None;
        self.frames_seen = 0;
    }

    /// Whether it is on.
    pub fn enabled(&self) -> bool {
        self.cfg.enabled
    }

    /// Starts looking: the next lidar frame is assessed (guidance calls it on entering
    /// the hover).
    pub fn arm(&mut self) {
        if self.cfg.enabled && self.choice.is_none() {
            self.armed = true;
        }
    }

    /// Whether it is waiting for a frame to assess.
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// The spot chosen, once assessed.
    pub fn choice(&self) -> Option<&SpotChoice> {
        self.choice.as_ref()
    }

    /// Lidar frames handed over while armed.
    pub fn frames_seen(&self) -> u32 {
        self.frames_seen
    }

    /// Takes in a frame: a usable lidar frame while armed is kept for [`Self::assess`].
    pub fn frame(&mut self, ann: &FrameAnnouncement, pixels: &[u8]) {
        if !self.armed || ann.device != FRAME_DEVICE_LIDAR {
            return;
        }
        self.frames_seen += 1;
        let n = self.ranges.len();
        if ann.format != FRAME_FORMAT_F32_LE_M
            || ann.width != self.cfg.lidar.width_px
            || ann.height != self.cfg.lidar.height_px
            || pixels.len() != n * 4
            || ann.flags & (FRAME_FLAG_OUTAGE | FRAME_FLAG_FROZEN) != 0
        {
            return;
        }
        for (r, b) in self.ranges.iter_mut().zip(pixels.chunks_exact(4)) {
            *r = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        self.pending = Some(ann.t_ns);
    }

    /// Builds the height map from the kept frame and chooses the spot nearest `aim_mci`
    /// (the ground point guidance flies to, `mci` at the frame's time) that is safe.
    /// `None`: no frame waiting, or too little of the ground seen.
    pub fn assess(
        &mut self,
        filter: &NavFilter,
        aim_at: impl Fn(i64) -> Vector3<f64>,
    ) -> Option<SpotChoice> {
        let t_ns = self.pending.take()?;
        let cfg = &self.cfg;
        let (r, q) = filter.pose_at(t_ns);
        let l = &cfg.lidar;
        let body_from_lidar = {
            let z = Vector3::from(l.boresight_body).normalize();
            let rr = Vector3::from(l.image_right_body);
            let x = (rr - z * z.dot(&rr)).normalize();
            Matrix3::from_columns(&[x, z.cross(&x), z])
        };
        let mci_from_lidar = q.to_rotation_matrix().matrix() * body_from_lidar;
        let origin = r + q * Vector3::from(l.position_body_m);
        // The local frame about the vehicle's ground point.
        let up = r.normalize();
        let east = Vector3::z().cross(&up).normalize();
        let north = up.cross(&east);
        let f_px = 0.5 * l.width_px as f64 / (0.5 * l.fov_deg.to_radians()).tan();
        let (cx, cy) = (0.5 * l.width_px as f64, 0.5 * l.height_px as f64);
        self.sum.iter_mut().for_each(|v| *v = 0.0);
        self.count.iter_mut().for_each(|v| *v = 0);
        let half = cfg.half_extent_m;
        let side = self.side;
        let mut z_ref = None;
        for j in 0..l.height_px as usize {
            for i in 0..l.width_px as usize {
                let range = self.ranges[j * l.width_px as usize + i] as f64;
                if !(range > 0.0 && range.is_finite()) {
                    continue;
                }
                let d = Vector3::new(
                    (i as f64 + 0.5 - cx) / f_px,
                    (j as f64 + 0.5 - cy) / f_px,
                    1.0,
                )
                .normalize();
                let p = origin + mci_from_lidar * d * range - r;
                let (x, y, z) = (p.dot(&east), p.dot(&north), p.dot(&up));
                // Heights about the first return (f32 keeps centimetres there).
                let z0 = *z_ref.get_or_insert(z);
                let (ci, cj) = (
                    ((x + half) / cfg.cell_m).floor(),
                    ((y + half) / cfg.cell_m).floor(),
                );
                if ci < 0.0 || cj < 0.0 || ci >= side as f64 || cj >= side as f64 {
                    continue;
                }
                let k = cj as usize * side + ci as usize;
                self.sum[k] += (z - z0) as f32;
                self.count[k] = self.count[k].saturating_add(1);
            }
        }
        let z0 = z_ref?;
        // The aim point in the local frame.
        let aim = aim_at(t_ns) - r;
        let (ax, ay) = (aim.dot(&east), aim.dot(&north));
        let judge = |x: f64, y: f64| self.judge(x, y);
        let aim_judged = judge(ax, ay);
        let step = cfg.candidate_step_m;
        let reach = cfg.max_divert_m;
        let steps = (reach / step).floor() as i64;
        // (score, east, north, slope, roughness)
        let (mut best_safe, mut best_any): (Option<Pick>, Option<Pick>) = (None, None);
        let (mut candidates, mut safe_candidates) = (0u32, 0u32);
        for a in -steps..=steps {
            for b in -steps..=steps {
                let (dx, dy) = (b as f64 * step, a as f64 * step);
                let dist = dx.hypot(dy);
                if dist > reach {
                    continue;
                }
                let Some((slope, rough)) = judge(ax + dx, ay + dy) else {
                    continue;
                };
                candidates += 1;
                let safe = slope <= cfg.max_slope_deg && rough <= cfg.max_roughness_m;
                if safe {
                    safe_candidates += 1;
                    // The safest spot, nearer ones preferred: slope and roughness as
                    // shares of their limits, plus half the divert's share of its budget.
                    let score = slope / cfg.max_slope_deg
                        + rough / cfg.max_roughness_m
                        + 0.5 * dist / cfg.max_divert_m;
                    if best_safe.is_none_or(|s| score < s.0) {
                        best_safe = Some((score, dx, dy, slope, rough));
                    }
                }
                let badness = slope / cfg.max_slope_deg + rough / cfg.max_roughness_m + 0.01 * dist;
                if best_any.is_none_or(|s| badness < s.0) {
                    best_any = Some((badness, dx, dy, slope, rough));
                }
            }
        }
        let (pick, safe) = match (best_safe, best_any) {
            (Some(s), _) => (s, true),
            (None, Some(a)) => (a, false),
            (None, None) => return None,
        };
        let (_, dx, dy, slope, rough) = pick;
        let spot = r
            + east * (ax + dx)
            + north * (ay + dy)
            + up * (z0 + self.plane_height(ax + dx, ay + dy).unwrap_or(0.0));
        let (aim_slope, aim_rough) = aim_judged.unwrap_or((f64::NAN, f64::NAN));
        let choice = SpotChoice {
            t_ns,
            spot_mci_m: spot,
            divert_m: dx.hypot(dy),
            slope_deg: slope,
            roughness_m: rough,
            safe,
            aim_slope_deg: aim_slope,
            aim_roughness_m: aim_rough,
            candidates,
            safe_candidates,
        };
        self.choice = Some(choice);
        self.armed = false;
        Some(choice)
    }

    /// The plane through the footprint at local `(x, y)`: its slope (deg) and the largest
    /// residual (m); `None` when too little of it was seen.
    fn judge(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let plane = self.fit(x, y)?;
        let [a, b, c] = plane;
        let mut rough = 0.0f64;
        self.for_cells(x, y, self.cfg.footprint_radius_m, |cx, cy, h| {
            rough = rough.max((h - (a + b * (cx - x) + c * (cy - y))).abs());
        });
        Some((PlaneFit::slope_deg(&plane), rough))
    }

    /// The fitted plane's height at `(x, y)` (relative to the first return).
    fn plane_height(&self, x: f64, y: f64) -> Option<f64> {
        self.fit(x, y).map(|c| c[0])
    }

    /// Least-squares plane `h = a + b (x' - x) + c (y' - y)` over the footprint's cells
    /// (the same fit the emulator judges a touchdown's ground with).
    fn fit(&self, x: f64, y: f64) -> Option<[f64; 3]> {
        let cfg = &self.cfg;
        let rad = cfg.footprint_radius_m;
        let mut total = 0usize;
        self.for_disk(x, y, rad, |_| total += 1);
        let mut fit = PlaneFit::default();
        self.for_cells(x, y, rad, |cx, cy, h| fit.add(cx - x, cy - y, h));
        let n = fit.count();
        if total == 0 || (n as f64) < cfg.min_coverage * total as f64 || n < 6 {
            return None;
        }
        fit.solve()
    }

    /// Every cell centre within `rad` of `(x, y)` inside the map.
    fn for_disk(&self, x: f64, y: f64, rad: f64, mut f: impl FnMut(usize)) {
        let cfg = &self.cfg;
        let side = self.side as i64;
        let half = cfg.half_extent_m;
        let k = (rad / cfg.cell_m).ceil() as i64 + 1;
        let (ci, cj) = (
            ((x + half) / cfg.cell_m).floor() as i64,
            ((y + half) / cfg.cell_m).floor() as i64,
        );
        for j in cj - k..=cj + k {
            for i in ci - k..=ci + k {
                let (px, py) = (
                    -half + (i as f64 + 0.5) * cfg.cell_m,
                    -half + (j as f64 + 0.5) * cfg.cell_m,
                );
                if (px - x).hypot(py - y) > rad {
                    continue;
                }
                if i < 0 || j < 0 || i >= side || j >= side {
                    f(usize::MAX);
                    continue;
                }
                f((j * side + i) as usize);
            }
        }
    }

    /// The seen cells within `rad` of `(x, y)`: centre and mean height.
    fn for_cells(&self, x: f64, y: f64, rad: f64, mut f: impl FnMut(f64, f64, f64)) {
        let cfg = &self.cfg;
        let half = cfg.half_extent_m;
        let side = self.side;
        self.for_disk(x, y, rad, |k| {
            if k == usize::MAX || self.count[k] == 0 {
                return;
            }
            let (i, j) = (k % side, k / side);
            let (px, py) = (
                -half + (i as f64 + 0.5) * cfg.cell_m,
                -half + (j as f64 + 0.5) * cfg.cell_m,
            );
            f(px, py, (self.sum[k] / self.count[k] as f32) as f64);
        });
    }
}
