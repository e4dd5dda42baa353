//! Terrain-relative navigation: camera frames matched against the onboard map give
//! absolute horizontal position fixes for the navigation filter.
//!
//! Method: map-relative localisation by normalised cross-correlation (NCC) of an
//! orthorectified image patch against the map, the coarse stage of the Mars 2020 Lander
//! Vision System (Johnson et al., "The Lander Vision System for Mars 2020 Entry Descent
//! and Landing", AAS 17-038, 2017), itself DSMAC's area correlation on a rendered
//! reference. Chosen over crater matching because it needs no crater catalogue and
//! works on any texture the map renders (rocks, small craters, shadows), and over
//! landmark matching because a single patch correlation is a few milliseconds with no
//! feature bookkeeping; NCC is invariant to the camera's gain and offset, so the map's
//! I/F and the frame's DN compare directly.
//!
//! Per frame (`docs/gnc.md`, "Terrain-relative navigation"):
//! 1. the frame becomes a mip pyramid (2x2 box averages) in buffers allocated at build;
//! 2. the filter's pose at the frame's time of validity puts the camera over the map:
//!    the boresight's ground point `(e_c, n_c)`, the range, a pixel's ground footprint;
//! 3. the map level is the finest whose cell is at least `cell_per_pixel` footprints
//!    and over which the search (3 sigma of the horizontal position) spans at most
//!    `max_search_cells`;
//! 4. a `patch_cells`² patch of map cells about `(e_c, n_c)` is projected into the
//!    frame (map height, pinhole with distortion) and sampled from the pyramid level of
//!    the cell's size: the frame as the map would show it if the estimate were right;
//! 5. NCC of the patch against the map at every offset within the search; the best
//!    offset, refined by a parabola through its neighbours, is the estimate's error
//!    (true minus estimate) in map east and north;
//! 6. gates: an outage, frozen or saturated frame; too little texture; a weak peak; a
//!    second peak nearly as good (a repeated pattern); the peak on the search's edge;
//!    then the filter's own 2-dof chi-square gate on the innovation (a shifted map).
//!
//! Everything a frame needs is allocated when the navigation is built; `frame` and
//! `process` never allocate.

use super::nav_filter::NavFilter;
use super::terrain_map::{MapLevel, TerrainMap};
use nalgebra::{Matrix3, Rotation3, Vector3};
use oils_shared::{
    FrameAnnouncement, FRAME_DEVICE_CAMERA, FRAME_FLAG_FROZEN, FRAME_FLAG_OUTAGE,
    FRAME_FORMAT_U16_LE,
};
use std::sync::Arc;

/// The navigation camera as the flight software knows it (the emulator's defaults,
/// `docs/sensors.md`; the scenario's camera must match: a frame of another size is
/// refused).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    /// Pixels per row.
    pub width_px: u32,
    /// Rows.
    pub height_px: u32,
    /// Full field of view across the width, degrees.
    pub fov_deg: f64,
    /// Brown-Conrady `r^2` coefficient.
    pub k1: f64,
    /// Brown-Conrady `r^4` coefficient.
    pub k2: f64,
    /// Boresight (camera +z), body axes.
    pub boresight_body: [f64; 3],
    /// Increasing column (camera +x), body axes.
    pub image_right_body: [f64; 3],
    /// Optical centre relative to the centre of mass, body, m.
    pub position_body_m: [f64; 3],
    /// Full-scale digital number (the ADC's `2^bits - 1`).
    pub full_scale_dn: u16,
}

impl Default for CameraModel {
    fn default() -> Self {
        Self {
            width_px: 1024,
            height_px: 1024,
            fov_deg: 45.0,
            k1: -0.05,
            k2: 0.005,
            boresight_body: [0.0, 0.0, -1.0],
            image_right_body: [0.0, 1.0, 0.0],
            position_body_m: [0.9, 0.0, -0.6],
            full_scale_dn: 4095,
        }
    }
}

impl CameraModel {
    /// Focal length, pixels.
    pub fn f_px(&self) -> f64 {
        0.5 * self.width_px as f64 / (0.5 * self.fov_deg.to_radians()).tan()
    }

    /// Columns of the rotation taking camera directions into body axes.
    pub fn body_from_camera(&self) -> Matrix3<f64> {
        let z = Vector3::from(self.boresight_body).normalize();
        let r = Vector3::from(self.image_right_body);
        let x = (r - z * z.dot(&r)).normalize();
        let y = z.cross(&x);
        Matrix3::from_columns(&[x, y, z])
    }

    /// Image point (pixels, pixel `(i, j)` spans `[i, i+1)`) of a camera direction.
    #[inline]
    pub fn project(&self, f_px: f64, p: &Vector3<f64>) -> Option<(f64, f64)> {
        if p.z <= 0.0 {
            return None;
        }
        let (x, y) = (p.x / p.z, p.y / p.z);
        let r2 = x * x + y * y;
        if 1.0 + r2 * (3.0 * self.k1 + 5.0 * self.k2 * r2) <= 0.0 {
            return None;
        }
        let d = 1.0 + r2 * (self.k1 + self.k2 * r2);
        Some((
            0.5 * self.width_px as f64 + f_px * x * d,
            0.5 * self.height_px as f64 + f_px * y * d,
        ))
    }
}

/// What terrain-relative navigation assumes and how hard it gates.
#[derive(Debug, Clone, PartialEq)]
pub struct TerrainNavConfig {
    /// The camera.
    pub camera: CameraModel,
    /// The map, loaded before the descent; `None`: no terrain navigation.
    pub map: Option<Arc<TerrainMap>>,
    /// Side of the correlated patch, map cells.
    pub patch_cells: usize,
    /// Largest search half-width, cells (the search spans `2 w + 1` offsets per axis).
    pub max_search_cells: usize,
    /// Least search half-width, cells: an estimate that is off by more than its own
    /// sigma still finds its peak inside the search, not on its edge.
    pub min_search_cells: usize,
    /// A map cell spans at least this many pixel footprints (fewer: the frame's noise
    /// and the map's own sampling no longer average out).
    pub cell_per_pixel: f64,
    /// Frames are matched from this height above the map's ground, m, ...
    pub max_height_m: f64,
    /// ... down to this one (below it the patch no longer fits the view).
    pub min_height_m: f64,
    /// Least patch contrast (standard deviation over mean of the sampled DN).
    pub min_contrast: f64,
    /// Least NCC of the best offset.
    pub min_peak_ncc: f64,
    /// Largest NCC of the best offset more than 2 cells from the best, over the best's.
    pub max_second_peak_ratio: f64,
    /// Largest share of saturated pixels in the patch.
    pub max_saturated_frac: f64,
    /// 1-sigma of a fix, in cells of the level it was made on (the sub-cell peak fit
    /// and the map's own rendering error; assumed, checked by the campaign's NIS).
    pub fix_sigma_cells: f64,
    /// Until the first fix is accepted (acquisition), the search spans at least this
    /// far, m, whatever the filter's own sigma: the ground's orbit determination can be
    /// off by more than it says; the first fix then widens the filter's horizontal
    /// sigma to its own size (its uniqueness gates stand in for the filter's gate).
    pub acquisition_radius_m: f64,
    /// [`Self::max_second_peak_ratio`] for the first fix (no filter gate behind it).
    pub acquisition_second_peak_ratio: f64,
    /// Terrain navigation, once acquired, is "lost" (`NAV_FLAG_TERRAIN_LOST`) after this
    /// long without an accepted fix while frames are expected (in the height band), ns.
    pub lost_after_ns: i64,
}

impl Default for TerrainNavConfig {
    fn default() -> Self {
        Self {
            camera: CameraModel::default(),
            map: None,
            patch_cells: 32,
            max_search_cells: 24,
            min_search_cells: 6,
            cell_per_pixel: 2.0,
            max_height_m: 7000.0,
            min_height_m: 40.0,
            min_contrast: 0.02,
            min_peak_ncc: 0.5,
            max_second_peak_ratio: 0.9,
            max_saturated_frac: 0.02,
            fix_sigma_cells: 1.0,
            acquisition_radius_m: 1500.0,
            acquisition_second_peak_ratio: 0.8,
            lost_after_ns: 10_000_000_000,
        }
    }
}

/// Why a frame gave no fix (index into [`TerrainNav::rejected`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// Flagged as an outage or frozen, or not a camera frame of the expected size.
    Unusable = 0,
    /// Outside the height band, or the patch or search leaves the map or the view.
    OutOfReach = 1,
    /// Too little texture (a low sun over flat ground, a blank frame).
    NoTexture = 2,
    /// Too many saturated pixels (the sun in view, glare).
    Saturated = 3,
    /// The best correlation is weak.
    WeakPeak = 4,
    /// A second peak nearly as good (a repeated pattern) or the peak on the edge.
    Ambiguous = 5,
    /// The filter's chi-square gate (a fix inconsistent with the estimate).
    Gated = 6,
    /// An acquisition candidate waiting for the next frame to confirm it.
    Unconfirmed = 7,
}

/// Kinds of [`Rejection`].
pub const REJECTIONS: usize = 8;

/// A fix the matcher made (accepted or not by the filter).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Fix {
    /// Time of validity, ns.
    pub t_ns: i64,
    /// Estimate error found (true minus estimate), map east and north, m.
    pub error_en_m: [f64; 2],
    /// 1-sigma, m.
    pub sigma_m: f64,
    /// Peak NCC.
    pub ncc: f64,
    /// Map level used.
    pub level: usize,
    /// Normalised innovation squared in the filter's gate.
    pub nis: f64,
}

/// One level of the frame's mip pyramid.
#[derive(Debug, Clone)]
struct Mip {
    w: usize,
    h: usize,
    px: Vec<f32>,
}

/// The terrain-relative navigation's state.
#[derive(Debug, Clone)]
pub struct TerrainNav {
    cfg: TerrainNavConfig,
    f_px: f64,
    body_from_cam: Matrix3<f64>,
    mips: Vec<Mip>,
    /// A frame waiting to be matched: its time of validity and the pyramid level it
    /// filled (0: the camera's full size).
    pending: Option<(i64, usize)>,
    patch: Vec<f32>,
    /// NCC per search offset, row-major over `(2 w + 1)^2`.
    scores: Vec<f64>,
    accepted: u64,
    rejected: [u64; REJECTIONS],
    last_fix: Option<Fix>,
    last_accepted_ns: Option<i64>,
    expected_since_ns: Option<i64>,
    /// A fix has been accepted since the start (or the last reset).
    acquired: bool,
    /// Acquisition: the last frame's fix (estimate error east, north, m; its level's
    /// spacing), to be confirmed by the next frame's before it is flown.
    candidate: Option<([f64; 2], f64, i64)>,
}

impl TerrainNav {
    /// Allocates the pyramid and the patch for `cfg`'s camera (nothing without a map).
    pub fn new(cfg: TerrainNavConfig) -> Self {
        let mut mips = Vec::new();
        let (mut w, mut h) = (cfg.camera.width_px as usize, cfg.camera.height_px as usize);
        while cfg.map.is_some() && w >= 8 && h >= 8 {
            mips.push(Mip {
                w,
                h,
                px: vec![0.0; w * h],
            });
            w /= 2;
            h /= 2;
        }
        let on = usize::from(cfg.map.is_some());
        let n = on * cfg.patch_cells * cfg.patch_cells;
        Self {
            f_px: cfg.camera.f_px(),
            body_from_cam: cfg.camera.body_from_camera(),
            mips,
            pending: None,
            patch: vec![0.0; n],
            scores: vec![0.0; on * (2 * cfg.max_search_cells.max(cfg.min_search_cells) + 1).pow(2)],
            accepted: 0,
            rejected: [0; REJECTIONS],
            last_fix: None,
            last_accepted_ns: None,
            expected_since_ns: None,
            acquired: false,
            candidate: None,
            cfg,
        }
    }

    /// Forgets the navigation state (a computer reset), keeping its buffers.
    pub fn reset(&mut self) {
        self.pending = None;
        self.accepted = 0;
        self.rejected = [0; REJECTIONS];
        self.last_fix = None;
        self.last_accepted_ns = None;
        self.expected_since_ns = None;
        self.acquired = false;
        self.candidate = None;
    }

    /// Whether a frame waits to be matched.
    pub fn has_pending(&self) -> bool {
        self.pending.is_some()
    }

    /// Whether there is a map to navigate by.
    pub fn enabled(&self) -> bool {
        self.cfg.map.is_some()
    }

    /// Fixes the filter accepted.
    pub fn accepted(&self) -> u64 {
        self.accepted
    }

    /// Frames that gave no fix, by [`Rejection`].
    pub fn rejected(&self) -> &[u64; REJECTIONS] {
        &self.rejected
    }

    /// The last fix made (accepted or gated by the filter).
    pub fn last_fix(&self) -> Option<&Fix> {
        self.last_fix.as_ref()
    }

    /// Whether a fix was accepted within `window_ns` of `t_ns`.
    pub fn used_within(&self, t_ns: i64, window_ns: i64) -> bool {
        self.last_accepted_ns
            .is_some_and(|t| t_ns.saturating_sub(t) <= window_ns)
    }

    /// Whether terrain navigation, once acquired, has had no fix accepted for
    /// `lost_after_ns` while frames were expected (over the map, in the height band).
    pub fn lost(&self, t_ns: i64) -> bool {
        let (Some(e), Some(a)) = (self.expected_since_ns, self.last_accepted_ns) else {
            return false;
        };
        t_ns.saturating_sub(e.max(a)) > self.cfg.lost_after_ns
    }

    fn reject(&mut self, why: Rejection) {
        self.rejected[why as usize] += 1;
    }

    /// Takes in a frame (before the step of the telemetry that announces it): a camera
    /// frame of the expected size becomes the pyramid, to be matched by the next
    /// [`TerrainNav::process`]. Other frames are ignored; unusable ones counted.
    pub fn frame(&mut self, ann: &FrameAnnouncement, pixels: &[u8]) {
        if !self.enabled() || ann.device != FRAME_DEVICE_CAMERA {
            return;
        }
        // The camera's own size, or the same optics binned by a power of two (a frame
        // of a quarter the width is the pyramid's level 2: one map serves both).
        let base = self.mips.iter().position(|m| {
            m.w == ann.width as usize && m.h == ann.height as usize && m.w * 2 * m.h == pixels.len()
        });
        let Some(base) = base.filter(|_| {
            ann.format == FRAME_FORMAT_U16_LE
                && ann.flags & (FRAME_FLAG_OUTAGE | FRAME_FLAG_FROZEN) == 0
        }) else {
            self.reject(Rejection::Unusable);
            return;
        };
        for (dst, src) in self.mips[base].px.iter_mut().zip(pixels.chunks_exact(2)) {
            *dst = u16::from_le_bytes([src[0], src[1]]) as f32;
        }
        for k in base + 1..self.mips.len() {
            let (lo, hi) = self.mips.split_at_mut(k);
            let (src, dst) = (&lo[k - 1], &mut hi[0]);
            for r in 0..dst.h {
                for c in 0..dst.w {
                    let i = 2 * r * src.w + 2 * c;
                    dst.px[r * dst.w + c] = 0.25
                        * (src.px[i] + src.px[i + 1] + src.px[i + src.w] + src.px[i + src.w + 1]);
                }
            }
        }
        self.pending = Some((ann.t_ns, base));
    }

    /// Matches the frame taken in since the last call, if any, and hands its fix to
    /// `filter`. `omega_rad_s`: the Moon's rotation rate about `mci` +Z (`mcmf` = `mci`
    /// at `t = 0`). `now_ns`: this cycle's time (for the lost watch).
    pub fn process(&mut self, filter: &mut NavFilter, omega_rad_s: f64, now_ns: i64) {
        let Some(map) = self.cfg.map.clone() else {
            return;
        };
        let Some((t_ns, base)) = self.pending.take() else {
            self.watch(filter, &map, omega_rad_s, now_ns);
            return;
        };
        match self.match_frame(filter, &map, omega_rad_s, t_ns, base) {
            Ok(fix) => {
                self.last_fix = Some(fix);
            }
            Err(why) => self.reject(why),
        }
        self.watch(filter, &map, omega_rad_s, now_ns);
    }

    /// Keeps `expected_since_ns`: the time from which frames have been expected (the
    /// vehicle in the height band over the map).
    fn watch(&mut self, filter: &NavFilter, map: &TerrainMap, omega_rad_s: f64, now_ns: i64) {
        let (r_mci, _) = filter.pose_at(now_ns);
        let r_mcmf =
            Rotation3::from_axis_angle(&Vector3::z_axis(), -omega_rad_s * now_ns as f64 * 1e-9)
                * r_mci;
        let (e, n, h) = map.frame.map_of_mcmf(&r_mcmf);
        let ground = map.height_at(e, n);
        let expected = ground.is_some_and(|g| {
            let above = h - g;
            above <= self.cfg.max_height_m && above >= self.cfg.min_height_m
        });
        if expected {
            self.expected_since_ns.get_or_insert(now_ns);
        } else {
            self.expected_since_ns = None;
        }
    }

    fn match_frame(
        &mut self,
        filter: &mut NavFilter,
        map: &TerrainMap,
        omega_rad_s: f64,
        t_ns: i64,
        base: usize,
    ) -> Result<Fix, Rejection> {
        let cfg = &self.cfg;
        // The camera at the frame's time of validity, Moon-fixed.
        let (r_mci, q) = filter.pose_at(t_ns);
        let mcmf_from_mci =
            Rotation3::from_axis_angle(&Vector3::z_axis(), -omega_rad_s * t_ns as f64 * 1e-9);
        let mcmf_from_body = mcmf_from_mci * q.to_rotation_matrix();
        let cam_mcmf =
            mcmf_from_mci * r_mci + mcmf_from_body * Vector3::from(cfg.camera.position_body_m);
        let cam_from_mcmf = (mcmf_from_body.matrix() * self.body_from_cam).transpose();
        let bore_mcmf = cam_from_mcmf.row(2).transpose();

        // The boresight's ground point: the ray against the sphere at the ground's
        // height (the map's under the vehicle, then under the first hit).
        let (e_v, n_v, h_v) = map.frame.map_of_mcmf(&cam_mcmf);
        let mut ground_m = map.height_at(e_v, n_v).ok_or(Rejection::OutOfReach)?;
        let above_m = h_v - ground_m;
        if !(above_m <= cfg.max_height_m && above_m >= cfg.min_height_m) {
            return Err(Rejection::OutOfReach);
        }
        let mut hit = None;
        for _ in 0..3 {
            let rho = map.frame.radius_m + ground_m;
            let b = cam_mcmf.dot(&bore_mcmf);
            let c = cam_mcmf.norm_squared() - rho * rho;
            let disc = b * b - c;
            if disc < 0.0 || b >= 0.0 {
                return Err(Rejection::OutOfReach);
            }
            let range_m = -b - disc.sqrt();
            let p = cam_mcmf + bore_mcmf * range_m;
            let (e, n, _) = map.frame.map_of_mcmf(&p);
            ground_m = map.height_at(e, n).ok_or(Rejection::OutOfReach)?;
            hit = Some((e, n, range_m));
        }
        let (e_c, n_c, range_m) = hit.ok_or(Rejection::OutOfReach)?;
        // The boresight within 75 deg of the vertical (beyond, the ground is a sliver
        // of the view at grazing incidence).
        let up_c = map.frame.mcmf_of_map(e_c, n_c, 0.0).normalize();
        if up_c.dot(&bore_mcmf) > -0.25 {
            return Err(Rejection::OutOfReach);
        }
        let footprint_m = range_m / self.f_px;

        // The horizontal uncertainty along map east and north (at the site, in mci).
        let mci_from_mcmf = mcmf_from_mci.inverse();
        let [east, north, _] = map.frame.axes_mcmf();
        let axes = [mci_from_mcmf * east, mci_from_mcmf * north];
        let p_rr = filter.covariance().fixed_view::<3, 3>(0, 0).into_owned();
        let sigma_h = axes
            .iter()
            .map(|a| (a.transpose() * p_rr * a)[(0, 0)].max(0.0).sqrt())
            .fold(0.0f64, f64::max);
        // The search: 3 sigma, and the acquisition radius until the first fix.
        let reach_m = if self.acquired {
            3.0 * sigma_h
        } else {
            (3.0 * sigma_h).max(cfg.acquisition_radius_m)
        };

        // The level: fine enough for the footprint, coarse enough for the search.
        let min_cell_m = cfg.cell_per_pixel * footprint_m;
        let max_w = cfg.max_search_cells as f64;
        let level = map
            .levels
            .iter()
            .position(|l| l.spacing_m >= min_cell_m && (reach_m / l.spacing_m).ceil() <= max_w)
            .ok_or(Rejection::OutOfReach)?;
        let lv = &map.levels[level];
        let s = lv.spacing_m;
        let search = ((reach_m / s).ceil() as i64).clamp(
            cfg.min_search_cells as i64,
            cfg.max_search_cells.max(cfg.min_search_cells) as i64,
        );
        let pc = cfg.patch_cells as i64;
        let (cc, rc) = lv.cell_of(e_c, n_c);
        let (c0, r0) = (cc.round() as i64 - pc / 2, rc.round() as i64 - pc / 2);
        if !lv.contains_window(
            c0 - search - 1,
            r0 - search - 1,
            pc + 2 * search + 2,
            pc + 2 * search + 2,
        ) {
            return Err(Rejection::OutOfReach);
        }

        // The patch: each map cell's ground point seen through the camera.
        let mip =
            ((s / footprint_m).log2().floor().max(0.0) as usize).clamp(base, self.mips.len() - 1);
        let scale = (1usize << mip) as f64;
        let full = cfg.camera.full_scale_dn as f32;
        let mut sat = 0usize;
        for i in 0..pc {
            for j in 0..pc {
                let (col, row) = ((c0 + j) as usize, (r0 + i) as usize);
                let e = lv.e0_m + col as f64 * s;
                let n = lv.n0_m + row as f64 * s;
                let h = lv.height_m[row * lv.width as usize + col] as f64;
                let p = map.frame.mcmf_of_map(e, n, h);
                let d = cam_from_mcmf * (p - cam_mcmf);
                let (u, v) = cfg
                    .camera
                    .project(self.f_px, &d)
                    .ok_or(Rejection::OutOfReach)?;
                let m = &self.mips[mip];
                let (x, y) = (u / scale - 0.5, v / scale - 0.5);
                if !(x >= 0.0 && y >= 0.0 && x < (m.w - 1) as f64 && y < (m.h - 1) as f64) {
                    return Err(Rejection::OutOfReach);
                }
                let (xi, yi) = (x as usize, y as usize);
                let (fx, fy) = ((x - xi as f64) as f32, (y - yi as f64) as f32);
                let k = yi * m.w + xi;
                let top = m.px[k] * (1.0 - fx) + m.px[k + 1] * fx;
                let bot = m.px[k + m.w] * (1.0 - fx) + m.px[k + m.w + 1] * fx;
                let value = top * (1.0 - fy) + bot * fy;
                self.patch[(i * pc + j) as usize] = value;
                sat += usize::from(value >= full);
            }
        }
        let n_cells = (pc * pc) as f64;
        if sat as f64 / n_cells > cfg.max_saturated_frac {
            return Err(Rejection::Saturated);
        }
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for &v in &self.patch {
            sum += v as f64;
            sum2 += (v as f64) * (v as f64);
        }
        let mean = sum / n_cells;
        let var = (sum2 / n_cells - mean * mean).max(0.0);
        if !(mean > 0.0 && var.sqrt() / mean >= cfg.min_contrast) {
            return Err(Rejection::NoTexture);
        }
        let sd = var.sqrt();

        // NCC over the search, kept per offset for the second peak and the fit.
        let side = (2 * search + 1) as usize;
        let mut best = (f64::MIN, 0usize);
        for a in 0..side {
            for b in 0..side {
                let (du, dv) = (b as i64 - search, a as i64 - search);
                let v = ncc(&self.patch, mean, sd, lv, c0 + du, r0 + dv, pc);
                self.scores[a * side + b] = v;
                if v > best.0 {
                    best = (v, a * side + b);
                }
            }
        }
        let (peak, at) = best;
        let (ba, bb) = (at / side, at % side);
        if peak.is_nan() || peak < cfg.min_peak_ncc {
            return Err(Rejection::WeakPeak);
        }
        if ba == 0 || bb == 0 || ba == side - 1 || bb == side - 1 {
            return Err(Rejection::Ambiguous);
        }
        let mut second = f64::MIN;
        for a in 0..side {
            for b in 0..side {
                if a.abs_diff(ba) > 2 || b.abs_diff(bb) > 2 {
                    second = second.max(self.scores[a * side + b]);
                }
            }
        }
        let ratio = if self.acquired {
            cfg.max_second_peak_ratio
        } else {
            cfg.acquisition_second_peak_ratio
        };
        if second > ratio * peak {
            return Err(Rejection::Ambiguous);
        }
        let sc = |a: usize, b: usize| self.scores[a * side + b];
        let vertex = |m: f64, z: f64, p: f64| {
            let d = m - 2.0 * z + p;
            if d < 0.0 {
                (0.5 * (m - p) / d).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        };
        let su = bb as f64 - search as f64 + vertex(sc(ba, bb - 1), peak, sc(ba, bb + 1));
        let sv = ba as f64 - search as f64 + vertex(sc(ba - 1, bb), peak, sc(ba + 1, bb));
        // The patch at map x matches the map at x + (su, sv) cells: the estimate is off
        // by that much (true minus estimate).
        let error_en_m = [su * s, sv * s];
        let att_sigma = filter
            .estimate()
            .sigma_att_rad
            .iter()
            .fold(0.0f64, |a, &b| a.max(b));
        let sigma_m = (cfg.fix_sigma_cells * s).hypot(att_sigma * range_m);
        // What the shift measures: moving the camera by `d` moves the ground point a
        // ray meets by `d - b (up . d) / (up . b)` (b the ray, up the local vertical):
        // the horizontal error, plus the height error seen along an oblique boresight.
        let bore_mci = mci_from_mcmf * bore_mcmf;
        let up_mci = mci_from_mcmf * map.frame.mcmf_of_map(e_c, n_c, 0.0).normalize();
        let ub = up_mci.dot(&bore_mci);
        let rows = axes.map(|a| a - up_mci * (a.dot(&bore_mci) / ub));
        if !self.acquired {
            // Acquisition: no filter gate stands behind the first fix, so two frames
            // in a row must agree on it (within two cells of the coarser level; the
            // estimate itself moves little in one frame period), as a false peak on a
            // repeated or featureless pattern does not twice in the same place.
            let agree = self.candidate.is_some_and(|(y0, s0, t0)| {
                t_ns - t0 <= 3_000_000_000
                    && (y0[0] - error_en_m[0]).hypot(y0[1] - error_en_m[1]) <= 2.0 * s0.max(s)
            });
            self.candidate = Some((error_en_m, s, t_ns));
            if !agree {
                return Err(Rejection::Unconfirmed);
            }
            // Acquisition: the filter is told its horizontal position is as uncertain
            // as this first fix says it was (at least the fix's size on each axis).
            for (a, y) in axes.iter().zip(error_en_m) {
                filter.widen_position(a, y.abs().max(sigma_m));
            }
        }
        let (used, nis) = filter.update_position_fix(rows, error_en_m, sigma_m);
        let fix = Fix {
            t_ns,
            error_en_m,
            sigma_m,
            ncc: peak,
            level,
            nis,
        };
        if used {
            if !self.acquired {
                // From here the horizontal position is known to metres: the altimeters
                // may take their ground from the map (before, a map height looked up
                // hundreds of metres from the true spot would pull the estimate
                // sideways through an oblique beam).
                filter.set_ground_map(self.cfg.map.clone());
            }
            self.acquired = true;
            self.candidate = None;
            self.accepted += 1;
            self.last_accepted_ns = Some(t_ns);
            Ok(fix)
        } else {
            self.last_fix = Some(fix);
            Err(Rejection::Gated)
        }
    }
}

/// NCC of `patch` (its mean and standard deviation given) against the map cells of
/// window `[c0, c0 + n) x [r0, r0 + n)` of `lv`.
#[inline]
fn ncc(patch: &[f32], mean: f64, sd: f64, lv: &MapLevel, c0: i64, r0: i64, n: i64) -> f64 {
    let w = lv.width as usize;
    let (mut sm, mut smm, mut spm) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..n as usize {
        let row = &lv.iof[(r0 as usize + i) * w + c0 as usize..][..n as usize];
        let prow = &patch[i * n as usize..][..n as usize];
        let (mut a, mut b, mut c) = (0.0f32, 0.0f32, 0.0f32);
        for (&m, &p) in row.iter().zip(prow) {
            a += m;
            b += m * m;
            c += p * m;
        }
        sm += a as f64;
        smm += b as f64;
        spm += c as f64;
    }
    let k = (n * n) as f64;
    let mm = sm / k;
    let var_m = (smm / k - mm * mm).max(0.0);
    if var_m <= 0.0 || sd <= 0.0 {
        return 0.0;
    }
    (spm / k - mean * mm) / (sd * var_m.sqrt())
}

#[cfg(test)]
mod tests {
    //! The matcher against frames synthesised from the map's own texture through an
    //! undistorted pinhole: the geometry closes on itself, so the estimate's offset must
    //! come back to a fraction of a cell.
    use super::*;
    use crate::gnc::nav_filter::NavFilterConfig;
    use crate::gnc::terrain_map::{MapFrame, MapLevel, TerrainMap};
    use nalgebra::{Matrix3, UnitQuaternion};
    use oils_shared::Telemetry;

    const R_M: f64 = 1_737_400.0;
    const H_M: f64 = 300.0;

    /// A random texture (value noise: hashed values on a 10 m lattice, bilinear), or one
    /// period `p` in both axes.
    fn texture(e: f64, n: f64, periodic: Option<f64>) -> f64 {
        if let Some(p) = periodic {
            let k = std::f64::consts::TAU / p;
            return (k * e).sin() * (k * n).cos();
        }
        let hash = |i: i64, j: i64| {
            let mut x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
            x ^= x >> 29;
            x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x ^= x >> 32;
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let (x, y) = (e / 10.0, n / 10.0);
        let (i, j) = (x.floor(), y.floor());
        let (fx, fy) = (x - i, y - j);
        let (i, j) = (i as i64, j as i64);
        let top = hash(i, j) * (1.0 - fx) + hash(i + 1, j) * fx;
        let bot = hash(i, j + 1) * (1.0 - fx) + hash(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bot * fy
    }

    fn map(periodic: Option<f64>, shift_e_m: f64) -> TerrainMap {
        let frame = MapFrame::new(-69.373, 32.319, R_M);
        let levels = [4.0, 8.0]
            .iter()
            .map(|&s| {
                let n = 256u32;
                let half = 0.5 * (n as f64 - 1.0) * s;
                let mut iof = Vec::new();
                for i in 0..n {
                    for j in 0..n {
                        let (e, nn) = (-half + j as f64 * s, -half + i as f64 * s);
                        iof.push((0.1 + 0.04 * texture(e - shift_e_m, nn, periodic)) as f32);
                    }
                }
                MapLevel {
                    spacing_m: s,
                    e0_m: -half,
                    n0_m: -half,
                    width: n,
                    height: n,
                    iof,
                    height_m: vec![0.0; (n * n) as usize],
                }
            })
            .collect();
        TerrainMap {
            frame,
            sun_azimuth_deg: 90.0,
            sun_elevation_deg: 30.0,
            camera: camera(),
            levels,
        }
    }

    fn camera() -> CameraModel {
        CameraModel {
            width_px: 128,
            height_px: 128,
            k1: 0.0,
            k2: 0.0,
            ..CameraModel::default()
        }
    }

    /// Body axes east, north, up at the site (the boresight, body -Z, straight down).
    fn attitude(f: &MapFrame) -> UnitQuaternion<f64> {
        let [e, n, u] = f.axes_mcmf();
        UnitQuaternion::from_matrix(&Matrix3::from_columns(&[e, n, u]))
    }

    /// The frame the camera sees from `H_M` above the site, the true pose.
    fn frame(m: &TerrainMap, periodic: Option<f64>) -> (FrameAnnouncement, Vec<u8>) {
        let cam = camera();
        let f = &m.frame;
        let q = attitude(f);
        let r = f.mcmf_of_map(0.0, 0.0, H_M);
        let c = r + q * Vector3::from(cam.position_body_m);
        let mcmf_from_cam = q.to_rotation_matrix().matrix() * cam.body_from_camera();
        let fpx = cam.f_px();
        let mut px = Vec::new();
        for v in 0..cam.height_px {
            for u in 0..cam.width_px {
                let d = Vector3::new(
                    (u as f64 + 0.5 - 64.0) / fpx,
                    (v as f64 + 0.5 - 64.0) / fpx,
                    1.0,
                );
                let d = (mcmf_from_cam * d).normalize();
                // The ray against the sphere of the map's (zero) heights.
                let b = c.dot(&d);
                let t = -b - (b * b - c.norm_squared() + R_M * R_M).sqrt();
                let (e, n, _) = f.map_of_mcmf(&(c + d * t));
                let dn = (1000.0 + 400.0 * texture(e, n, periodic)).round() as u16;
                px.extend_from_slice(&dn.to_le_bytes());
            }
        }
        let ann = FrameAnnouncement {
            device: FRAME_DEVICE_CAMERA,
            format: FRAME_FORMAT_U16_LE,
            width: cam.width_px,
            height: cam.height_px,
            t_ns: 0,
            bytes: px.len() as u32,
            ..Default::default()
        };
        (ann, px)
    }

    /// A filter whose estimate is `offset` (east, north, m) from the true pose.
    fn filter(m: &TerrainMap, offset: [f64; 2], sigma_m: f64) -> NavFilter {
        let f = &m.frame;
        let [e, n, _] = f.axes_mcmf();
        let q = attitude(f);
        let mut tlm = Telemetry::default();
        let r = f.mcmf_of_map(0.0, 0.0, H_M) + e * offset[0] + n * offset[1];
        tlm.nav.pos_mci_m = r.into();
        tlm.nav.q_mci_from_body = [q.w, q.i, q.j, q.k];
        let mut nf = NavFilter::new(NavFilterConfig {
            init_sigma_pos_m: sigma_m,
            ..NavFilterConfig::default()
        });
        nf.step(&tlm);
        nf
    }

    fn nav(m: TerrainMap) -> TerrainNav {
        TerrainNav::new(TerrainNavConfig {
            camera: camera(),
            map: Some(Arc::new(m)),
            // The search of these tests is the filter's 3 sigma (the map's levels are
            // 4 and 8 m: no room for the 1.5 km acquisition search).
            acquisition_radius_m: 0.0,
            ..TerrainNavConfig::default()
        })
    }

    #[test]
    fn an_offset_estimate_comes_back_to_a_fraction_of_a_cell() {
        let m = map(None, 0.0);
        let (ann, px) = frame(&m, None);
        let mut nf = filter(&m, [12.0, -7.0], 30.0);
        let mut tn = nav(m.clone());
        // The first fix waits for a second frame to confirm it (acquisition).
        tn.frame(&ann, &px);
        tn.process(&mut nf, 0.0, 0);
        assert_eq!(tn.rejected()[Rejection::Unconfirmed as usize], 1);
        tn.frame(&ann, &px);
        tn.process(&mut nf, 0.0, 0);
        assert_eq!(tn.accepted(), 1, "rejected: {:?}", tn.rejected());
        let fix = tn.last_fix().unwrap();
        // True minus estimate: (-12, +7) m, on the 4 m level.
        assert_eq!(fix.level, 0);
        assert!(
            (fix.error_en_m[0] + 12.0).abs() < 0.5 && (fix.error_en_m[1] - 7.0).abs() < 0.5,
            "{fix:?}"
        );
        let (r, _) = nf.pose_at(0);
        let (e, n, _) = m.frame.map_of_mcmf(&r);
        assert!(e.hypot(n) < 1.0, "estimate still {e:.2}, {n:.2} m off");
    }

    #[test]
    fn a_repeated_pattern_a_blank_frame_and_a_shifted_map_give_no_fix() {
        // A 16 m period in both axes: peaks every 16 m within the search.
        let m = map(Some(16.0), 0.0);
        let (ann, px) = frame(&m, Some(16.0));
        let mut nf = filter(&m, [12.0, -7.0], 30.0);
        let mut tn = nav(m);
        tn.frame(&ann, &px);
        tn.process(&mut nf, 0.0, 0);
        assert_eq!(
            tn.rejected()[Rejection::Ambiguous as usize],
            1,
            "{:?}",
            tn.rejected()
        );

        // A blank frame.
        let m = map(None, 0.0);
        let (ann, _) = frame(&m, None);
        let blank = vec![0x08u8; ann.bytes as usize];
        let mut nf = filter(&m, [12.0, -7.0], 30.0);
        let mut tn = nav(m.clone());
        tn.frame(&ann, &blank);
        tn.process(&mut nf, 0.0, 0);
        assert_eq!(
            tn.rejected()[Rejection::NoTexture as usize],
            1,
            "{:?}",
            tn.rejected()
        );

        // Acquired on the right map, confident to 2 m; then a map whose ground is drawn
        // 20 m east of where it is (5 cells, inside the 6-cell search): the matcher finds
        // the 20 m shift, the filter's gate refuses it.
        let (ann, px) = frame(&m, None);
        let mut nf = filter(&m, [0.5, 0.5], 2.0);
        let mut tn = nav(m.clone());
        for _ in 0..2 {
            tn.frame(&ann, &px);
            tn.process(&mut nf, 0.0, 0);
        }
        assert_eq!(tn.accepted(), 1, "{:?}", tn.rejected());
        tn.cfg.map = Some(Arc::new(map(None, 20.0)));
        tn.frame(&ann, &px);
        tn.process(&mut nf, 0.0, 0);
        assert_eq!(tn.accepted(), 1);
        assert_eq!(
            tn.rejected()[Rejection::Gated as usize],
            1,
            "{:?}",
            tn.rejected()
        );
        let fix = tn.last_fix().unwrap();
        assert!(
            fix.nis > 13.8 && (fix.error_en_m[0] - 20.0).abs() < 1.0,
            "{fix:?}"
        );
    }
}
