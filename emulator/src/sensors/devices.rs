//! The star tracker, the altimeters (laser: one ray; RF: a cone of rays) and the laser
//! Doppler velocimeter: each a snapshot of the truth at its time of validity.

use super::config::{
    ms_to_ns, LaserAltimeterConfig, RfAltimeterConfig, StarTrackerConfig, VelocimeterConfig,
};
use super::{device_rng, due, gauss, FaultState, Queue, SensorTruth};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use oils_shared::{
    AltimeterSample, StarTrackerSample, VelocimeterSample, ALTIMETER_SAMPLES_MAX,
    SAMPLE_FLAG_INHIBITED, SAMPLE_FLAG_NO_LOCK, SAMPLE_FLAG_OUTAGE, STAR_TRACKER_SAMPLES_MAX,
    VELOCIMETER_BEAMS, VELOCIMETER_SAMPLES_MAX,
};
use rand_chacha::ChaCha8Rng;

const ARCSEC_RAD: f64 = std::f64::consts::PI / (180.0 * 3600.0);
/// Most rays of the RF altimeter's cone: the centre plus a ring of 16.
const MAX_RAYS: usize = 17;

/// A unit vector and two more completing a right-handed orthonormal set `(x, y, axis)`.
fn frame_about(axis: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let z = axis.normalize();
    // The body axis least aligned with z seeds the perpendicular.
    let seed = if z.x.abs() <= z.y.abs() && z.x.abs() <= z.z.abs() {
        Vector3::x()
    } else if z.y.abs() <= z.z.abs() {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let x = seed.cross(&z).normalize();
    let y = z.cross(&x);
    (x, y, z)
}

/// Star tracker.
#[derive(Debug, Clone)]
pub(crate) struct StarTracker {
    period_ns: i64,
    latency_ns: i64,
    /// Tracker axes (x, y cross-boresight; z boresight) as columns, body axes.
    body_from_tracker: Matrix3<f64>,
    sigma_rad: [f64; 3],
    /// Outage windows `[start, end)`, ns.
    outages: Vec<(i64, i64)>,
    last: [f64; 4],
    frozen: Option<[f64; 4]>,
    pub faults: FaultState,
    rng: ChaCha8Rng,
    pub queue: Queue<StarTrackerSample>,
}

impl StarTracker {
    pub fn new(c: &StarTrackerConfig, seed: u64) -> Self {
        let period_ns = ms_to_ns(c.period_ms).max(1);
        let latency_ns = ms_to_ns(c.latency_ms);
        let (x, y, z) = frame_about(&Vector3::from(c.boresight_body));
        Self {
            period_ns,
            latency_ns,
            body_from_tracker: Matrix3::from_columns(&[x, y, z]),
            sigma_rad: [
                c.cross_boresight_arcsec * ARCSEC_RAD,
                c.cross_boresight_arcsec * ARCSEC_RAD,
                c.about_boresight_arcsec * ARCSEC_RAD,
            ],
            outages: c
                .outage_start_s
                .iter()
                .zip(&c.outage_duration_s)
                .map(|(&a, &d)| ((a * 1e9).round() as i64, ((a + d) * 1e9).round() as i64))
                .collect(),
            last: [1.0, 0.0, 0.0, 0.0],
            frozen: None,
            faults: FaultState::default(),
            rng: device_rng(seed, "star-tracker"),
            queue: Queue::new(period_ns, latency_ns, STAR_TRACKER_SAMPLES_MAX),
        }
    }

    pub fn step(&mut self, t: &SensorTruth<'_>) {
        let Some(tv) = due(t.t_ns, t.dt_ns, self.period_ns) else {
            return;
        };
        let n = [0; 3].map(|_| gauss(&mut self.rng));
        let f = &mut self.faults;
        if f.dropout > 0 {
            return;
        }
        let mut s = StarTrackerSample {
            t_ns: tv,
            valid: 1,
            ..Default::default()
        };
        if f.inhibited > 0 {
            s.valid = 0;
            s.flags = SAMPLE_FLAG_INHIBITED;
        } else if self.outages.iter().any(|&(a, b)| tv >= a && tv < b) {
            s.valid = 0;
            s.flags = SAMPLE_FLAG_OUTAGE;
        } else if f.frozen > 0 {
            s.q_mci_from_body = *self.frozen.get_or_insert(self.last);
        } else {
            self.frozen = None;
            let extra = (f.bias + f.take_spike()) * ARCSEC_RAD;
            let err_tracker = Vector3::new(
                self.sigma_rad[0] * f.noise * n[0] + extra,
                self.sigma_rad[1] * f.noise * n[1],
                self.sigma_rad[2] * f.noise * n[2],
            );
            let err_body = self.body_from_tracker * err_tracker;
            let q = t.q_end() * UnitQuaternion::from_scaled_axis(err_body);
            let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
            s.q_mci_from_body = [q.w, q.i, q.j, q.k].map(|c| c * sign);
            self.last = s.q_mci_from_body;
        }
        self.queue.push(tv + self.latency_ns, s);
    }
}

/// Range noise: one sigma `constant + fraction x range`.
#[derive(Debug, Clone, Copy)]
struct RangeNoise {
    frac: f64,
    m: f64,
}

impl RangeNoise {
    fn sigma(&self, range_m: f64) -> f64 {
        self.m + self.frac * range_m
    }
}

/// Return limits of a beam.
#[derive(Debug, Clone, Copy)]
struct Limits {
    min_range_m: f64,
    max_range_m: f64,
    max_incidence_deg: f64,
}

/// A laser altimeter (one ray) or an RF altimeter (a centre ray and a ring).
#[derive(Debug, Clone)]
pub(crate) struct Altimeter {
    name: &'static str,
    period_ns: i64,
    latency_ns: i64,
    lever_body: Vector3<f64>,
    rays_body: [Vector3<f64>; MAX_RAYS],
    ray_count: usize,
    noise: RangeNoise,
    limits: Limits,
    last: AltimeterSample,
    frozen: Option<AltimeterSample>,
    pub faults: FaultState,
    rng: ChaCha8Rng,
    pub queue: Queue<AltimeterSample>,
}

impl Altimeter {
    #[allow(clippy::too_many_arguments)]
    fn build(
        name: &'static str,
        period_ms: f64,
        latency_ms: f64,
        beam: &[f64; 3],
        lever: &[f64; 3],
        half_cone_deg: f64,
        ring: usize,
        noise: RangeNoise,
        limits: Limits,
        seed: u64,
    ) -> Self {
        let period_ns = ms_to_ns(period_ms).max(1);
        let latency_ns = ms_to_ns(latency_ms);
        let (x, y, z) = frame_about(&Vector3::from(*beam));
        let mut rays_body = [z; MAX_RAYS];
        let (sh, ch) = half_cone_deg.to_radians().sin_cos();
        for (k, ray) in rays_body.iter_mut().skip(1).take(ring).enumerate() {
            let phi = std::f64::consts::TAU * k as f64 / ring as f64;
            *ray = z * ch + (x * phi.cos() + y * phi.sin()) * sh;
        }
        Self {
            name,
            period_ns,
            latency_ns,
            lever_body: Vector3::from(*lever),
            rays_body,
            ray_count: 1 + ring,
            noise,
            limits,
            last: AltimeterSample::default(),
            frozen: None,
            faults: FaultState::default(),
            rng: device_rng(seed, name),
            queue: Queue::new(period_ns, latency_ns, ALTIMETER_SAMPLES_MAX),
        }
    }

    pub fn laser(c: &LaserAltimeterConfig, seed: u64) -> Self {
        Self::build(
            "laser-altimeter",
            c.period_ms,
            c.latency_ms,
            &c.beam_body,
            &c.position_body_m,
            0.0,
            0,
            RangeNoise {
                frac: c.noise_frac,
                m: c.noise_m,
            },
            Limits {
                min_range_m: c.min_range_m,
                max_range_m: c.max_range_m,
                max_incidence_deg: c.max_incidence_deg,
            },
            seed,
        )
    }

    pub fn rf(c: &RfAltimeterConfig, seed: u64) -> Self {
        Self::build(
            "rf-altimeter",
            c.period_ms,
            c.latency_ms,
            &c.beam_body,
            &c.position_body_m,
            c.half_cone_deg,
            c.ring_rays as usize,
            RangeNoise {
                frac: c.noise_frac,
                m: c.noise_m,
            },
            Limits {
                min_range_m: c.min_range_m,
                max_range_m: c.max_range_m,
                max_incidence_deg: c.max_incidence_deg,
            },
            seed,
        )
    }

    /// The device's name.
    #[allow(dead_code)]
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// True slant range: the nearest return among the rays, if any. Each ray after a
    /// return is cast only as far as the best so far (it can only win if shorter).
    fn true_range(&self, t: &SensorTruth<'_>) -> Option<f64> {
        let lim = &self.limits;
        let mut best: Option<f64> = None;
        for ray in &self.rays_body[..self.ray_count] {
            let reach = best.unwrap_or(lim.max_range_m);
            if let Some(h) = t.cast(&self.lever_body, ray, reach) {
                if h.range_m >= lim.min_range_m
                    && h.incidence_deg <= lim.max_incidence_deg
                    && best.is_none_or(|b| h.range_m < b)
                {
                    best = Some(h.range_m);
                }
            }
        }
        best
    }

    pub fn step(&mut self, t: &SensorTruth<'_>) {
        let Some(tv) = due(t.t_ns, t.dt_ns, self.period_ns) else {
            return;
        };
        let n = gauss(&mut self.rng);
        if self.faults.dropout > 0 {
            return;
        }
        let mut s = AltimeterSample {
            t_ns: tv,
            ..Default::default()
        };
        if self.faults.inhibited > 0 {
            s.flags = SAMPLE_FLAG_INHIBITED;
        } else if self.faults.frozen > 0 {
            let held = *self.frozen.get_or_insert(self.last);
            s.range_m = held.range_m;
            s.valid = held.valid;
            s.flags = held.flags;
        } else {
            self.frozen = None;
            match self.true_range(t) {
                Some(r) => {
                    let f = &mut self.faults;
                    let extra = f.bias + f.take_spike();
                    s.range_m = (r + self.noise.sigma(r) * f.noise * n + extra).max(0.0);
                    s.valid = 1;
                }
                None => s.flags = SAMPLE_FLAG_NO_LOCK,
            }
            self.last = s;
        }
        self.queue.push(tv + self.latency_ns, s);
    }
}

/// Laser Doppler velocimeter.
#[derive(Debug, Clone)]
pub(crate) struct Velocimeter {
    period_ns: i64,
    latency_ns: i64,
    lever_body: Vector3<f64>,
    beams_body: [Vector3<f64>; VELOCIMETER_BEAMS],
    velocity_sigma: f64,
    range_noise: RangeNoise,
    limits: Limits,
    last: VelocimeterSample,
    frozen: Option<VelocimeterSample>,
    pub faults: FaultState,
    rng: ChaCha8Rng,
    pub queue: Queue<VelocimeterSample>,
}

impl Velocimeter {
    pub fn new(c: &VelocimeterConfig, seed: u64) -> Self {
        let period_ns = ms_to_ns(c.period_ms).max(1);
        let latency_ns = ms_to_ns(c.latency_ms);
        Self {
            period_ns,
            latency_ns,
            lever_body: Vector3::from(c.position_body_m),
            beams_body: c.beams_body.map(|b| Vector3::from(b).normalize()),
            velocity_sigma: c.velocity_noise_m_s,
            range_noise: RangeNoise {
                frac: c.range_noise_frac,
                m: c.range_noise_m,
            },
            limits: Limits {
                min_range_m: c.min_range_m,
                max_range_m: c.max_range_m,
                max_incidence_deg: c.max_incidence_deg,
            },
            last: VelocimeterSample::default(),
            frozen: None,
            faults: FaultState::default(),
            rng: device_rng(seed, "velocimeter"),
            queue: Queue::new(period_ns, latency_ns, VELOCIMETER_SAMPLES_MAX),
        }
    }

    pub fn step(&mut self, t: &SensorTruth<'_>) {
        let Some(tv) = due(t.t_ns, t.dt_ns, self.period_ns) else {
            return;
        };
        let nv = [0; VELOCIMETER_BEAMS].map(|_| gauss(&mut self.rng));
        let nr = [0; VELOCIMETER_BEAMS].map(|_| gauss(&mut self.rng));
        if self.faults.dropout > 0 {
            return;
        }
        let mut s = VelocimeterSample {
            t_ns: tv,
            ..Default::default()
        };
        if self.faults.inhibited > 0 {
            s.flags = SAMPLE_FLAG_INHIBITED;
        } else if self.faults.frozen > 0 {
            let held = *self.frozen.get_or_insert(self.last);
            s = VelocimeterSample { t_ns: tv, ..held };
        } else {
            self.frozen = None;
            let q = t.q_end();
            let lever_mci = q * self.lever_body;
            let origin_mci = Vector3::from(t.pos_mci_m) + lever_mci;
            // Velocity of the optical head relative to the turning ground, mci.
            let omega_moon = Vector3::new(0.0, 0.0, t.moon_rotation_rate_rad_s);
            let v_head = Vector3::from(t.vel_mci_m_s)
                + q * Vector3::from(t.rate_body_rad_s).cross(&self.lever_body);
            let v_rel = v_head - omega_moon.cross(&origin_mci);
            let f = &mut self.faults;
            let extra = f.bias + f.take_spike();
            let lim = &self.limits;
            for (b, beam) in self.beams_body.iter().enumerate() {
                let hit = t.cast(&self.lever_body, beam, lim.max_range_m).filter(|h| {
                    h.range_m >= lim.min_range_m && h.incidence_deg <= lim.max_incidence_deg
                });
                match hit {
                    Some(h) => {
                        let los = v_rel.dot(&(q * beam));
                        s.los_velocity_m_s[b] = los + self.velocity_sigma * f.noise * nv[b] + extra;
                        s.range_m[b] = (h.range_m
                            + self.range_noise.sigma(h.range_m) * f.noise * nr[b])
                            .max(0.0);
                        s.valid[b] = 1;
                    }
                    None => s.flags |= SAMPLE_FLAG_NO_LOCK,
                }
            }
            self.last = s;
        }
        self.queue.push(tv + self.latency_ns, s);
    }
}
