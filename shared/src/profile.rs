//! Thrust-command profiles: the bench's CSV exchange format for open-loop command
//! sequences (playback flight software, the hifi runner, training excitation, validation).
//!
//! ```text
//! t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4
//! 0.0,800,800,800,800,1,1,1,1
//! 2.5,400,400,400,400,1,1,0,0
//! ```
//! `t` in seconds (strictly increasing, first row at or before 0 is not required), thrust
//! commands in newtons, engine switches 0 or 1. A row holds until the next row's time;
//! before the first row every engine is off.
//!
//! Lives in `oils-shared` because both processes and every offline tool read it, and it
//! is nothing but a list of commands: the one other format a flight-code author meets.

use crate::ENGINE_COUNT;
use std::fmt::Write as _;

/// Header line of a profile CSV.
pub const PROFILE_HEADER: &str = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4";

/// One row: from `t_ns` on, command these thrusts and switches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileRow {
    /// Start time of the row, integer nanoseconds.
    pub t_ns: i64,
    /// Thrust command per engine, newtons.
    pub thrust_cmd_n: [f64; ENGINE_COUNT],
    /// Engine on/off.
    pub on: [bool; ENGINE_COUNT],
}

/// A profile could not be read.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileError {
    /// 1-based line number (0: the file as a whole).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl core::fmt::Display for ProfileError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.line == 0 {
            write!(f, "profile: {}", self.message)
        } else {
            write!(f, "profile line {}: {}", self.line, self.message)
        }
    }
}

impl std::error::Error for ProfileError {}

/// A parsed thrust-command profile, rows sorted by strictly increasing time.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ThrustProfile {
    rows: Vec<ProfileRow>,
}

impl ThrustProfile {
    /// A profile from rows; they must be in strictly increasing time with finite,
    /// non-negative thrusts.
    pub fn from_rows(rows: Vec<ProfileRow>) -> Result<Self, ProfileError> {
        if rows.is_empty() {
            return Err(ProfileError {
                line: 0,
                message: "no rows".into(),
            });
        }
        for (i, w) in rows.windows(2).enumerate() {
            if w[1].t_ns <= w[0].t_ns {
                return Err(ProfileError {
                    line: i + 3,
                    message: format!(
                        "time {} s is not after the previous row",
                        w[1].t_ns as f64 * 1e-9
                    ),
                });
            }
        }
        for (i, r) in rows.iter().enumerate() {
            if r.thrust_cmd_n.iter().any(|c| !c.is_finite() || *c < 0.0) {
                return Err(ProfileError {
                    line: i + 2,
                    message: "thrust commands must be finite and >= 0 N".into(),
                });
            }
        }
        Ok(Self { rows })
    }

    /// Parses CSV text (header line first).
    pub fn parse(text: &str) -> Result<Self, ProfileError> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        match lines.next() {
            Some((_, h)) if h.trim().replace(' ', "") == PROFILE_HEADER => {}
            Some((i, h)) => {
                return Err(ProfileError {
                    line: i + 1,
                    message: format!("expected header `{PROFILE_HEADER}`, found `{}`", h.trim()),
                })
            }
            None => {
                return Err(ProfileError {
                    line: 0,
                    message: "empty file".into(),
                })
            }
        }
        let mut rows = Vec::new();
        for (i, line) in lines {
            let err = |message: String| ProfileError {
                line: i + 1,
                message,
            };
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != 9 {
                return Err(err(format!("expected 9 fields, found {}", fields.len())));
            }
            let num = |s: &str, what: &str| -> Result<f64, ProfileError> {
                let v: f64 = s
                    .parse()
                    .map_err(|_| err(format!("{what}: `{s}` is not a number")))?;
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(err(format!("{what}: `{s}` is not finite")))
                }
            };
            let t_s = num(fields[0], "t")?;
            if t_s.abs() > 1e9 {
                return Err(err(format!("t: {t_s} s is out of range")));
            }
            let mut row = ProfileRow {
                t_ns: (t_s * 1e9).round() as i64,
                thrust_cmd_n: [0.0; ENGINE_COUNT],
                on: [false; ENGINE_COUNT],
            };
            for e in 0..ENGINE_COUNT {
                row.thrust_cmd_n[e] = num(fields[1 + e], "cmd")?;
                row.on[e] = match fields[5 + e] {
                    "0" => false,
                    "1" => true,
                    other => return Err(err(format!("on{}: `{other}` is not 0 or 1", e + 1))),
                };
            }
            rows.push(row);
        }
        Self::from_rows(rows)
    }

    /// Reads and parses a file.
    pub fn load(path: &std::path::Path) -> Result<Self, ProfileError> {
        let text = std::fs::read_to_string(path).map_err(|e| ProfileError {
            line: 0,
            message: format!("cannot read {}: {e}", path.display()),
        })?;
        Self::parse(&text)
    }

    /// The rows.
    pub fn rows(&self) -> &[ProfileRow] {
        &self.rows
    }

    /// Time of the last row, nanoseconds.
    pub fn end_ns(&self) -> i64 {
        self.rows.last().map_or(0, |r| r.t_ns)
    }

    /// The row in force at `t_ns` (rows hold until the next), or `None` before the first.
    /// Binary search: no allocation, O(log n).
    pub fn at(&self, t_ns: i64) -> Option<&ProfileRow> {
        let idx = self.rows.partition_point(|r| r.t_ns <= t_ns);
        idx.checked_sub(1).map(|i| &self.rows[i])
    }

    /// Writes the profile as CSV text.
    pub fn to_csv(&self) -> String {
        let mut s = String::with_capacity(64 * (self.rows.len() + 1));
        s.push_str(PROFILE_HEADER);
        s.push('\n');
        for r in &self.rows {
            write_seconds(&mut s, r.t_ns);
            for c in r.thrust_cmd_n {
                let _ = write!(s, ",{c}");
            }
            for o in r.on {
                let _ = write!(s, ",{}", o as u8);
            }
            s.push('\n');
        }
        s
    }
}

/// Writes integer nanoseconds as exact decimal seconds (`894.3`, not the float
/// `894.3000000000001`), so profiles read back to the same nanosecond.
fn write_seconds(s: &mut String, t_ns: i64) {
    if t_ns < 0 {
        s.push('-');
    }
    let abs = t_ns.unsigned_abs();
    let (secs, nanos) = (abs / 1_000_000_000, abs % 1_000_000_000);
    let _ = write!(s, "{secs}");
    if nanos != 0 {
        let frac = format!("{nanos:09}");
        let _ = write!(s, ".{}", frac.trim_end_matches('0'));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,800,800,800,800,1,1,1,1\n2.5,400,400,400,400,1,1,0,0\n";

    #[test]
    fn parses_and_holds_between_rows() {
        let p = ThrustProfile::parse(TEXT).unwrap();
        assert!(p.at(-1).is_none());
        assert_eq!(p.at(0).unwrap().thrust_cmd_n[0], 800.0);
        assert_eq!(p.at(2_499_999_999).unwrap().thrust_cmd_n[0], 800.0);
        let r = p.at(2_500_000_000).unwrap();
        assert_eq!(r.thrust_cmd_n[3], 400.0);
        assert_eq!(r.on, [true, true, false, false]);
        assert_eq!(p.end_ns(), 2_500_000_000);
    }

    #[test]
    fn round_trips_through_csv() {
        let p = ThrustProfile::parse(TEXT).unwrap();
        assert_eq!(ThrustProfile::parse(&p.to_csv()).unwrap(), p);
        let row = |t_ns| ProfileRow {
            t_ns,
            thrust_cmd_n: [1.0; 4],
            on: [true; 4],
        };
        let q = ThrustProfile::from_rows(vec![
            row(-5_000_000),
            row(894_300_000_000),
            row(894_300_000_001),
        ])
        .unwrap();
        let csv = q.to_csv();
        assert!(
            csv.contains("\n-0.005,")
                && csv.contains("\n894.3,")
                && csv.contains("\n894.300000001,"),
            "{csv}"
        );
        assert_eq!(ThrustProfile::parse(&csv).unwrap(), q);
    }

    #[test]
    fn bad_input_names_the_line() {
        let bad_header = "time,a\n0,1\n";
        assert_eq!(ThrustProfile::parse(bad_header).unwrap_err().line, 1);
        let bad_on = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,1,1,1,1,1,1,1,2\n";
        let e = ThrustProfile::parse(bad_on).unwrap_err();
        assert_eq!(e.line, 2);
        assert!(e.message.contains("on4"), "{e}");
        let nan = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,NaN,1,1,1,1,1,1,1\n";
        assert!(ThrustProfile::parse(nan).is_err());
        let backwards =
            "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n1,1,1,1,1,1,1,1,1\n0.5,1,1,1,1,1,1,1,1\n";
        assert_eq!(ThrustProfile::parse(backwards).unwrap_err().line, 3);
        assert!(ThrustProfile::parse("").is_err());
        let short = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,1,1\n";
        assert!(ThrustProfile::parse(short)
            .unwrap_err()
            .message
            .contains("9 fields"));
    }
}
