//! The sun's direction at the landing site (`docs/world.md`), from the scenario's epoch
//! through an analytic model, or set directly as azimuth and elevation (`[sun]`).
//!
//! Model, each piece sourced:
//! - the Sun's geocentric apparent ecliptic longitude and distance: the Astronomical
//!   Almanac's low-precision formulas (section C, "Sun"; 0.01 deg from 1950 to 2050),
//!   referred to the mean equinox of date, precessed to J2000 by the general precession
//!   in longitude (5028.796" per century, IAU 2006) and turned equatorial with the J2000
//!   obliquity 23.4392911 deg;
//! - the Moon's geocentric position: the Almanac's low-precision lunar formulas (section
//!   D; 0.3 deg in longitude, 0.2 deg in latitude), needed only to move the Sun's
//!   direction from the Earth to the Moon: 0.3 deg of the Moon's 384 400 km is 2 000 km,
//!   1.3e-5 rad (0.0008 deg) of the Sun's direction;
//! - the Moon's orientation: the IAU 2009 model of Archinal et al. (2011, Celest. Mech.
//!   Dyn. Astron. 109, 101-135, table 2: `alpha0`, `delta0`, `W` with the E1..E13 terms),
//!   which approximates the mean-Earth/polar-axis frame of lunar maps (LOLA) to about
//!   150 m on the surface (0.005 deg).
//!
//! The lander-Sun parallax (the site is 1 737 km from the Moon's centre, the Sun
//! 1.496e8 km away: 1.2e-5 rad, 0.0007 deg) is neglected: the direction is the same at
//! every point of the site frame. Stated error: about 0.02 deg in direction, dominated by
//! the solar formulas. Time: UTC to TT through the leap-second table (TAI - UTC), TDB
//! taken as TT (they differ by under 2 ms: 1e-6 deg of the Sun's motion).

use super::terrain::SiteFrame;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// The default scenario's epoch: Chandrayaan-3's landing, 2023-08-23 12:33 UTC (ISRO: 18:03
/// IST), at the default site (Chandrayaan-3's).
pub const DEFAULT_EPOCH_UTC: &str = "2023-08-23T12:33:00Z";
/// The Moon's sidereal rotation seen against the Sun, about 0.51 deg per hour (360 deg a
/// synodic month of 29.53 d): how far the sun moves over a descent.
pub const SUN_RATE_DEG_PER_HOUR: f64 = 360.0 / (29.530_589 * 24.0);

/// Why a `[sun]` table is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SunError {
    /// The epoch string is not `YYYY-MM-DDTHH:MM:SS[.fff][Z]`.
    #[error("sun.epoch_utc `{0}`: expected YYYY-MM-DDTHH:MM:SS[.fff]Z")]
    BadEpoch(String),
    /// The epoch is outside the model's years.
    #[error("sun epoch: year {0} outside 1950..=2100, the analytic model's span")]
    EpochOutOfRange(i64),
    /// More than one way, or half of the direct way, is given.
    #[error("sun: {0}")]
    Conflict(&'static str),
    /// A number is out of range or not finite.
    #[error("sun.{field} = {value}: {why}")]
    OutOfRange {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
        /// The rule.
        why: &'static str,
    },
}

/// The scenario's `[sun]` table: one of an epoch (`epoch_utc` or `epoch_tdb_s`) or a
/// direction at the site (`azimuth_deg` and `elevation_deg`); nothing: the
/// [`DEFAULT_EPOCH_UTC`]. The epoch is the scenario's `t = 0`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SunSpec {
    /// UTC epoch of `t = 0`, `YYYY-MM-DDTHH:MM:SS[.fff]Z`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub epoch_utc: Option<String>,
    /// Or TDB seconds past J2000 (2000-01-01 12:00:00 TDB).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub epoch_tdb_s: Option<f64>,
    /// Or the sun held at this azimuth, degrees clockwise from north at the site...
    #[serde(skip_serializing_if = "Option::is_none")]
    pub azimuth_deg: Option<f64>,
    /// ...and this elevation above the site's horizon, degrees.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub elevation_deg: Option<f64>,
}

impl SunSpec {
    /// True when nothing is set (the default epoch).
    pub fn is_default(&self) -> bool {
        *self == SunSpec::default()
    }

    /// Checks the table; run before tick 0.
    pub fn validate(&self) -> Result<(), SunError> {
        self.source().map(|_| ())
    }

    fn source(&self) -> Result<Source, SunError> {
        let direct = (self.azimuth_deg, self.elevation_deg);
        match (&self.epoch_utc, self.epoch_tdb_s, direct) {
            (None, None, (None, None)) => Ok(Source::Epoch(tdb_s_from_utc(DEFAULT_EPOCH_UTC)?)),
            (Some(s), None, (None, None)) => Ok(Source::Epoch(tdb_s_from_utc(s)?)),
            (None, Some(t), (None, None)) => {
                let century = 100.0 * 365.25 * 86_400.0;
                if !(t.is_finite() && t.abs() <= 1.0 * century) {
                    return Err(SunError::OutOfRange {
                        field: "epoch_tdb_s",
                        value: t,
                        why: "within a century of J2000",
                    });
                }
                Ok(Source::Epoch(t))
            }
            (None, None, (Some(az), Some(el))) => {
                if !(az.is_finite() && (-360.0..=360.0).contains(&az)) {
                    return Err(SunError::OutOfRange {
                        field: "azimuth_deg",
                        value: az,
                        why: "within [-360, 360] deg",
                    });
                }
                if !(el.is_finite() && (-90.0..=90.0).contains(&el)) {
                    return Err(SunError::OutOfRange {
                        field: "elevation_deg",
                        value: el,
                        why: "within [-90, 90] deg",
                    });
                }
                Ok(Source::Direct { az, el })
            }
            (_, _, (Some(_), None)) | (_, _, (None, Some(_))) => Err(SunError::Conflict(
                "azimuth_deg and elevation_deg go together",
            )),
            _ => Err(SunError::Conflict(
                "give one of epoch_utc, epoch_tdb_s, or azimuth_deg with elevation_deg",
            )),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Source {
    Epoch(f64),
    Direct { az: f64, el: f64 },
}

/// The sun as a run sees it: a direction at the site at simulated time `t_ns` past the
/// epoch. Immutable; a few dozen trigonometric calls a query (no allocation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sun {
    site: SiteFrame,
    source: Source,
}

impl Sun {
    /// The sun of `spec` at `site`.
    pub fn new(spec: &SunSpec, site: &SiteFrame) -> Result<Self, SunError> {
        Ok(Self {
            site: *site,
            source: spec.source()?,
        })
    }

    /// TDB seconds past J2000 at `t_ns` (`None` for a direction set directly).
    pub fn tdb_s(&self, t_ns: i64) -> Option<f64> {
        match self.source {
            Source::Epoch(t0) => Some(t0 + t_ns as f64 * 1e-9),
            Source::Direct { .. } => None,
        }
    }

    /// Unit vector toward the sun, `mcmf`, at `t_ns` past the epoch.
    pub fn sun_dir_mcmf(&self, t_ns: i64) -> Vector3<f64> {
        match self.source {
            Source::Epoch(t0) => sun_dir_mcmf_at_tdb(t0 + t_ns as f64 * 1e-9),
            Source::Direct { az, el } => self.site.mcmf_dir_from_site(&dir_of_az_el(az, el)),
        }
    }

    /// Unit vector toward the sun in the site frame (East, North, Up) at `t_ns`. A set
    /// direction is held constant; from an epoch it moves ~0.5 deg an hour
    /// ([`SUN_RATE_DEG_PER_HOUR`]), under 0.13 deg over a 15-minute descent: a renderer
    /// may evaluate it once a frame, or once a run.
    pub fn sun_dir_site(&self, t_ns: i64) -> Vector3<f64> {
        match self.source {
            Source::Epoch(_) => self.site.site_dir_from_mcmf(&self.sun_dir_mcmf(t_ns)),
            Source::Direct { az, el } => dir_of_az_el(az, el),
        }
    }

    /// Azimuth (degrees clockwise from north, in [0, 360)) and elevation (degrees above
    /// the site's horizon) at `t_ns`.
    pub fn azimuth_elevation_deg(&self, t_ns: i64) -> (f64, f64) {
        az_el_of_dir(&self.sun_dir_site(t_ns))
    }
}

/// Site-frame unit vector of azimuth `az_deg` (clockwise from north), elevation `el_deg`.
pub fn dir_of_az_el(az_deg: f64, el_deg: f64) -> Vector3<f64> {
    let (sa, ca) = az_deg.to_radians().sin_cos();
    let (se, ce) = el_deg.to_radians().sin_cos();
    Vector3::new(sa * ce, ca * ce, se)
}

/// Azimuth in [0, 360) and elevation, degrees, of a site-frame direction.
pub fn az_el_of_dir(d: &Vector3<f64>) -> (f64, f64) {
    let az = d.x.atan2(d.y).to_degrees().rem_euclid(360.0);
    let el = d.z.atan2(d.x.hypot(d.y)).to_degrees();
    (az, el)
}

/// Sub-solar latitude and east longitude (degrees) on the Moon at `tdb_s` past J2000.
pub fn subsolar_lat_lon_deg(tdb_s: f64) -> (f64, f64) {
    let s = sun_dir_mcmf_at_tdb(tdb_s);
    (
        s.z.atan2(s.x.hypot(s.y)).to_degrees(),
        s.y.atan2(s.x).to_degrees(),
    )
}

const AU_KM: f64 = 149_597_870.7;
/// J2000 mean obliquity (IAU 2006), degrees.
const OBLIQUITY_J2000_DEG: f64 = 23.439_291_1;
/// General precession in longitude, degrees per Julian century (5028.796195"; IAU 2006).
const PRECESSION_DEG_PER_CENTURY: f64 = 1.396_887_83;

fn sin_d(x: f64) -> f64 {
    x.to_radians().sin()
}

fn cos_d(x: f64) -> f64 {
    x.to_radians().cos()
}

/// Ecliptic (J2000) longitude/latitude (deg) and distance to equatorial J2000.
fn equatorial_of_ecliptic(lon_deg: f64, lat_deg: f64, r: f64) -> Vector3<f64> {
    let (se, ce) = OBLIQUITY_J2000_DEG.to_radians().sin_cos();
    let (sl, cl) = lon_deg.to_radians().sin_cos();
    let (sb, cb) = lat_deg.to_radians().sin_cos();
    Vector3::new(
        r * cb * cl,
        r * (ce * cb * sl - se * sb),
        r * (se * cb * sl + ce * sb),
    )
}

/// The Sun's geocentric position, equatorial J2000, km (Astronomical Almanac, low
/// precision).
pub fn sun_geocentric_km(tdb_s: f64) -> Vector3<f64> {
    let n = tdb_s / 86_400.0;
    let t = n / 36_525.0;
    let l = 280.460 + 0.985_647_4 * n;
    let g = 357.528 + 0.985_600_3 * n;
    let lon_date = l + 1.915 * sin_d(g) + 0.020 * sin_d(2.0 * g);
    let r_au = 1.000_14 - 0.016_71 * cos_d(g) - 0.000_14 * cos_d(2.0 * g);
    let lon = lon_date - PRECESSION_DEG_PER_CENTURY * t;
    equatorial_of_ecliptic(lon, 0.0, r_au * AU_KM)
}

/// The Moon's geocentric position, equatorial J2000, km (Astronomical Almanac, low
/// precision; distance from the horizontal parallax with the Earth's 6378.14 km).
pub fn moon_geocentric_km(tdb_s: f64) -> Vector3<f64> {
    let t = tdb_s / 86_400.0 / 36_525.0;
    let lon_date = 218.32 + 481_267.881 * t + 6.29 * sin_d(135.0 + 477_198.87 * t)
        - 1.27 * sin_d(259.3 - 413_335.36 * t)
        + 0.66 * sin_d(235.7 + 890_534.22 * t)
        + 0.21 * sin_d(269.9 + 954_397.74 * t)
        - 0.19 * sin_d(357.5 + 35_999.05 * t)
        - 0.11 * sin_d(186.5 + 966_404.03 * t);
    let lat = 5.13 * sin_d(93.3 + 483_202.02 * t) + 0.28 * sin_d(228.2 + 960_400.89 * t)
        - 0.28 * sin_d(318.3 + 6_003.15 * t)
        - 0.17 * sin_d(217.6 - 407_332.21 * t);
    let parallax = 0.9508
        + 0.0518 * cos_d(135.0 + 477_198.87 * t)
        + 0.0095 * cos_d(259.3 - 413_335.36 * t)
        + 0.0078 * cos_d(235.7 + 890_534.22 * t)
        + 0.0028 * cos_d(269.9 + 954_397.74 * t);
    let r_km = 6378.14 / sin_d(parallax);
    equatorial_of_ecliptic(lon_date - PRECESSION_DEG_PER_CENTURY * t, lat, r_km)
}

/// The rotation from ICRF (J2000 equatorial) to the Moon-fixed frame at `tdb_s`: the IAU
/// 2009 model (Archinal et al. 2011), `Rz(W) Rx(90 - delta0) Rz(90 + alpha0)`.
pub fn rot_mcmf_from_icrf(tdb_s: f64) -> Matrix3<f64> {
    let d = tdb_s / 86_400.0;
    let t = d / 36_525.0;
    let e = [
        125.045 - 0.052_992_1 * d,
        250.089 - 0.105_984_2 * d,
        260.008 + 13.012_000_9 * d,
        176.625 + 13.340_715_4 * d,
        357.529 + 0.985_600_3 * d,
        311.589 + 26.405_708_4 * d,
        134.963 + 13.064_993_0 * d,
        276.617 + 0.328_714_6 * d,
        34.226 + 1.748_487_7 * d,
        15.134 - 0.158_976_3 * d,
        119.743 + 0.003_609_6 * d,
        239.961 + 0.164_357_3 * d,
        25.053 + 12.959_008_8 * d,
    ];
    let s = |k: usize| sin_d(e[k - 1]);
    let c = |k: usize| cos_d(e[k - 1]);
    let alpha0 = 269.9949 + 0.0031 * t - 3.8787 * s(1) - 0.1204 * s(2) + 0.0700 * s(3)
        - 0.0172 * s(4)
        + 0.0072 * s(6)
        - 0.0052 * s(10)
        + 0.0043 * s(13);
    let delta0 = 66.5392 + 0.0130 * t + 1.5419 * c(1) + 0.0239 * c(2) - 0.0278 * c(3)
        + 0.0068 * c(4)
        - 0.0029 * c(6)
        + 0.0009 * c(7)
        + 0.0008 * c(10)
        - 0.0009 * c(13);
    let w = 38.3213 + 13.176_358_15 * d - 1.4e-12 * d * d + 3.5610 * s(1) + 0.1208 * s(2)
        - 0.0642 * s(3)
        + 0.0158 * s(4)
        + 0.0252 * s(5)
        - 0.0066 * s(6)
        - 0.0047 * s(7)
        - 0.0046 * s(8)
        + 0.0028 * s(9)
        + 0.0052 * s(10)
        + 0.0040 * s(11)
        + 0.0019 * s(12)
        - 0.0044 * s(13);
    rot_z(w) * rot_x(90.0 - delta0) * rot_z(90.0 + alpha0)
}

/// Frame rotation about z by `deg` (a vector's coordinates in axes turned by `deg`).
fn rot_z(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0)
}

fn rot_x(deg: f64) -> Matrix3<f64> {
    let (s, c) = deg.to_radians().sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, s, 0.0, -s, c)
}

/// Unit vector from the Moon's centre toward the Sun, Moon-fixed (`mcmf`), at `tdb_s`
/// TDB seconds past J2000.
pub fn sun_dir_mcmf_at_tdb(tdb_s: f64) -> Vector3<f64> {
    let from_moon = sun_geocentric_km(tdb_s) - moon_geocentric_km(tdb_s);
    (rot_mcmf_from_icrf(tdb_s) * from_moon).normalize()
}

/// TAI - UTC (s) at a UTC instant given as civil seconds past 1970 (leap seconds not
/// counted): the IERS leap-second table from 1972; before it, the 1968-1971 rate
/// `4.2131700 + (MJD - 39126) * 0.002592` (USNO tai-utc.dat), within 2 s back to 1961.
fn tai_minus_utc_s(unix_s: f64) -> f64 {
    // (days past 1970-01-01 the step took effect, TAI - UTC from then).
    const STEPS: [(i64, f64); 28] = [
        (730, 10.0),   // 1972-01-01
        (912, 11.0),   // 1972-07-01
        (1096, 12.0),  // 1973-01-01
        (1461, 13.0),  // 1974-01-01
        (1826, 14.0),  // 1975-01-01
        (2191, 15.0),  // 1976-01-01
        (2557, 16.0),  // 1977-01-01
        (2922, 17.0),  // 1978-01-01
        (3287, 18.0),  // 1979-01-01
        (3652, 19.0),  // 1980-01-01
        (4199, 20.0),  // 1981-07-01
        (4564, 21.0),  // 1982-07-01
        (4929, 22.0),  // 1983-07-01
        (5660, 23.0),  // 1985-07-01
        (6574, 24.0),  // 1988-01-01
        (7305, 25.0),  // 1990-01-01
        (7670, 26.0),  // 1991-01-01
        (8217, 27.0),  // 1992-07-01
        (8582, 28.0),  // 1993-07-01
        (8947, 29.0),  // 1994-07-01
        (9496, 30.0),  // 1996-01-01
        (10043, 31.0), // 1997-07-01
        (10592, 32.0), // 1999-01-01
        (13149, 33.0), // 2006-01-01
        (14245, 34.0), // 2009-01-01
        (15522, 35.0), // 2012-07-01
        (16617, 36.0), // 2015-07-01
        (17167, 37.0), // 2017-01-01
    ];
    let day = (unix_s / 86_400.0).floor() as i64;
    match STEPS.iter().rev().find(|(d, _)| day >= *d) {
        Some((_, v)) => *v,
        None => {
            let mjd = unix_s / 86_400.0 + 40_587.0;
            4.213_170_0 + (mjd - 39_126.0) * 0.002_592
        }
    }
}

/// Days from 1970-01-01 to the civil date (proleptic Gregorian; H. Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// TDB (taken as TT) seconds past J2000 of a UTC instant `YYYY-MM-DDTHH:MM:SS[.fff][Z]`.
pub fn tdb_s_from_utc(text: &str) -> Result<f64, SunError> {
    let bad = || SunError::BadEpoch(text.to_string());
    let s = text.trim();
    let s = s.strip_suffix('Z').unwrap_or(s);
    let (date, time) = s.split_once(['T', ' ']).ok_or_else(bad)?;
    let mut dp = date.split('-');
    let num = |it: &mut std::str::Split<'_, char>| -> Result<i64, SunError> {
        it.next()
            .filter(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|p| p.parse().ok())
            .ok_or_else(bad)
    };
    let (y, mo, d) = (num(&mut dp)?, num(&mut dp)?, num(&mut dp)?);
    if dp.next().is_some() {
        return Err(bad());
    }
    let mut tp = time.split(':');
    let (h, mi) = (num(&mut tp)?, num(&mut tp)?);
    let sec: f64 = tp
        .next()
        .filter(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit() || b == b'.'))
        .and_then(|p| p.parse().ok())
        .ok_or_else(bad)?;
    if tp.next().is_some() {
        return Err(bad());
    }
    let month_days = [31, 29, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
    let ok = (1..=12).contains(&mo)
        && d >= 1
        && d <= month_days[(mo - 1).clamp(0, 11) as usize]
        && (0..24).contains(&h)
        && (0..60).contains(&mi)
        && (0.0..61.0).contains(&sec);
    if !ok {
        return Err(bad());
    }
    if !(1950..=2100).contains(&y) {
        return Err(SunError::EpochOutOfRange(y));
    }
    let unix_s = (days_from_civil(y, mo, d) * 86_400 + h * 3600 + mi * 60) as f64 + sec;
    // 2000-01-01T12:00:00 civil, seconds past 1970.
    const J2000_CIVIL_UNIX_S: f64 = 946_728_000.0;
    Ok(unix_s - J2000_CIVIL_UNIX_S + tai_minus_utc_s(unix_s) + 32.184)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_days_and_leap_seconds() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(days_from_civil(1972, 1, 1), 730);
        assert_eq!(days_from_civil(2017, 1, 1), 17167);
        assert_eq!(days_from_civil(2000, 1, 1), 10957);
        // J2000 is 2000-01-01 11:58:55.816 UTC (TT - UTC = 32 + 32.184 s then).
        let t = tdb_s_from_utc("2000-01-01T11:58:55.816Z").unwrap();
        assert!(t.abs() < 1e-6, "{t}");
        assert!(tdb_s_from_utc("2023-02-30T00:00:00Z").is_err());
        assert!(tdb_s_from_utc("2023-08-23 12:33").is_err());
        assert!(matches!(
            tdb_s_from_utc("1900-01-01T00:00:00Z"),
            Err(SunError::EpochOutOfRange(1900))
        ));
    }
}
