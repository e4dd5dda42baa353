//! Thrust-command profiles: the bench's CSV exchange format for open-loop command
//! sequences (playback flight software, the hifi runner, training excitation, validation).
//!
//! ```text
//! t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4
//! 0.0,800,800,800,800,1,1,1,1
//! 2.5,400,400,400,400,1,1,0,0
//! ```
//! A row holds until the next row's time; before the first row every engine is off.
//!
//! One reader, one set of rules, for every command (`oils run --fsw playback`,
//! `oils hifi`, `oils validate`, `oils train --descent`, the onboard stub); documented in
//! `docs/profiles.md`:
//! * the file is UTF-8 text of at most [`MAX_PROFILE_BYTES`]; a leading byte-order mark,
//!   `\r\n` line ends and blank lines are allowed; line numbers in errors count every
//!   physical line, blank ones included;
//! * the first non-blank line is the header [`PROFILE_HEADER`] (spaces ignored);
//! * every other non-blank line has 9 comma-separated fields: `t` in seconds, finite, in
//!   `[0, MAX_PROFILE_END_S]`, strictly increasing (after rounding to the nanosecond);
//!   four thrust commands in newtons, finite, in `[0, rating]` (the engine rating:
//!   `scenario.propulsion.max_thrust_n`, [`RATED_THRUST_N`] by default); four switches
//!   `0` or `1`;
//! * between 1 and [`MAX_PROFILE_ROWS`] rows.
//!
//! Errors name the line and the field, and quote at most [`MAX_QUOTED_CHARS`] characters
//! of it.
//!
//! Lives in `oils-shared` because both processes and every offline tool read it, and it
//! is nothing but a list of commands: the one other format a flight-code author meets.

use crate::ENGINE_COUNT;
use std::fmt::Write as _;

/// Header line of a profile CSV.
pub const PROFILE_HEADER: &str = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4";
/// Largest profile file, bytes (a 10 ms profile of a whole descent is ~50 kB).
pub const MAX_PROFILE_BYTES: u64 = 64 << 20;
/// Most rows in a profile.
pub const MAX_PROFILE_ROWS: usize = 1_000_000;
/// Latest row time, seconds (one hour: four times a whole powered descent). It bounds
/// the duration a profile implies (`oils hifi` and `oils validate` run to the last row).
pub const MAX_PROFILE_END_S: f64 = 3600.0;
/// The engine rating profiles are checked against unless a command says otherwise,
/// newtons (the default scenario's `propulsion.max_thrust_n`).
pub const RATED_THRUST_N: f64 = 800.0;
/// Characters of an offending field quoted in an error.
pub const MAX_QUOTED_CHARS: usize = 40;

/// The rules a profile is checked against (beyond the format's own).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileRules {
    /// Highest thrust command, newtons: the engine rating of the run.
    pub max_thrust_n: f64,
}

impl Default for ProfileRules {
    fn default() -> Self {
        Self {
            max_thrust_n: RATED_THRUST_N,
        }
    }
}

impl ProfileRules {
    /// Rules for engines rated `max_thrust_n` newtons.
    pub fn rated(max_thrust_n: f64) -> Self {
        Self { max_thrust_n }
    }
}

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
    /// 1-based line number (0: the file as a whole, or a profile built from rows).
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

/// `s` as quoted in an error: whole if short, else its first [`MAX_QUOTED_CHARS`]
/// characters and its length.
pub fn quoted(s: &str) -> String {
    if s.chars().count() <= MAX_QUOTED_CHARS {
        format!("`{s}`")
    } else {
        let head: String = s.chars().take(MAX_QUOTED_CHARS).collect();
        format!("`{head}...` ({} bytes)", s.len())
    }
}

/// A number as an error shows it: plain when short, else in exponent form (a 1e300 in
/// plain form is 301 digits).
fn shown(v: f64) -> String {
    if v == 0.0 || (1e-3..1e9).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

fn whole(message: impl Into<String>) -> ProfileError {
    ProfileError {
        line: 0,
        message: message.into(),
    }
}

/// A parsed thrust-command profile, rows sorted by strictly increasing time.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ThrustProfile {
    rows: Vec<ProfileRow>,
}

impl ThrustProfile {
    /// A profile from rows (a tool's, not a file's): the file rules but the rating, which
    /// the caller applies: 1 to [`MAX_PROFILE_ROWS`] rows in strictly increasing time
    /// within `[0, MAX_PROFILE_END_S]`, thrusts finite and non-negative. Errors name the
    /// row (1-based).
    pub fn from_rows(rows: Vec<ProfileRow>) -> Result<Self, ProfileError> {
        if rows.is_empty() {
            return Err(whole("no rows"));
        }
        if rows.len() > MAX_PROFILE_ROWS {
            return Err(whole(format!(
                "{} rows; a profile has at most {MAX_PROFILE_ROWS}",
                rows.len()
            )));
        }
        let mut prev: Option<i64> = None;
        for (i, r) in rows.iter().enumerate() {
            let at = |m: String| whole(format!("row {}: {m}", i + 1));
            check_time(r.t_ns, prev).map_err(at)?;
            if r.thrust_cmd_n.iter().any(|c| !c.is_finite() || *c < 0.0) {
                return Err(at("thrust commands must be finite and >= 0 N".into()));
            }
            prev = Some(r.t_ns);
        }
        Ok(Self { rows })
    }

    /// Parses CSV text against the default rules ([`RATED_THRUST_N`]).
    pub fn parse(text: &str) -> Result<Self, ProfileError> {
        Self::parse_with(text, &ProfileRules::default())
    }

    /// Parses CSV text (header line first) against `rules`; see the module's rules.
    pub fn parse_with(text: &str, rules: &ProfileRules) -> Result<Self, ProfileError> {
        if !(rules.max_thrust_n.is_finite() && rules.max_thrust_n > 0.0) {
            return Err(whole(format!(
                "engine rating {} N is not a positive number",
                shown(rules.max_thrust_n)
            )));
        }
        if text.len() as u64 > MAX_PROFILE_BYTES {
            return Err(whole(format!(
                "{} bytes; a profile is at most {MAX_PROFILE_BYTES}",
                text.len()
            )));
        }
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        // Physical line numbers: `enumerate` before dropping blank lines.
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l))
            .filter(|(_, l)| !l.trim().is_empty());
        match lines.next() {
            Some((_, h)) if h.trim().replace(' ', "") == PROFILE_HEADER => {}
            Some((line, h)) => {
                return Err(ProfileError {
                    line,
                    message: format!(
                        "expected header `{PROFILE_HEADER}`, found {}",
                        quoted(h.trim())
                    ),
                })
            }
            None => return Err(whole("empty file")),
        }
        let mut rows = Vec::new();
        let mut prev: Option<i64> = None;
        for (line, text_line) in lines {
            let err = |message: String| ProfileError { line, message };
            if rows.len() == MAX_PROFILE_ROWS {
                return Err(err(format!(
                    "more than {MAX_PROFILE_ROWS} rows; a profile has at most that many"
                )));
            }
            let mut fields = [""; 9];
            let mut n = 0;
            for f in text_line.split(',') {
                if n < fields.len() {
                    fields[n] = f.trim();
                }
                n += 1;
            }
            if n != 9 {
                return Err(err(format!("expected 9 fields, found {n}")));
            }
            let num = |s: &str, what: &str| -> Result<f64, ProfileError> {
                let v: f64 = s
                    .parse()
                    .map_err(|_| err(format!("{what}: {} is not a number", quoted(s))))?;
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(err(format!("{what}: {} is not finite", quoted(s))))
                }
            };
            let t_s = num(fields[0], "t")?;
            if !(0.0..=MAX_PROFILE_END_S).contains(&t_s) {
                return Err(err(format!(
                    "t: {} s is outside [0, {MAX_PROFILE_END_S}] s",
                    shown(t_s)
                )));
            }
            let t_ns = (t_s * 1e9).round() as i64;
            check_time(t_ns, prev).map_err(err)?;
            prev = Some(t_ns);
            let mut row = ProfileRow {
                t_ns,
                thrust_cmd_n: [0.0; ENGINE_COUNT],
                on: [false; ENGINE_COUNT],
            };
            for e in 0..ENGINE_COUNT {
                let what = format!("cmd{}", e + 1);
                let c = num(fields[1 + e], &what)?;
                if !(0.0..=rules.max_thrust_n).contains(&c) {
                    return Err(err(format!(
                        "{what}: {} N is outside [0, {}] N (the engine rating)",
                        shown(c),
                        shown(rules.max_thrust_n)
                    )));
                }
                row.thrust_cmd_n[e] = c;
                row.on[e] = match fields[5 + e] {
                    "0" => false,
                    "1" => true,
                    other => {
                        return Err(err(format!("on{}: {} is not 0 or 1", e + 1, quoted(other))))
                    }
                };
            }
            rows.push(row);
        }
        if rows.is_empty() {
            return Err(whole("no rows after the header"));
        }
        Ok(Self { rows })
    }

    /// Reads and parses a file against the default rules ([`RATED_THRUST_N`]).
    pub fn load(path: &std::path::Path) -> Result<Self, ProfileError> {
        Self::load_with(path, &ProfileRules::default())
    }

    /// Reads (at most [`MAX_PROFILE_BYTES`]) and parses a file against `rules`.
    pub fn load_with(path: &std::path::Path, rules: &ProfileRules) -> Result<Self, ProfileError> {
        use std::io::Read;
        let cannot =
            |e: &dyn core::fmt::Display| whole(format!("cannot read {}: {e}", path.display()));
        let file = std::fs::File::open(path).map_err(|e| cannot(&e))?;
        let mut bytes = Vec::new();
        // One byte more than allowed tells "too large" without reading a huge file whole.
        file.take(MAX_PROFILE_BYTES + 1)
            .read_to_end(&mut bytes)
            .map_err(|e| cannot(&e))?;
        if bytes.len() as u64 > MAX_PROFILE_BYTES {
            return Err(whole(format!(
                "{} is larger than {MAX_PROFILE_BYTES} bytes, the largest profile",
                path.display()
            )));
        }
        let text = String::from_utf8(bytes).map_err(|e| {
            whole(format!(
                "{} is not UTF-8 text (byte {})",
                path.display(),
                e.utf8_error().valid_up_to()
            ))
        })?;
        Self::parse_with(&text, rules)
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

/// A row time in `[0, MAX_PROFILE_END_S]` and after the previous row's.
fn check_time(t_ns: i64, prev: Option<i64>) -> Result<(), String> {
    let max_ns = (MAX_PROFILE_END_S * 1e9) as i64;
    if !(0..=max_ns).contains(&t_ns) {
        return Err(format!(
            "t: {} s is outside [0, {MAX_PROFILE_END_S}] s",
            t_ns as f64 * 1e-9
        ));
    }
    if let Some(p) = prev {
        if t_ns <= p {
            return Err(format!(
                "t: {} s is not after the previous row's {} s",
                t_ns as f64 * 1e-9,
                p as f64 * 1e-9
            ));
        }
    }
    Ok(())
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
            row(5_000_000),
            row(894_300_000_000),
            row(894_300_000_001),
        ])
        .unwrap();
        let csv = q.to_csv();
        assert!(
            csv.contains("\n0.005,")
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

    const H: &str = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n";

    /// Issue #24: line numbers were wrong after blank lines.
    #[test]
    fn line_numbers_count_blank_lines() {
        let text = format!("\n{H}\n0,1,1,1,1,1,1,1,1\n\n\n1,1,1,1,1,1,1,1,x\n");
        let e = ThrustProfile::parse(&text).unwrap_err();
        assert_eq!(e.line, 7, "{e}");
        let text = format!("{H}\n\n2,1,1,1,1,1,1,1,1\n\n1,1,1,1,1,1,1,1,1\n");
        let e = ThrustProfile::parse(&text).unwrap_err();
        assert_eq!(e.line, 6, "{e}");
        let text = format!("{H}\r\n0,1,1,1,1,1,1,1,1\r\n\r\n0,1,1,1,1,1,1,1,1\r\n");
        assert_eq!(ThrustProfile::parse(&text).unwrap_err().line, 5);
        let bom = format!("{}{H}0,1,1,1,1,1,1,1,1\n", '\u{feff}');
        assert_eq!(ThrustProfile::parse(&bom).unwrap().rows().len(), 1);
    }

    /// Issue #24: thrust above the rating and negative times were accepted by two
    /// commands and refused by one; now the reader refuses them for all.
    #[test]
    fn one_set_of_rules() {
        let over = format!("{H}0,900,1,1,1,1,1,1,1\n");
        let e = ThrustProfile::parse(&over).unwrap_err();
        assert_eq!(e.line, 2);
        assert!(
            e.message.contains("cmd1") && e.message.contains("800"),
            "{e}"
        );
        assert!(ThrustProfile::parse_with(&over, &ProfileRules::rated(1000.0)).is_ok());
        let negative = format!("{H}-1,1,1,1,1,1,1,1,1\n0,1,1,1,1,1,1,1,1\n");
        let e = ThrustProfile::parse(&negative).unwrap_err();
        assert!(
            e.line == 2 && e.message.contains("outside [0, 3600]"),
            "{e}"
        );
        let late = format!("{H}0,1,1,1,1,1,1,1,1\n100000,1,1,1,1,1,1,1,1\n");
        let e = ThrustProfile::parse(&late).unwrap_err();
        assert!(e.line == 3 && e.message.contains("3600"), "{e}");
        assert!(ThrustProfile::parse(&format!("{H}0,-1,1,1,1,1,1,1,1\n")).is_err());
        assert!(ThrustProfile::parse(H).is_err());
        // Rows that round to the same nanosecond are not increasing.
        let same = format!("{H}1,1,1,1,1,1,1,1,1\n1.0000000001,1,1,1,1,1,1,1,1\n");
        assert_eq!(ThrustProfile::parse(&same).unwrap_err().line, 3);
    }

    /// Found by the property test: a time of 1e300 was printed as 301 digits.
    #[test]
    fn huge_numbers_are_shown_short() {
        for text in [
            format!("{H}1e300,0,0,0,0,0,0,0,0\n"),
            format!("{H}0,1e300,0,0,0,0,0,0,0\n"),
            format!("{H}0,-1e-300,0,0,0,0,0,0,0\n"),
        ] {
            let e = ThrustProfile::parse(&text).unwrap_err().to_string();
            assert!(e.len() < 100, "{e}");
        }
    }

    /// Issue #24: an error echoed a 20 MB field whole.
    #[test]
    fn errors_quote_at_most_a_few_characters() {
        let long = "9".repeat(100_000) + "x";
        for text in [
            format!("{H}{long},1,1,1,1,1,1,1,1\n"),
            format!("{H}0,1,1,1,1,1,1,1,{long}\n"),
            format!("{long}\n"),
        ] {
            let e = ThrustProfile::parse(&text).unwrap_err().to_string();
            assert!(e.len() < 200, "{} bytes: {}", e.len(), &e[..200]);
            assert!(e.contains("100001 bytes"), "{e}");
        }
        let many = format!("{H}0{}\n", ",1".repeat(100_000));
        let e = ThrustProfile::parse(&many).unwrap_err().to_string();
        assert!(e.contains("found 100001") && e.len() < 100, "{e}");
    }

    #[test]
    fn size_and_row_counts_are_capped() {
        let path =
            std::env::temp_dir().join(format!("oils-profile-big-{}.csv", std::process::id()));
        let f = std::fs::File::create(&path).unwrap();
        f.set_len(MAX_PROFILE_BYTES + 10).unwrap();
        let e = ThrustProfile::load(&path).unwrap_err();
        assert!(e.message.contains("larger than"), "{e}");
        std::fs::remove_file(&path).ok();
        let row = |i: usize| ProfileRow {
            t_ns: i as i64,
            thrust_cmd_n: [0.0; 4],
            on: [false; 4],
        };
        let rows: Vec<ProfileRow> = (0..=MAX_PROFILE_ROWS).map(row).collect();
        assert!(ThrustProfile::from_rows(rows).is_err());
        let text = format!(
            "{H}{}",
            (0..=MAX_PROFILE_ROWS)
                .map(|i| format!("{}e-9,0,0,0,0,0,0,0,0\n", i))
                .collect::<String>()
        );
        let e = ThrustProfile::parse(&text).unwrap_err();
        assert!(e.message.contains("more than"), "{e}");
    }
}
