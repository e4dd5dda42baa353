//! The IMU: delta-theta and delta-v increments integrated from the truth over each
//! period, with the error model of `docs/sensors.md`.

use super::config::{ms_to_ns, ImuConfig};
use super::{
    device_rng, due, gauss, quat, DeviceFault, FaultState, Queue, SensorTarget, SensorTruth,
};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use oils_shared::{ImuSample, IMU_SAMPLES_MAX, SAMPLE_FLAG_INHIBITED, SAMPLE_FLAG_SATURATED};
use rand_chacha::ChaCha8Rng;

/// Standard gravity, m/s^2 (micro-g and g in the configuration).
const G0_M_S2: f64 = 9.80665;
/// Peak Allan deviation of a first-order Gauss-Markov process over its stationary
/// sigma: `max_x sqrt((2x - 3 + 4e^-x - e^-2x) / x^2)` = 0.61736 at `x = tau / T` =
/// 1.893.
pub const GM_ADEV_PEAK_OVER_SIGMA: f64 = 0.617_364;
/// Allan deviation floor of flicker (bias-instability) noise over the bias
/// instability `B`: `sqrt(2 ln 2 / pi)` (IEEE Std 952).
pub const FLICKER_FLOOR_OVER_B: f64 = 0.664_282;

/// One triad (gyros or accelerometers), SI: rad and rad/s, or m/s and m/s^2.
#[derive(Debug, Clone)]
struct Triad {
    /// `(I + misalignment) (I + diag(scale factor))`.
    gain: Matrix3<f64>,
    /// Constant bias (fixed plus turn-on draw), per second.
    bias: Vector3<f64>,
    /// Gauss-Markov bias state.
    gm: Vector3<f64>,
    /// GM: `exp(-T / tau)` and the drive `sigma sqrt(1 - phi^2)`.
    gm_phi: f64,
    gm_drive: f64,
    /// White noise of one increment: random walk times sqrt(T).
    white: f64,
    quantum: f64,
    residual: Vector3<f64>,
    /// Largest increment per axis (range times T).
    limit: f64,
}

/// The numbers of one triad, SI.
struct TriadSpec {
    bias_fixed: [f64; 3],
    bias_sigma: f64,
    instability: f64,
    correlation_s: f64,
    random_walk: f64,
    sf_fixed_ppm: [f64; 3],
    sf_sigma_ppm: f64,
    mis_sigma_rad: f64,
    quantum: f64,
    range: f64,
}

impl Triad {
    /// Draws the turn-on errors (in a fixed order: bias, scale factor, misalignment, GM
    /// start; 15 draws).
    fn new(s: &TriadSpec, period_s: f64, rng: &mut ChaCha8Rng) -> Self {
        let bias = Vector3::from_fn(|i, _| s.bias_fixed[i] + s.bias_sigma * gauss(rng));
        let sf = Vector3::from_fn(|i, _| (s.sf_fixed_ppm[i] + s.sf_sigma_ppm * gauss(rng)) * 1e-6);
        let mut mis = Matrix3::identity();
        for (r, c) in [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)] {
            mis[(r, c)] = s.mis_sigma_rad * gauss(rng);
        }
        let gm_sigma = s.instability * FLICKER_FLOOR_OVER_B / GM_ADEV_PEAK_OVER_SIGMA;
        let gm = Vector3::from_fn(|_, _| gm_sigma * gauss(rng));
        let gm_phi = (-period_s / s.correlation_s).exp();
        Self {
            gain: mis * Matrix3::from_diagonal(&(Vector3::repeat(1.0) + sf)),
            bias,
            gm,
            gm_phi,
            gm_drive: gm_sigma * (1.0 - gm_phi * gm_phi).max(0.0).sqrt(),
            white: s.random_walk * period_s.sqrt(),
            quantum: s.quantum,
            residual: Vector3::zeros(),
            limit: s.range * period_s,
        }
    }

    /// The measured increment of a true one over a period of `period_s`; six draws
    /// (white, then GM) whatever the faults. Returns it and whether an axis saturated.
    fn measure(
        &mut self,
        truth: &Vector3<f64>,
        period_s: f64,
        fault: &mut FaultState,
        rng: &mut ChaCha8Rng,
    ) -> (Vector3<f64>, bool) {
        let white = Vector3::from_fn(|_, _| gauss(rng));
        let drive = Vector3::from_fn(|_, _| gauss(rng));
        self.gm = self.gm * self.gm_phi + drive * self.gm_drive;
        let extra = fault.bias + fault.take_spike();
        let mut m = self.gain * truth
            + (self.bias + self.gm + Vector3::repeat(extra)) * period_s
            + white * (self.white * fault.noise);
        let mut saturated = false;
        for x in m.iter_mut() {
            if x.abs() > self.limit {
                *x = x.signum() * self.limit;
                saturated = true;
            }
        }
        if self.quantum > 0.0 {
            // Quantise what has accumulated, carrying the residual: the sum of the
            // outputs never strays from the sum of the inputs by more than a quantum.
            let total = m + self.residual;
            m = total.map(|x| (x / self.quantum).round() * self.quantum);
            self.residual = total - m;
        }
        (m, saturated)
    }
}

/// The IMU (its axes are the body axes; it sits at the centre of mass).
#[derive(Debug, Clone)]
pub(crate) struct Imu {
    period_ns: i64,
    latency_ns: i64,
    period_s: f64,
    gyro: Triad,
    accel: Triad,
    gyro_faults: FaultState,
    accel_faults: FaultState,
    /// True increments accumulated in the current period: delta-theta (body), delta-v
    /// (body axes at the period's start).
    dtheta: Vector3<f64>,
    dv: Vector3<f64>,
    /// Attitude at the period's start (`None` before the first step).
    q_ref: Option<UnitQuaternion<f64>>,
    /// Last output, held by a frozen fault.
    last: ([f64; 3], [f64; 3]),
    frozen_gyro: Option<[f64; 3]>,
    frozen_accel: Option<[f64; 3]>,
    rng: ChaCha8Rng,
    pub queue: Queue<ImuSample>,
}

impl Imu {
    pub fn new(c: &ImuConfig, seed: u64) -> Self {
        let period_ns = ms_to_ns(c.period_ms).max(1);
        let latency_ns = ms_to_ns(c.latency_ms);
        let period_s = period_ns as f64 * 1e-9;
        let mut rng = device_rng(seed, "imu");
        let deg_h = std::f64::consts::PI / 180.0 / 3600.0;
        let ug = 1e-6 * G0_M_S2;
        let gyro = Triad::new(
            &TriadSpec {
                bias_fixed: c.gyro_bias_deg_h.map(|b| b * deg_h),
                bias_sigma: c.gyro_bias_sigma_deg_h * deg_h,
                instability: c.gyro_bias_instability_deg_h * deg_h,
                correlation_s: c.gyro_bias_correlation_s,
                // deg/sqrt(h) -> rad/sqrt(s).
                random_walk: c.gyro_arw_deg_rt_h.to_radians() / 60.0,
                sf_fixed_ppm: c.gyro_scale_factor_ppm,
                sf_sigma_ppm: c.gyro_scale_factor_sigma_ppm,
                mis_sigma_rad: c.gyro_misalignment_sigma_mrad * 1e-3,
                quantum: c.gyro_quantum_rad,
                range: c.gyro_range_deg_s.to_radians(),
            },
            period_s,
            &mut rng,
        );
        let accel = Triad::new(
            &TriadSpec {
                bias_fixed: c.accel_bias_ug.map(|b| b * ug),
                bias_sigma: c.accel_bias_sigma_ug * ug,
                instability: c.accel_bias_instability_ug * ug,
                correlation_s: c.accel_bias_correlation_s,
                // ug/sqrt(Hz) -> m/s/sqrt(s).
                random_walk: c.accel_vrw_ug_rt_hz * ug,
                sf_fixed_ppm: c.accel_scale_factor_ppm,
                sf_sigma_ppm: c.accel_scale_factor_sigma_ppm,
                mis_sigma_rad: c.accel_misalignment_sigma_mrad * 1e-3,
                quantum: c.accel_quantum_m_s,
                range: c.accel_range_g * G0_M_S2,
            },
            period_s,
            &mut rng,
        );
        Self {
            period_ns,
            latency_ns,
            period_s,
            gyro,
            accel,
            gyro_faults: FaultState::default(),
            accel_faults: FaultState::default(),
            dtheta: Vector3::zeros(),
            dv: Vector3::zeros(),
            q_ref: None,
            last: ([0.0; 3], [0.0; 3]),
            frozen_gyro: None,
            frozen_accel: None,
            rng,
            queue: Queue::new(period_ns, latency_ns, IMU_SAMPLES_MAX),
        }
    }

    pub fn set_fault(&mut self, target: SensorTarget, fault: DeviceFault, active: bool) {
        if matches!(target, SensorTarget::Imu | SensorTarget::ImuGyro) {
            self.gyro_faults.set(fault, active);
        }
        if matches!(target, SensorTarget::Imu | SensorTarget::ImuAccel) {
            self.accel_faults.set(fault, active);
        }
    }

    /// Accumulates one plant step; at a period's end, measures and queues a sample.
    pub fn step(&mut self, t: &SensorTruth<'_>) {
        let q0 = quat(&t.q_start_mci_from_body);
        let q1 = quat(&t.q_mci_from_body);
        let q_ref = *self.q_ref.get_or_insert(q0);
        // The step's rotation vector (body axes): its sum over a period is the
        // integral of the body rate to second order in the step.
        let dtheta = (q0.inverse() * q1).scaled_axis();
        // Mean specific force (mid-step body axes) into the period's start axes.
        let mid_from_ref = q_ref.inverse() * q0 * UnitQuaternion::from_scaled_axis(dtheta * 0.5);
        self.dtheta += dtheta;
        self.dv +=
            mid_from_ref * Vector3::from(t.specific_force_body_m_s2) * (t.dt_ns as f64 * 1e-9);
        let Some(tv) = due(t.t_ns, t.dt_ns, self.period_ns) else {
            return;
        };
        let (dtheta, dv) = (self.dtheta, self.dv);
        self.dtheta = Vector3::zeros();
        self.dv = Vector3::zeros();
        self.q_ref = Some(q1);

        let (g, g_sat) =
            self.gyro
                .measure(&dtheta, self.period_s, &mut self.gyro_faults, &mut self.rng);
        let (a, a_sat) =
            self.accel
                .measure(&dv, self.period_s, &mut self.accel_faults, &mut self.rng);
        let (gf, af) = (&self.gyro_faults, &self.accel_faults);
        if gf.dropout > 0 || af.dropout > 0 {
            return;
        }
        let mut s = ImuSample {
            t_ns: tv,
            valid: 1,
            ..Default::default()
        };
        if gf.inhibited > 0 || af.inhibited > 0 {
            s.valid = 0;
            s.flags = SAMPLE_FLAG_INHIBITED;
        } else {
            if g_sat || a_sat {
                s.flags |= SAMPLE_FLAG_SATURATED;
            }
            let last = self.last;
            s.delta_theta_body_rad = if gf.frozen > 0 {
                *self.frozen_gyro.get_or_insert(last.0)
            } else {
                self.frozen_gyro = None;
                g.into()
            };
            s.delta_v_body_m_s = if af.frozen > 0 {
                *self.frozen_accel.get_or_insert(last.1)
            } else {
                self.frozen_accel = None;
                a.into()
            };
            self.last = (s.delta_theta_body_rad, s.delta_v_body_m_s);
        }
        self.queue.push(tv + self.latency_ns, s);
    }
}
