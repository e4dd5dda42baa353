//! The `[sensors]` table of the scenario: one sub-table per device. Every default is in
//! the table of `docs/sensors.md`, marked sourced or assumed.

use crate::config::{check, within, ConfigError};
use oils_shared::{
    ALTIMETER_SAMPLES_MAX, IMU_SAMPLES_MAX, STAR_TRACKER_SAMPLES_MAX, VELOCIMETER_SAMPLES_MAX,
};
use serde::{Deserialize, Deserializer, Serialize};

use crate::fixed_len::fixed_len;

fixed_len! {
    gyro_bias: [f64; 3] => "sensors.imu.gyro_bias_deg_h",
    gyro_sf: [f64; 3] => "sensors.imu.gyro_scale_factor_ppm",
    accel_bias: [f64; 3] => "sensors.imu.accel_bias_ug",
    accel_sf: [f64; 3] => "sensors.imu.accel_scale_factor_ppm",
    st_boresight: [f64; 3] => "sensors.star_tracker.boresight_body",
    la_beam: [f64; 3] => "sensors.laser_altimeter.beam_body",
    la_pos: [f64; 3] => "sensors.laser_altimeter.position_body_m",
    rf_beam: [f64; 3] => "sensors.rf_altimeter.beam_body",
    rf_pos: [f64; 3] => "sensors.rf_altimeter.position_body_m",
    v_beams: [[f64; 3]; 3] => "sensors.velocimeter.beams_body",
    v_pos: [f64; 3] => "sensors.velocimeter.position_body_m",
    cam_bore: [f64; 3] => "sensors.camera.boresight_body",
    cam_right: [f64; 3] => "sensors.camera.image_right_body",
    cam_pos: [f64; 3] => "sensors.camera.position_body_m",
    lid_bore: [f64; 3] => "sensors.lidar.boresight_body",
    lid_right: [f64; 3] => "sensors.lidar.image_right_body",
    lid_pos: [f64; 3] => "sensors.lidar.position_body_m",
}

/// Every device on board, each with its rate, latency, error model and mounting.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorsConfig {
    /// Inertial measurement unit (gyros and accelerometers).
    pub imu: ImuConfig,
    /// Star tracker.
    pub star_tracker: StarTrackerConfig,
    /// Laser altimeter.
    pub laser_altimeter: LaserAltimeterConfig,
    /// RF (Ka-band) altimeter.
    pub rf_altimeter: RfAltimeterConfig,
    /// Laser Doppler velocimeter.
    pub velocimeter: VelocimeterConfig,
    /// The test card: a frame device with a known pattern (protocol v4 frames).
    pub test_card: TestCardConfig,
    /// The navigation camera (a frame device, off by default).
    pub camera: CameraConfig,
    /// The flash lidar (a frame device, off by default).
    pub lidar: LidarConfig,
}

/// The test card (`sensors::test_card`): a deterministic `u16` pattern with the frame
/// counter burnt in, published on `oils/<run>/frame/test-card`. Every number is assumed:
/// it models no instrument; the defaults are the size of a navigation camera's frame
/// (1024 x 1024 x 2 bytes = 2 MiB) at 1 Hz, so the frame path is exercised at its real
/// load.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TestCardConfig {
    /// Publish frames at all.
    pub enabled: bool,
    /// Frame period, ms (a whole multiple of the plant step, at least the
    /// flight-software cycle).
    pub period_ms: f64,
    /// Exposure, ms (at most the period); the frame's time of validity is its middle.
    pub exposure_ms: f64,
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

impl Default for TestCardConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            period_ms: 1000.0,
            exposure_ms: 10.0,
            width: 1024,
            height: 1024,
        }
    }
}

impl TestCardConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        timing(
            "sensors.test_card.period_ms",
            self.period_ms,
            "sensors.test_card.exposure_ms",
            0.0,
        )?;
        within(
            "sensors.test_card.exposure_ms",
            self.exposure_ms,
            0.0,
            self.period_ms,
            "in [0, period_ms] ms",
        )?;
        check(
            (self.exposure_ms * 1e6 - (self.exposure_ms * 1e6).round()).abs() < 1e-3,
            "sensors.test_card.exposure_ms",
            self.exposure_ms,
            "a whole number of nanoseconds",
        )?;
        for (field, v) in [
            ("sensors.test_card.width", self.width),
            ("sensors.test_card.height", self.height),
        ] {
            check(
                (1..=4096).contains(&v),
                field,
                f64::from(v),
                "in [1, 4096] pixels",
            )?;
        }
        Ok(())
    }
}

/// IMU: delta-theta and delta-v increments over each period. Errors per axis: a
/// constant bias (fixed part plus a per-run draw), a first-order Gauss-Markov bias
/// (its Allan floor is the bias instability), scale factor (fixed plus draw),
/// misalignment (drawn), white noise (angle / velocity random walk), quantisation with
/// the residual carried, saturation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuConfig {
    /// Produce samples at all.
    pub enabled: bool,
    /// Integration period, ms (a whole multiple of the plant step).
    pub period_ms: f64,
    /// Delay from the end of a period to the sample's delivery, ms.
    pub latency_ms: f64,
    /// Gyro bias, fixed part per axis, deg/h.
    #[serde(deserialize_with = "gyro_bias")]
    pub gyro_bias_deg_h: [f64; 3],
    /// Gyro turn-on bias, one sigma per axis (drawn once per run), deg/h.
    pub gyro_bias_sigma_deg_h: f64,
    /// Gyro bias instability (the Allan deviation floor / 0.664), deg/h.
    pub gyro_bias_instability_deg_h: f64,
    /// Correlation time of the gyro's Gauss-Markov bias, s.
    pub gyro_bias_correlation_s: f64,
    /// Gyro angle random walk, deg/sqrt(h).
    pub gyro_arw_deg_rt_h: f64,
    /// Gyro scale-factor error, fixed part per axis, ppm.
    #[serde(deserialize_with = "gyro_sf")]
    pub gyro_scale_factor_ppm: [f64; 3],
    /// Gyro scale-factor error, one sigma (drawn once per run), ppm.
    pub gyro_scale_factor_sigma_ppm: f64,
    /// Gyro axis misalignment, one sigma of each off-diagonal term, mrad.
    pub gyro_misalignment_sigma_mrad: f64,
    /// Delta-theta quantum, rad (0: none).
    pub gyro_quantum_rad: f64,
    /// Gyro range per axis, deg/s (beyond: clamped and flagged saturated).
    pub gyro_range_deg_s: f64,
    /// Accelerometer bias, fixed part per axis, micro-g.
    #[serde(deserialize_with = "accel_bias")]
    pub accel_bias_ug: [f64; 3],
    /// Accelerometer turn-on bias, one sigma per axis, micro-g.
    pub accel_bias_sigma_ug: f64,
    /// Accelerometer bias instability, micro-g.
    pub accel_bias_instability_ug: f64,
    /// Correlation time of the accelerometer's Gauss-Markov bias, s.
    pub accel_bias_correlation_s: f64,
    /// Velocity random walk, micro-g/sqrt(Hz).
    pub accel_vrw_ug_rt_hz: f64,
    /// Accelerometer scale-factor error, fixed part per axis, ppm.
    #[serde(deserialize_with = "accel_sf")]
    pub accel_scale_factor_ppm: [f64; 3],
    /// Accelerometer scale-factor error, one sigma, ppm.
    pub accel_scale_factor_sigma_ppm: f64,
    /// Accelerometer misalignment, one sigma of each off-diagonal term, mrad.
    pub accel_misalignment_sigma_mrad: f64,
    /// Delta-v quantum, m/s (0: none).
    pub accel_quantum_m_s: f64,
    /// Accelerometer range per axis, g (9.80665 m/s^2).
    pub accel_range_g: f64,
}

impl Default for ImuConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            period_ms: 5.0,
            latency_ms: 1.0,
            gyro_bias_deg_h: [0.0; 3],
            gyro_bias_sigma_deg_h: 0.01,
            gyro_bias_instability_deg_h: 0.01,
            gyro_bias_correlation_s: 600.0,
            gyro_arw_deg_rt_h: 0.005,
            gyro_scale_factor_ppm: [0.0; 3],
            gyro_scale_factor_sigma_ppm: 50.0,
            gyro_misalignment_sigma_mrad: 0.1,
            gyro_quantum_rad: 1e-6,
            gyro_range_deg_s: 400.0,
            accel_bias_ug: [0.0; 3],
            accel_bias_sigma_ug: 50.0,
            accel_bias_instability_ug: 10.0,
            accel_bias_correlation_s: 600.0,
            accel_vrw_ug_rt_hz: 30.0,
            accel_scale_factor_ppm: [0.0; 3],
            accel_scale_factor_sigma_ppm: 50.0,
            accel_misalignment_sigma_mrad: 0.1,
            accel_quantum_m_s: 1e-5,
            accel_range_g: 30.0,
        }
    }
}

/// Star tracker: the body attitude at each period's end, with noise about two
/// cross-boresight axes and about the boresight, and scheduled outages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StarTrackerConfig {
    /// Produce samples at all.
    pub enabled: bool,
    /// Period, ms.
    pub period_ms: f64,
    /// Delivery delay after the time of validity, ms.
    pub latency_ms: f64,
    /// Boresight direction, body axes (normalised when built).
    #[serde(deserialize_with = "st_boresight")]
    pub boresight_body: [f64; 3],
    /// Noise about each cross-boresight axis, one sigma, arcsec.
    pub cross_boresight_arcsec: f64,
    /// Noise about the boresight, one sigma, arcsec.
    pub about_boresight_arcsec: f64,
    /// Outage starts, s since the start of the run (samples then invalid, flagged
    /// outage); one per entry of `outage_duration_s`.
    pub outage_start_s: Vec<f64>,
    /// Outage durations, s.
    pub outage_duration_s: Vec<f64>,
}

impl Default for StarTrackerConfig {
    fn default() -> Self {
        let c = std::f64::consts::FRAC_1_SQRT_2;
        Self {
            enabled: true,
            period_ms: 200.0,
            latency_ms: 100.0,
            boresight_body: [0.0, c, c],
            cross_boresight_arcsec: 5.0,
            about_boresight_arcsec: 30.0,
            outage_start_s: Vec::new(),
            outage_duration_s: Vec::new(),
        }
    }
}

/// Laser altimeter: slant range along a body-fixed beam (one ray).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LaserAltimeterConfig {
    /// Produce samples at all.
    pub enabled: bool,
    /// Period, ms.
    pub period_ms: f64,
    /// Delivery delay, ms.
    pub latency_ms: f64,
    /// Beam direction, body axes (normalised when built).
    #[serde(deserialize_with = "la_beam")]
    pub beam_body: [f64; 3],
    /// Beam origin relative to the centre of mass, body axes, m.
    #[serde(deserialize_with = "la_pos")]
    pub position_body_m: [f64; 3],
    /// Range noise proportional to range, one sigma, fraction.
    pub noise_frac: f64,
    /// Constant range noise, one sigma, m.
    pub noise_m: f64,
    /// Shortest range with a return, m.
    pub min_range_m: f64,
    /// Longest range with a return, m.
    pub max_range_m: f64,
    /// Largest incidence (reversed beam to surface normal) with a return, deg.
    pub max_incidence_deg: f64,
}

impl Default for LaserAltimeterConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            period_ms: 100.0,
            latency_ms: 10.0,
            beam_body: [0.0, 0.0, -1.0],
            position_body_m: [0.0, 0.0, -0.8],
            noise_frac: 0.001,
            noise_m: 0.5,
            min_range_m: 1.0,
            max_range_m: 8000.0,
            max_incidence_deg: 60.0,
        }
    }
}

/// RF (Ka-band) altimeter: the nearest surface in a cone, approximated by a centre ray
/// and a ring of rays at the half-cone angle (the minimum range wins).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RfAltimeterConfig {
    /// Produce samples at all.
    pub enabled: bool,
    /// Period, ms.
    pub period_ms: f64,
    /// Delivery delay, ms.
    pub latency_ms: f64,
    /// Beam axis, body axes (normalised when built).
    #[serde(deserialize_with = "rf_beam")]
    pub beam_body: [f64; 3],
    /// Antenna position relative to the centre of mass, body axes, m.
    #[serde(deserialize_with = "rf_pos")]
    pub position_body_m: [f64; 3],
    /// Half-cone angle of the beam, deg.
    pub half_cone_deg: f64,
    /// Rays on the ring at the half-cone angle (0: the centre ray only), at most 16.
    pub ring_rays: u32,
    /// Range noise proportional to range, one sigma, fraction.
    pub noise_frac: f64,
    /// Constant range noise, one sigma, m.
    pub noise_m: f64,
    /// Shortest range with a return, m.
    pub min_range_m: f64,
    /// Longest range with a return, m.
    pub max_range_m: f64,
    /// Largest incidence of a ray that still returns, deg.
    pub max_incidence_deg: f64,
}

impl Default for RfAltimeterConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            period_ms: 50.0,
            latency_ms: 10.0,
            beam_body: [0.0, 0.0, -1.0],
            position_body_m: [0.0, 0.0, -0.8],
            half_cone_deg: 10.0,
            ring_rays: 6,
            noise_frac: 0.005,
            noise_m: 1.0,
            min_range_m: 2.0,
            max_range_m: 15_000.0,
            max_incidence_deg: 75.0,
        }
    }
}

/// Laser Doppler velocimeter: three beams, each the line-of-sight velocity relative to
/// the ground and the range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VelocimeterConfig {
    /// Produce samples at all.
    pub enabled: bool,
    /// Period, ms.
    pub period_ms: f64,
    /// Delivery delay, ms.
    pub latency_ms: f64,
    /// Beam directions, body axes (each normalised when built).
    #[serde(deserialize_with = "v_beams")]
    pub beams_body: [[f64; 3]; 3],
    /// Optical head position relative to the centre of mass, body axes, m.
    #[serde(deserialize_with = "v_pos")]
    pub position_body_m: [f64; 3],
    /// Line-of-sight velocity noise per beam, one sigma, m/s.
    pub velocity_noise_m_s: f64,
    /// Range noise proportional to range, one sigma, fraction.
    pub range_noise_frac: f64,
    /// Constant range noise, one sigma, m.
    pub range_noise_m: f64,
    /// Shortest range with a return, m.
    pub min_range_m: f64,
    /// Longest range with a return, m.
    pub max_range_m: f64,
    /// Largest incidence with a return, deg.
    pub max_incidence_deg: f64,
}

/// Three beams canted 20 deg from body -Z, 120 deg apart in azimuth.
fn default_velocimeter_beams() -> [[f64; 3]; 3] {
    let cant = 20f64.to_radians();
    [0.0f64, 120.0, 240.0].map(|az| {
        let az = az.to_radians();
        [cant.sin() * az.cos(), cant.sin() * az.sin(), -cant.cos()]
    })
}

impl Default for VelocimeterConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            period_ms: 100.0,
            latency_ms: 20.0,
            beams_body: default_velocimeter_beams(),
            position_body_m: [0.0, 0.0, -0.8],
            velocity_noise_m_s: 0.01,
            range_noise_frac: 0.001,
            range_noise_m: 0.5,
            min_range_m: 1.0,
            max_range_m: 6000.0,
            max_incidence_deg: 70.0,
        }
    }
}

/// A period or latency in ms as whole nanoseconds.
pub(crate) fn ms_to_ns(ms: f64) -> i64 {
    (ms * 1e6).round() as i64
}

fn timing(
    period_field: &'static str,
    period_ms: f64,
    latency_field: &'static str,
    latency_ms: f64,
) -> Result<(), ConfigError> {
    within(
        period_field,
        period_ms,
        1e-3,
        60_000.0,
        "in [0.001, 60000] ms",
    )?;
    check(
        (period_ms * 1e6 - (period_ms * 1e6).round()).abs() < 1e-3,
        period_field,
        period_ms,
        "a whole number of nanoseconds",
    )?;
    within(latency_field, latency_ms, 0.0, 10_000.0, "in [0, 10000] ms")
}

fn direction(field: &'static str, v: &[f64; 3]) -> Result<(), ConfigError> {
    for c in v {
        within(field, *c, -1e3, 1e3, "each component in [-1000, 1000]")?;
    }
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    check(
        n > 1e-9,
        field,
        n,
        "a non-zero direction (its norm is shown)",
    )
}

fn position(field: &'static str, v: &[f64; 3]) -> Result<(), ConfigError> {
    for c in v {
        within(field, *c, -100.0, 100.0, "each component in [-100, 100] m")?;
    }
    Ok(())
}

fn ranges(
    fields: [&'static str; 3],
    min_m: f64,
    max_m: f64,
    incidence_deg: f64,
) -> Result<(), ConfigError> {
    within(fields[0], min_m, 0.0, 1e6, "in [0, 1e6] m")?;
    check(
        max_m > min_m && max_m <= 1e7,
        fields[1],
        max_m,
        "above the minimum range, at most 1e7 m",
    )?;
    within(fields[2], incidence_deg, 0.0, 90.0, "in [0, 90] deg")
}

impl SensorsConfig {
    /// Checks every field (whether or not the device is enabled); run before tick 0.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.test_card.validate()?;
        self.camera.validate()?;
        self.lidar.validate()?;
        let i = &self.imu;
        timing(
            "sensors.imu.period_ms",
            i.period_ms,
            "sensors.imu.latency_ms",
            i.latency_ms,
        )?;
        for b in i.gyro_bias_deg_h {
            within(
                "sensors.imu.gyro_bias_deg_h",
                b,
                -1e4,
                1e4,
                "within 1e4 deg/h",
            )?;
        }
        for b in i.accel_bias_ug {
            within("sensors.imu.accel_bias_ug", b, -1e6, 1e6, "within 1e6 ug")?;
        }
        for s in i.gyro_scale_factor_ppm {
            within(
                "sensors.imu.gyro_scale_factor_ppm",
                s,
                -1e5,
                1e5,
                "within 1e5 ppm",
            )?;
        }
        for s in i.accel_scale_factor_ppm {
            within(
                "sensors.imu.accel_scale_factor_ppm",
                s,
                -1e5,
                1e5,
                "within 1e5 ppm",
            )?;
        }
        for (field, v, hi, why) in [
            (
                "sensors.imu.gyro_bias_sigma_deg_h",
                i.gyro_bias_sigma_deg_h,
                1e4,
                "in [0, 1e4] deg/h",
            ),
            (
                "sensors.imu.gyro_bias_instability_deg_h",
                i.gyro_bias_instability_deg_h,
                1e4,
                "in [0, 1e4] deg/h",
            ),
            (
                "sensors.imu.gyro_arw_deg_rt_h",
                i.gyro_arw_deg_rt_h,
                1e3,
                "in [0, 1e3] deg/sqrt(h)",
            ),
            (
                "sensors.imu.gyro_scale_factor_sigma_ppm",
                i.gyro_scale_factor_sigma_ppm,
                1e5,
                "in [0, 1e5] ppm",
            ),
            (
                "sensors.imu.gyro_misalignment_sigma_mrad",
                i.gyro_misalignment_sigma_mrad,
                100.0,
                "in [0, 100] mrad",
            ),
            (
                "sensors.imu.gyro_quantum_rad",
                i.gyro_quantum_rad,
                1e-2,
                "in [0, 0.01] rad",
            ),
            (
                "sensors.imu.accel_bias_sigma_ug",
                i.accel_bias_sigma_ug,
                1e6,
                "in [0, 1e6] ug",
            ),
            (
                "sensors.imu.accel_bias_instability_ug",
                i.accel_bias_instability_ug,
                1e6,
                "in [0, 1e6] ug",
            ),
            (
                "sensors.imu.accel_vrw_ug_rt_hz",
                i.accel_vrw_ug_rt_hz,
                1e6,
                "in [0, 1e6] ug/sqrt(Hz)",
            ),
            (
                "sensors.imu.accel_scale_factor_sigma_ppm",
                i.accel_scale_factor_sigma_ppm,
                1e5,
                "in [0, 1e5] ppm",
            ),
            (
                "sensors.imu.accel_misalignment_sigma_mrad",
                i.accel_misalignment_sigma_mrad,
                100.0,
                "in [0, 100] mrad",
            ),
            (
                "sensors.imu.accel_quantum_m_s",
                i.accel_quantum_m_s,
                1.0,
                "in [0, 1] m/s",
            ),
        ] {
            within(field, v, 0.0, hi, why)?;
        }
        within(
            "sensors.imu.gyro_bias_correlation_s",
            i.gyro_bias_correlation_s,
            1e-3,
            1e7,
            "in [0.001, 1e7] s",
        )?;
        within(
            "sensors.imu.accel_bias_correlation_s",
            i.accel_bias_correlation_s,
            1e-3,
            1e7,
            "in [0.001, 1e7] s",
        )?;
        within(
            "sensors.imu.gyro_range_deg_s",
            i.gyro_range_deg_s,
            1e-3,
            1e5,
            "in [0.001, 1e5] deg/s",
        )?;
        within(
            "sensors.imu.accel_range_g",
            i.accel_range_g,
            1e-3,
            1e4,
            "in [0.001, 1e4] g",
        )?;

        let s = &self.star_tracker;
        timing(
            "sensors.star_tracker.period_ms",
            s.period_ms,
            "sensors.star_tracker.latency_ms",
            s.latency_ms,
        )?;
        direction("sensors.star_tracker.boresight_body", &s.boresight_body)?;
        within(
            "sensors.star_tracker.cross_boresight_arcsec",
            s.cross_boresight_arcsec,
            0.0,
            3.6e5,
            "in [0, 360000] arcsec",
        )?;
        within(
            "sensors.star_tracker.about_boresight_arcsec",
            s.about_boresight_arcsec,
            0.0,
            3.6e5,
            "in [0, 360000] arcsec",
        )?;
        check(
            s.outage_start_s.len() == s.outage_duration_s.len(),
            "sensors.star_tracker.outage_duration_s",
            s.outage_duration_s.len() as f64,
            "one duration per entry of outage_start_s (the count is shown)",
        )?;
        for (&a, &d) in s.outage_start_s.iter().zip(&s.outage_duration_s) {
            within(
                "sensors.star_tracker.outage_start_s",
                a,
                0.0,
                1e7,
                "in [0, 1e7] s",
            )?;
            within(
                "sensors.star_tracker.outage_duration_s",
                d,
                0.0,
                1e7,
                "in [0, 1e7] s",
            )?;
        }

        let l = &self.laser_altimeter;
        timing(
            "sensors.laser_altimeter.period_ms",
            l.period_ms,
            "sensors.laser_altimeter.latency_ms",
            l.latency_ms,
        )?;
        direction("sensors.laser_altimeter.beam_body", &l.beam_body)?;
        position(
            "sensors.laser_altimeter.position_body_m",
            &l.position_body_m,
        )?;
        within(
            "sensors.laser_altimeter.noise_frac",
            l.noise_frac,
            0.0,
            1.0,
            "in [0, 1]",
        )?;
        within(
            "sensors.laser_altimeter.noise_m",
            l.noise_m,
            0.0,
            1e4,
            "in [0, 1e4] m",
        )?;
        ranges(
            [
                "sensors.laser_altimeter.min_range_m",
                "sensors.laser_altimeter.max_range_m",
                "sensors.laser_altimeter.max_incidence_deg",
            ],
            l.min_range_m,
            l.max_range_m,
            l.max_incidence_deg,
        )?;

        let r = &self.rf_altimeter;
        timing(
            "sensors.rf_altimeter.period_ms",
            r.period_ms,
            "sensors.rf_altimeter.latency_ms",
            r.latency_ms,
        )?;
        direction("sensors.rf_altimeter.beam_body", &r.beam_body)?;
        position("sensors.rf_altimeter.position_body_m", &r.position_body_m)?;
        within(
            "sensors.rf_altimeter.half_cone_deg",
            r.half_cone_deg,
            0.0,
            60.0,
            "in [0, 60] deg",
        )?;
        check(
            r.ring_rays <= 16,
            "sensors.rf_altimeter.ring_rays",
            f64::from(r.ring_rays),
            "at most 16",
        )?;
        within(
            "sensors.rf_altimeter.noise_frac",
            r.noise_frac,
            0.0,
            1.0,
            "in [0, 1]",
        )?;
        within(
            "sensors.rf_altimeter.noise_m",
            r.noise_m,
            0.0,
            1e4,
            "in [0, 1e4] m",
        )?;
        ranges(
            [
                "sensors.rf_altimeter.min_range_m",
                "sensors.rf_altimeter.max_range_m",
                "sensors.rf_altimeter.max_incidence_deg",
            ],
            r.min_range_m,
            r.max_range_m,
            r.max_incidence_deg,
        )?;

        let v = &self.velocimeter;
        timing(
            "sensors.velocimeter.period_ms",
            v.period_ms,
            "sensors.velocimeter.latency_ms",
            v.latency_ms,
        )?;
        for b in &v.beams_body {
            direction("sensors.velocimeter.beams_body", b)?;
        }
        position("sensors.velocimeter.position_body_m", &v.position_body_m)?;
        within(
            "sensors.velocimeter.velocity_noise_m_s",
            v.velocity_noise_m_s,
            0.0,
            100.0,
            "in [0, 100] m/s",
        )?;
        within(
            "sensors.velocimeter.range_noise_frac",
            v.range_noise_frac,
            0.0,
            1.0,
            "in [0, 1]",
        )?;
        within(
            "sensors.velocimeter.range_noise_m",
            v.range_noise_m,
            0.0,
            1e4,
            "in [0, 1e4] m",
        )?;
        ranges(
            [
                "sensors.velocimeter.min_range_m",
                "sensors.velocimeter.max_range_m",
                "sensors.velocimeter.max_incidence_deg",
            ],
            v.min_range_m,
            v.max_range_m,
            v.max_incidence_deg,
        )?;
        Ok(())
    }

    /// Each enabled device: (name, period ms, latency ms, frame capacity, period field).
    fn timings(&self) -> [(bool, &'static str, f64, f64, usize, &'static str); 5] {
        [
            (
                self.imu.enabled,
                "imu",
                self.imu.period_ms,
                self.imu.latency_ms,
                IMU_SAMPLES_MAX,
                "sensors.imu.period_ms",
            ),
            (
                self.star_tracker.enabled,
                "star-tracker",
                self.star_tracker.period_ms,
                self.star_tracker.latency_ms,
                STAR_TRACKER_SAMPLES_MAX,
                "sensors.star_tracker.period_ms",
            ),
            (
                self.laser_altimeter.enabled,
                "laser-altimeter",
                self.laser_altimeter.period_ms,
                self.laser_altimeter.latency_ms,
                ALTIMETER_SAMPLES_MAX,
                "sensors.laser_altimeter.period_ms",
            ),
            (
                self.rf_altimeter.enabled,
                "rf-altimeter",
                self.rf_altimeter.period_ms,
                self.rf_altimeter.latency_ms,
                ALTIMETER_SAMPLES_MAX,
                "sensors.rf_altimeter.period_ms",
            ),
            (
                self.velocimeter.enabled,
                "velocimeter",
                self.velocimeter.period_ms,
                self.velocimeter.latency_ms,
                VELOCIMETER_SAMPLES_MAX,
                "sensors.velocimeter.period_ms",
            ),
        ]
    }

    /// Checks the rates against the run's plant step and flight-software cycle, before
    /// tick 0: each enabled device's period is a whole multiple of the plant step (the
    /// samples fall on step ends), and one cycle's samples fit the frame (at most
    /// `ceil(cycle / period)` fall due in a cycle). The error names the device.
    pub fn check_rates(&self, plant_step_ns: u64, fsw_period_ns: u64) -> Result<(), ConfigError> {
        for (enabled, name, period_ms, _, capacity, field) in self.timings() {
            if !enabled {
                continue;
            }
            let period_ns = ms_to_ns(period_ms).max(1) as u64;
            if plant_step_ns == 0 || !period_ns.is_multiple_of(plant_step_ns) {
                return Err(ConfigError {
                    field,
                    value: format!(
                        "{period_ms} ms ({name}) with a plant step of {} ms",
                        plant_step_ns as f64 * 1e-6
                    ),
                    why: "a whole multiple of the plant step (dt_ms): samples fall on step ends",
                });
            }
            let per_cycle = fsw_period_ns.div_ceil(period_ns) as usize;
            if per_cycle > capacity {
                return Err(ConfigError {
                    field,
                    value: format!(
                        "{period_ms} ms ({name}): {per_cycle} samples per {} ms flight-software cycle, the frame holds {capacity}",
                        fsw_period_ns as f64 * 1e-6
                    ),
                    why: "one cycle's samples must fit the protocol frame: a longer period or a shorter cycle",
                });
            }
        }
        Ok(())
    }

    /// Checks the frame devices' periods against the plant step and the flight-software
    /// cycle, before tick 0 and whatever the telemetry source (frames do not need the
    /// sample devices): each enabled one's period is a whole multiple of the plant step,
    /// and at least the cycle (one frame per device per telemetry).
    pub fn check_frame_rates(
        &self,
        plant_step_ns: u64,
        fsw_period_ns: u64,
    ) -> Result<(), ConfigError> {
        for (enabled, name, period_ms, field) in [
            (
                self.test_card.enabled,
                "test-card",
                self.test_card.period_ms,
                "sensors.test_card.period_ms",
            ),
            (
                self.camera.enabled,
                "camera",
                self.camera.period_ms,
                "sensors.camera.period_ms",
            ),
            (
                self.lidar.enabled,
                "lidar",
                self.lidar.period_ms,
                "sensors.lidar.period_ms",
            ),
        ] {
            if !enabled {
                continue;
            }
            let period_ns = ms_to_ns(period_ms).max(1) as u64;
            if plant_step_ns == 0 || !period_ns.is_multiple_of(plant_step_ns) {
                return Err(ConfigError {
                    field,
                    value: format!(
                        "{period_ms} ms ({name}) with a plant step of {} ms",
                        plant_step_ns as f64 * 1e-6
                    ),
                    why: "a whole multiple of the plant step (dt_ms): frames fall on step ends",
                });
            }
            if period_ns < fsw_period_ns {
                return Err(ConfigError {
                    field,
                    value: format!(
                        "{period_ms} ms ({name}) with a {} ms flight-software cycle",
                        fsw_period_ns as f64 * 1e-6
                    ),
                    why: "at least the flight-software cycle: a telemetry announces one frame per device",
                });
            }
        }
        Ok(())
    }

    /// The sensor set and rates, one line per device, for `oils run --print-config`.
    pub fn summary(&self) -> String {
        let mut out = String::new();
        for (enabled, name, period_ms, latency_ms, capacity, _) in self.timings() {
            if enabled {
                out.push_str(&format!(
                    "{name:<16} {:>8.3} Hz  period {period_ms} ms  latency {latency_ms} ms  frame capacity {capacity}\n",
                    1e3 / period_ms
                ));
            } else {
                out.push_str(&format!("{name:<16} off\n"));
            }
        }
        let t = &self.test_card;
        if t.enabled {
            out.push_str(&format!(
                "{:<16} {:>8.3} Hz  period {} ms  exposure {} ms  {} x {} u16  {} bytes a frame\n",
                "test-card",
                1e3 / t.period_ms,
                t.period_ms,
                t.exposure_ms,
                t.width,
                t.height,
                2 * t.width as u64 * t.height as u64
            ));
        } else {
            out.push_str("test-card        off\n");
        }
        out
    }
}

/// Navigation camera: a global-shutter pinhole with Brown-Conrady radial distortion,
/// lunar-Lambert radiance, shot and read noise, a full well and an ADC
/// (`docs/sensors.md`, "Navigation camera"). Off by default: nothing existing changes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Produce frames at all.
    pub enabled: bool,
    /// Frame period, ms (integer nanoseconds once built).
    pub period_ms: f64,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Full field of view across the image width (undistorted), degrees.
    pub fov_deg: f64,
    /// Brown-Conrady radial distortion, `r^2` coefficient.
    pub k1: f64,
    /// Brown-Conrady radial distortion, `r^4` coefficient.
    pub k2: f64,
    /// Boresight (camera +z), body axes (normalised when built).
    #[serde(deserialize_with = "cam_bore")]
    pub boresight_body: [f64; 3],
    /// Direction of increasing column (camera +x), body axes; made perpendicular to the
    /// boresight when built. Rows increase along boresight x right.
    #[serde(deserialize_with = "cam_right")]
    pub image_right_body: [f64; 3],
    /// Optical centre relative to the centre of mass, body axes, m.
    #[serde(deserialize_with = "cam_pos")]
    pub position_body_m: [f64; 3],
    /// Exposure (integration) time, ms.
    pub exposure_ms: f64,
    /// ADC bits per pixel (8 to 16; stored in a u16).
    pub bits: u32,
    /// Full-well capacity, electrons.
    pub full_well_e: f64,
    /// Read noise, one sigma, electrons.
    pub read_noise_e: f64,
    /// Focal ratio f/D of the optics.
    pub f_number: f64,
    /// Pixel pitch, micrometres.
    pub pixel_pitch_um: f64,
    /// Optical transmission times quantum efficiency (0..1].
    pub throughput: f64,
    /// Solar irradiance at the Moon in the camera's band, W/m^2.
    pub solar_band_irradiance_w_m2: f64,
    /// Mean wavelength of the band, nm (photon energy).
    pub wavelength_nm: f64,
    /// Normal albedo `A` of the lunar-Lambert model (I/F at zero phase, normal view).
    pub normal_albedo: f64,
    /// I/F of surfaces the sun does not reach (earthshine, scatter), 0: black.
    pub shadow_floor_iof: f64,
    /// Shot and read noise on (off: the noiseless expected signal, for tests).
    pub noise: bool,
    /// Poses rendered across the exposure and averaged (motion blur); 1: none.
    pub blur_samples: u32,
    /// Largest angle between the frame's sun and the shadow map's for the map to be
    /// used, degrees (beyond it every lit point casts an exact shadow ray).
    pub shadow_map_tolerance_deg: f64,
    /// Powered below this height above the reference sphere, m: above it the device
    /// publishes blank frames flagged `FRAME_FLAG_OUTAGE` (switched off for the coast
    /// and the braking burn, as a descent camera is; the default, 1e9, never).
    pub on_below_altitude_m: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            period_ms: 200.0,
            width_px: 1024,
            height_px: 1024,
            fov_deg: 45.0,
            k1: -0.05,
            k2: 0.005,
            boresight_body: [0.0, 0.0, -1.0],
            image_right_body: [0.0, 1.0, 0.0],
            position_body_m: [0.9, 0.0, -0.6],
            exposure_ms: 0.3,
            bits: 12,
            full_well_e: 20_000.0,
            read_noise_e: 10.0,
            f_number: 4.0,
            pixel_pitch_um: 5.5,
            throughput: 0.5,
            solar_band_irradiance_w_m2: 520.0,
            wavelength_nm: 550.0,
            normal_albedo: 0.15,
            shadow_floor_iof: 0.0,
            noise: true,
            blur_samples: 1,
            shadow_map_tolerance_deg: 0.25,
            on_below_altitude_m: 1e9,
        }
    }
}

/// Flash lidar: a range image over a square field of view, one exact ray cast per
/// pixel, Gaussian range noise, no-return pixels 0 (`docs/sensors.md`, "Flash lidar").
/// Off by default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LidarConfig {
    /// Produce frames at all.
    pub enabled: bool,
    /// Frame period, ms.
    pub period_ms: f64,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Full field of view across the width (a pinhole, no distortion), degrees.
    pub fov_deg: f64,
    /// Boresight, body axes.
    #[serde(deserialize_with = "lid_bore")]
    pub boresight_body: [f64; 3],
    /// Direction of increasing column, body axes.
    #[serde(deserialize_with = "lid_right")]
    pub image_right_body: [f64; 3],
    /// Receiver position relative to the centre of mass, body axes, m.
    #[serde(deserialize_with = "lid_pos")]
    pub position_body_m: [f64; 3],
    /// Range noise, one sigma, m.
    pub range_noise_m: f64,
    /// Shortest range with a return, m.
    pub min_range_m: f64,
    /// Longest range with a return, m.
    pub max_range_m: f64,
    /// Largest incidence with a return, degrees.
    pub max_incidence_deg: f64,
    /// Range noise on.
    pub noise: bool,
    /// Powered below this height above the reference sphere, m: above it the device
    /// publishes blank frames flagged `FRAME_FLAG_OUTAGE` (switched off for the coast
    /// and the braking burn, as a descent camera is; the default, 1e9, never).
    pub on_below_altitude_m: f64,
}

impl Default for LidarConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            period_ms: 200.0,
            width_px: 128,
            height_px: 128,
            fov_deg: 20.0,
            boresight_body: [0.0, 0.0, -1.0],
            image_right_body: [0.0, 1.0, 0.0],
            position_body_m: [0.9, 0.3, -0.6],
            range_noise_m: 0.05,
            min_range_m: 1.0,
            max_range_m: 1000.0,
            max_incidence_deg: 85.0,
            noise: true,
            on_below_altitude_m: 1e9,
        }
    }
}

/// A boresight and an image-right axis that are unit-able and not parallel.
fn check_axes(
    bore_field: &'static str,
    bore: [f64; 3],
    right_field: &'static str,
    right: [f64; 3],
) -> Result<(), ConfigError> {
    let b = nalgebra::Vector3::from(bore);
    let r = nalgebra::Vector3::from(right);
    check(
        b.norm() > 1e-9,
        bore_field,
        b.norm(),
        "a non-zero finite vector",
    )?;
    check(
        r.norm() > 1e-9,
        right_field,
        r.norm(),
        "a non-zero finite vector",
    )?;
    let cross = b.normalize().cross(&r.normalize()).norm();
    check(
        cross > 1e-3,
        right_field,
        cross,
        "not parallel to the boresight (|boresight x right| > 1e-3)",
    )
}

fn check_frame_size(
    w_field: &'static str,
    w: u32,
    h_field: &'static str,
    h: u32,
) -> Result<(), ConfigError> {
    within(w_field, w as f64, 1.0, 8192.0, "1 to 8192 pixels")?;
    within(h_field, h as f64, 1.0, 8192.0, "1 to 8192 pixels")
}

impl CameraConfig {
    /// Refuses, naming the field, any value the model cannot use.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check(
            self.period_ms >= 1e-3 && self.period_ms <= 1e6,
            "sensors.camera.period_ms",
            self.period_ms,
            "1e-3 to 1e6 ms",
        )?;
        check_frame_size(
            "sensors.camera.width_px",
            self.width_px,
            "sensors.camera.height_px",
            self.height_px,
        )?;
        within(
            "sensors.camera.fov_deg",
            self.fov_deg,
            1.0,
            120.0,
            "1 to 120 deg",
        )?;
        within("sensors.camera.k1", self.k1, -0.5, 0.5, "|k1| <= 0.5")?;
        within("sensors.camera.k2", self.k2, -0.5, 0.5, "|k2| <= 0.5")?;
        check_axes(
            "sensors.camera.boresight_body",
            self.boresight_body,
            "sensors.camera.image_right_body",
            self.image_right_body,
        )?;
        for p in self.position_body_m {
            within(
                "sensors.camera.position_body_m",
                p,
                -100.0,
                100.0,
                "within 100 m",
            )?;
        }
        check(
            self.exposure_ms > 0.0 && self.exposure_ms <= self.period_ms,
            "sensors.camera.exposure_ms",
            self.exposure_ms,
            "positive and at most the frame period",
        )?;
        within(
            "sensors.camera.bits",
            self.bits as f64,
            8.0,
            16.0,
            "8 to 16 bits",
        )?;
        within(
            "sensors.camera.full_well_e",
            self.full_well_e,
            1.0,
            1e8,
            "1 to 1e8 e-",
        )?;
        within(
            "sensors.camera.read_noise_e",
            self.read_noise_e,
            0.0,
            1e4,
            "0 to 1e4 e-",
        )?;
        within(
            "sensors.camera.f_number",
            self.f_number,
            0.5,
            100.0,
            "0.5 to 100",
        )?;
        within(
            "sensors.camera.pixel_pitch_um",
            self.pixel_pitch_um,
            0.1,
            100.0,
            "0.1 to 100 um",
        )?;
        check(
            self.throughput > 0.0 && self.throughput <= 1.0,
            "sensors.camera.throughput",
            self.throughput,
            "in (0, 1]",
        )?;
        within(
            "sensors.camera.solar_band_irradiance_w_m2",
            self.solar_band_irradiance_w_m2,
            0.0,
            1e4,
            "0 to 1e4 W/m^2",
        )?;
        within(
            "sensors.camera.wavelength_nm",
            self.wavelength_nm,
            100.0,
            20_000.0,
            "100 to 20000 nm",
        )?;
        within(
            "sensors.camera.normal_albedo",
            self.normal_albedo,
            0.0,
            1.0,
            "0 to 1",
        )?;
        within(
            "sensors.camera.shadow_floor_iof",
            self.shadow_floor_iof,
            0.0,
            1.0,
            "0 to 1",
        )?;
        within(
            "sensors.camera.blur_samples",
            self.blur_samples as f64,
            1.0,
            64.0,
            "1 to 64",
        )?;
        within(
            "sensors.camera.shadow_map_tolerance_deg",
            self.shadow_map_tolerance_deg,
            0.0,
            10.0,
            "0 to 10 deg",
        )
    }
}

impl LidarConfig {
    /// Refuses, naming the field, any value the model cannot use.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check(
            self.period_ms >= 1e-3 && self.period_ms <= 1e6,
            "sensors.lidar.period_ms",
            self.period_ms,
            "1e-3 to 1e6 ms",
        )?;
        check_frame_size(
            "sensors.lidar.width_px",
            self.width_px,
            "sensors.lidar.height_px",
            self.height_px,
        )?;
        within(
            "sensors.lidar.fov_deg",
            self.fov_deg,
            0.1,
            120.0,
            "0.1 to 120 deg",
        )?;
        check_axes(
            "sensors.lidar.boresight_body",
            self.boresight_body,
            "sensors.lidar.image_right_body",
            self.image_right_body,
        )?;
        for p in self.position_body_m {
            within(
                "sensors.lidar.position_body_m",
                p,
                -100.0,
                100.0,
                "within 100 m",
            )?;
        }
        within(
            "sensors.lidar.range_noise_m",
            self.range_noise_m,
            0.0,
            100.0,
            "0 to 100 m",
        )?;
        check(
            self.min_range_m >= 0.0 && self.min_range_m < self.max_range_m,
            "sensors.lidar.min_range_m",
            self.min_range_m,
            "at least 0 and below max_range_m",
        )?;
        within(
            "sensors.lidar.max_range_m",
            self.max_range_m,
            1e-3,
            1e6,
            "1e-3 to 1e6 m",
        )?;
        within(
            "sensors.lidar.max_incidence_deg",
            self.max_incidence_deg,
            0.0,
            90.0,
            "0 to 90 deg",
        )
    }
}

#[cfg(test)]
mod eyes_tests {
    use super::*;

    #[test]
    fn camera_and_lidar_defaults_are_off_and_valid() {
        let (c, l) = (CameraConfig::default(), LidarConfig::default());
        assert!(!c.enabled && !l.enabled);
        c.validate().unwrap();
        l.validate().unwrap();
    }

    #[test]
    fn bad_camera_and_lidar_fields_are_named() {
        let c = CameraConfig {
            exposure_ms: 300.0,
            ..CameraConfig::default()
        };
        assert_eq!(
            c.validate().unwrap_err().field,
            "sensors.camera.exposure_ms"
        );
        let c = CameraConfig {
            image_right_body: [0.0, 0.0, -2.0],
            ..CameraConfig::default()
        };
        assert_eq!(
            c.validate().unwrap_err().field,
            "sensors.camera.image_right_body"
        );
        let l = LidarConfig {
            min_range_m: 2000.0,
            ..LidarConfig::default()
        };
        assert_eq!(l.validate().unwrap_err().field, "sensors.lidar.min_range_m");
        let l = LidarConfig {
            fov_deg: f64::NAN,
            ..LidarConfig::default()
        };
        assert_eq!(l.validate().unwrap_err().field, "sensors.lidar.fov_deg");
        assert!(toml::from_str::<CameraConfig>("enabled = true\nfocal = 3").is_err());
        assert!(toml::from_str::<LidarConfig>("boresight_body = [0, 0, -1, 0]").is_err());
        let c: CameraConfig = toml::from_str("enabled = true\nwidth_px = 640").unwrap();
        assert!(c.enabled && c.width_px == 640 && c.height_px == 1024);
    }
}
