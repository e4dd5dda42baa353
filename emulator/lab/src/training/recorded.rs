//! Training data from recorded time series: a hot-fire test or a run of the user's own
//! model, as CSV in the layout of `docs/recorded-data.md` (what `oils hifi --profile P
//! --out F.csv` writes is one such file), resampled to the surrogate's sample time.
//!
//! A row at `t_s` holds the state at that time and the command held over the step that
//! ended there; the first row is the initial state (its command is not used). The file's
//! own step must be uniform and divide the sample time: the state is kept every
//! `sample / step` rows, and a sample's input is the command held over its first row
//! (the command a sampled controller applied at the sample's start). Files are read
//! line by line, so a long recording needs no more memory than its samples.

use super::dataset::Dataset;
use oils_emulator::propulsion::surrogate::features::{
    InputVec, StateVec, INPUT_DIM, STATE_DIM, STATE_MF, STATE_MO,
};
use oils_emulator::propulsion::surrogate::model_file::ReferenceOutput;
use oils_shared::ENGINE_COUNT;
use std::io::BufRead;
use std::path::{Path, PathBuf};

/// The columns a recorded file must have (any order; other columns are ignored).
pub const REQUIRED_COLUMNS: [&str; 1 + 2 * ENGINE_COUNT + STATE_DIM] = [
    "t_s",
    "cmd1_n",
    "cmd2_n",
    "cmd3_n",
    "cmd4_n",
    "on1",
    "on2",
    "on3",
    "on4",
    "thrust1_n",
    "thrust2_n",
    "thrust3_n",
    "thrust4_n",
    "gas_pressure_pa",
    "ejected_fuel_kg",
    "ejected_ox_kg",
];
/// Optional columns: the tank pressures the surrogate reports but does not model (the
/// first row's values are held); 0 when absent.
pub const OPTIONAL_COLUMNS: [&str; 2] = ["fuel_tank_pa", "ox_tank_pa"];

/// A step may differ from the file's step by this fraction (clock jitter of a recorder).
pub const STEP_JITTER_FRAC: f64 = 0.01;
/// A step longer than this many file steps is a gap (a lost stretch of data).
pub const GAP_STEPS: f64 = 1.5;

/// Why a recorded file was refused. Lines are 1-based physical lines; columns 1-based
/// fields.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file has no header line.
    #[error("{path}: no header line (the layout: docs/recorded-data.md)")]
    NoHeader {
        /// The file.
        path: String,
    },
    /// A required column is not in the header.
    #[error("{path}: line {line}: missing column `{column}` (the layout: docs/recorded-data.md)")]
    MissingColumn {
        /// The file.
        path: String,
        /// The header's line.
        line: usize,
        /// The column's name.
        column: &'static str,
    },
    /// A column is named twice.
    #[error("{path}: line {line}: column `{column}` appears twice (fields {first} and {second})")]
    DuplicateColumn {
        /// The file.
        path: String,
        /// The header's line.
        line: usize,
        /// The column's name.
        column: String,
        /// Its first field.
        first: usize,
        /// Its second field.
        second: usize,
    },
    /// A row has another number of fields than the header.
    #[error("{path}: line {line}: {found} fields, the header has {expected}")]
    FieldCount {
        /// The file.
        path: String,
        /// The row's line.
        line: usize,
        /// Fields found.
        found: usize,
        /// Fields in the header.
        expected: usize,
    },
    /// A value is not a finite number (or not 0/1 for a switch).
    #[error("{path}: line {line}, column {column} (`{name}`): {why}")]
    Value {
        /// The file.
        path: String,
        /// The row's line.
        line: usize,
        /// The field, 1-based.
        column: usize,
        /// The column's name.
        name: &'static str,
        /// What is wrong, quoting the text.
        why: String,
    },
    /// Time does not increase.
    #[error("{path}: line {line}, column {column} (`t_s`): {t_s} s is not after the previous row's {prev_s} s")]
    TimeNotIncreasing {
        /// The file.
        path: String,
        /// The row's line.
        line: usize,
        /// The field of `t_s`.
        column: usize,
        /// The row's time.
        t_s: f64,
        /// The previous row's time.
        prev_s: f64,
    },
    /// Rows are missing between two times.
    #[error("{path}: line {line}: a gap: {prev_s} s to {t_s} s, {steps:.1} of the file's {step_s} s steps (resample the recording onto a uniform grid first)")]
    Gap {
        /// The file.
        path: String,
        /// The row after the gap.
        line: usize,
        /// The row's time.
        t_s: f64,
        /// The previous row's time.
        prev_s: f64,
        /// The gap in file steps.
        steps: f64,
        /// The file's step, s.
        step_s: f64,
    },
    /// A step is neither the file's step nor a gap.
    #[error("{path}: line {line}: the step {got_s} s from {prev_s} s differs from the file's {step_s} s by more than {pct} % (the rows must be uniform in time)", pct = STEP_JITTER_FRAC * 100.0)]
    IrregularStep {
        /// The file.
        path: String,
        /// The row.
        line: usize,
        /// The step found, s.
        got_s: f64,
        /// The previous row's time.
        prev_s: f64,
        /// The file's step, s.
        step_s: f64,
    },
    /// The surrogate's sample time is not a whole number of the file's steps.
    #[error("{path}: the surrogate's sample time {sample_s} s is not a whole multiple of the file's step {step_s} s (set sample_time_ns in the training configuration to a multiple)")]
    SampleTime {
        /// The file.
        path: String,
        /// Sample time, s.
        sample_s: f64,
        /// The file's step, s.
        step_s: f64,
    },
    /// Too few rows for one sample.
    #[error("{path}: {rows} data rows make no whole sample of {sample_s} s (at least two rows, one sample time apart, are needed)")]
    TooShort {
        /// The file.
        path: String,
        /// Data rows read.
        rows: usize,
        /// Sample time, s.
        sample_s: f64,
    },
}

/// One recorded file, resampled.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedRun {
    /// The file.
    pub path: PathBuf,
    /// Its samples (no valve filter tracked yet).
    pub dataset: Dataset,
    /// The tank pressures of its first row (0 where the file has no such column).
    pub reference_output: ReferenceOutput,
    /// The file's own step, nanoseconds.
    pub file_step_ns: u64,
    /// Data rows read.
    pub rows: usize,
    /// Rows after the last whole sample, not used.
    pub dropped_rows: usize,
}

/// Column indices of the header.
struct Columns {
    /// Field of each required column, in [`REQUIRED_COLUMNS`] order.
    required: [usize; REQUIRED_COLUMNS.len()],
    /// Field of each optional column, if present.
    optional: [Option<usize>; OPTIONAL_COLUMNS.len()],
    /// Fields in the header.
    count: usize,
}

fn columns(path: &str, line: usize, header: &str) -> Result<Columns, DataError> {
    let names: Vec<&str> = header
        .trim_start_matches('\u{feff}')
        .split(',')
        .map(str::trim)
        .collect();
    for (i, n) in names.iter().enumerate() {
        if let Some(j) = names[..i].iter().position(|m| m == n) {
            return Err(DataError::DuplicateColumn {
                path: path.into(),
                line,
                column: (*n).to_string(),
                first: j + 1,
                second: i + 1,
            });
        }
    }
    let find = |c: &str| names.iter().position(|n| *n == c);
    let mut required = [0; REQUIRED_COLUMNS.len()];
    for (slot, c) in required.iter_mut().zip(REQUIRED_COLUMNS) {
        *slot = find(c).ok_or(DataError::MissingColumn {
            path: path.into(),
            line,
            column: c,
        })?;
    }
    Ok(Columns {
        required,
        optional: OPTIONAL_COLUMNS.map(find),
        count: names.len(),
    })
}

/// One parsed data row.
#[derive(Clone, Copy)]
struct Row {
    t_ns: i64,
    input: InputVec,
    state: StateVec,
    tanks: [f64; 2],
}

fn quote(text: &str) -> String {
    const MAX: usize = 40;
    if text.chars().count() <= MAX {
        format!("`{text}`")
    } else {
        let cut: String = text.chars().take(MAX).collect();
        format!("`{cut}...` ({} characters)", text.chars().count())
    }
}

fn parse_row(path: &str, line: usize, text: &str, cols: &Columns) -> Result<Row, DataError> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    if fields.len() != cols.count {
        return Err(DataError::FieldCount {
            path: path.into(),
            line,
            found: fields.len(),
            expected: cols.count,
        });
    }
    let value = |k: usize, field: usize, name: &'static str| -> Result<f64, DataError> {
        let bad = |why: String| DataError::Value {
            path: path.into(),
            line,
            column: field + 1,
            name,
            why,
        };
        let raw = fields[field];
        let v: f64 = raw
            .parse()
            .map_err(|_| bad(format!("{} is not a number", quote(raw))))?;
        if !v.is_finite() {
            return Err(bad(format!("{} is not a finite number", quote(raw))));
        }
        // The switches: 0 or 1.
        if (1 + ENGINE_COUNT..1 + 2 * ENGINE_COUNT).contains(&k) && v != 0.0 && v != 1.0 {
            return Err(bad(format!("{} is not 0 or 1", quote(raw))));
        }
        if k == 0 && v.abs() > 1e9 {
            return Err(bad(format!("{} s is beyond 1e9 s", quote(raw))));
        }
        Ok(v)
    };
    let mut v = [0.0; REQUIRED_COLUMNS.len()];
    for (k, (&field, name)) in cols.required.iter().zip(REQUIRED_COLUMNS).enumerate() {
        v[k] = value(k, field, name)?;
    }
    let mut tanks = [0.0; 2];
    for (t, (field, name)) in tanks
        .iter_mut()
        .zip(cols.optional.iter().zip(OPTIONAL_COLUMNS))
    {
        if let Some(f) = field {
            // `value` checks finiteness; index past the switches so no 0/1 rule applies.
            *t = value(usize::MAX, *f, name)?;
        }
    }
    let mut input = [0.0; INPUT_DIM];
    for e in 0..ENGINE_COUNT {
        let on = v[1 + ENGINE_COUNT + e] > 0.5;
        // A switched-off engine's command reads 0, as the surrogate's input does.
        input[e] = if on { v[1 + e] } else { 0.0 };
        input[ENGINE_COUNT + e] = f64::from(u8::from(on));
    }
    let mut state = [0.0; STATE_DIM];
    state.copy_from_slice(&v[1 + 2 * ENGINE_COUNT..]);
    Ok(Row {
        t_ns: (v[0] * 1e9).round() as i64,
        input,
        state,
        tanks,
    })
}

/// Reads one recorded file from `reader` (named `path` in errors), resampled to
/// `sample_time_ns`.
pub fn read(
    reader: impl BufRead,
    path: &Path,
    sample_time_ns: u64,
) -> Result<RecordedRun, DataError> {
    let shown = path.display().to_string();
    let io = |source| DataError::Io {
        path: shown.clone(),
        source,
    };
    let mut lines = reader.lines().enumerate();
    // Header: the first line that is neither blank nor a `#` comment.
    let cols = loop {
        let Some((i, l)) = lines.next() else {
            return Err(DataError::NoHeader { path: shown });
        };
        let l = l.map_err(io)?;
        if !l.trim().is_empty() && !l.trim_start().starts_with('#') {
            break columns(&shown, i + 1, &l)?;
        }
    };
    let t_field = cols.required[0];
    let sample_s = sample_time_ns as f64 / 1e9;
    let mut first: Option<Row> = None;
    let mut prev: Option<Row> = None;
    let mut step_ns = 0i64;
    let mut per_sample = 0usize;
    let mut rows = 0usize;
    let mut inputs = Vec::new();
    let mut states = Vec::new();
    let mut pending_input: Option<InputVec> = None;
    for (i, l) in lines {
        let line = i + 1;
        let l = l.map_err(io)?;
        if l.trim().is_empty() || l.trim_start().starts_with('#') {
            continue;
        }
        let row = parse_row(&shown, line, &l, &cols)?;
        if let Some(p) = prev {
            let dt = row.t_ns - p.t_ns;
            let (t_s, prev_s) = (row.t_ns as f64 / 1e9, p.t_ns as f64 / 1e9);
            if dt <= 0 {
                return Err(DataError::TimeNotIncreasing {
                    path: shown,
                    line,
                    column: t_field + 1,
                    t_s,
                    prev_s,
                });
            }
            if rows == 1 {
                // The second row sets the file's step, and with it the decimation.
                step_ns = dt;
                let ratio = sample_time_ns as f64 / dt as f64;
                let whole = ratio.round();
                if whole < 1.0 || (ratio - whole).abs() > 1e-6 * whole {
                    return Err(DataError::SampleTime {
                        path: shown,
                        sample_s,
                        step_s: dt as f64 / 1e9,
                    });
                }
                per_sample = whole as usize;
            } else {
                let off = (dt - step_ns) as f64 / step_ns as f64;
                let step_s = step_ns as f64 / 1e9;
                if dt as f64 > GAP_STEPS * step_ns as f64 {
                    return Err(DataError::Gap {
                        path: shown,
                        line,
                        t_s,
                        prev_s,
                        steps: dt as f64 / step_ns as f64,
                        step_s,
                    });
                }
                if off.abs() > STEP_JITTER_FRAC {
                    return Err(DataError::IrregularStep {
                        path: shown,
                        line,
                        got_s: dt as f64 / 1e9,
                        prev_s,
                        step_s,
                    });
                }
            }
            // Row `rows` ends file step `rows - 1`: the first of a sample holds its input,
            // the last its state.
            let within = (rows - 1) % per_sample;
            if within == 0 {
                pending_input = Some(row.input);
            }
            if within == per_sample - 1 {
                if let Some(input) = pending_input.take() {
                    inputs.push(input);
                    states.push(row.state);
                }
            }
        } else {
            first = Some(row);
        }
        prev = Some(row);
        rows += 1;
    }
    let Some(first) = first.filter(|_| !states.is_empty()) else {
        return Err(DataError::TooShort {
            path: shown,
            rows,
            sample_s,
        });
    };
    Ok(RecordedRun {
        path: path.to_path_buf(),
        dataset: Dataset {
            sample_time_ns,
            initial: first.state,
            inputs,
            states: states.clone(),
            valve_filter: None,
            valves: Vec::new(),
        },
        reference_output: ReferenceOutput {
            fuel_tank_pressure_pa: first.tanks[0],
            ox_tank_pressure_pa: first.tanks[1],
        },
        file_step_ns: step_ns as u64,
        rows,
        dropped_rows: rows - 1 - states.len() * per_sample.max(1),
    })
}

/// Reads one recorded file from disk.
pub fn load(path: &Path, sample_time_ns: u64) -> Result<RecordedRun, DataError> {
    let file = std::fs::File::open(path).map_err(|source| DataError::Io {
        path: path.display().to_string(),
        source,
    })?;
    read(std::io::BufReader::new(file), path, sample_time_ns)
}

/// Joins recorded runs end to end, in order, into one dataset: the first run's initial
/// state starts it, and each later run's ejected masses are offset so they stay
/// cumulative (the run then continues from where the masses were). Thrust and gas
/// pressure jump at a join: the few samples after it whose history reaches across are
/// kept (a history is at most `cv.history_max` samples).
pub fn join(runs: &[RecordedRun]) -> Option<(Dataset, ReferenceOutput)> {
    let first = runs.first()?;
    let mut d = first.dataset.clone();
    for r in &runs[1..] {
        let last = *d.states.last().unwrap_or(&d.initial);
        let offset = [
            last[STATE_MF] - r.dataset.initial[STATE_MF],
            last[STATE_MO] - r.dataset.initial[STATE_MO],
        ];
        d.inputs.extend_from_slice(&r.dataset.inputs);
        d.states.extend(r.dataset.states.iter().map(|s| {
            let mut s = *s;
            s[STATE_MF] += offset[0];
            s[STATE_MO] += offset[1];
            s
        }));
    }
    Some((d, first.reference_output))
}

/// The provenance hash of recorded files: BLAKE3 over each file's name length, name and
/// bytes, in order.
pub fn hash_files(paths: &[PathBuf]) -> Result<String, DataError> {
    let mut h = blake3::Hasher::new();
    for p in paths {
        let mut f = std::fs::File::open(p).map_err(|source| DataError::Io {
            path: p.display().to_string(),
            source,
        })?;
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
        let name = name.unwrap_or_default();
        h.update(&(name.len() as u64).to_le_bytes());
        h.update(name.as_bytes());
        let mut buf = [0u8; 64 * 1024];
        loop {
            let n = std::io::Read::read(&mut f, &mut buf).map_err(|source| DataError::Io {
                path: p.display().to_string(),
                source,
            })?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
        }
    }
    Ok(h.finalize().to_hex().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "t_s,cmd1_n,cmd2_n,cmd3_n,cmd4_n,on1,on2,on3,on4,thrust1_n,thrust2_n,thrust3_n,thrust4_n,gas_pressure_pa,ejected_fuel_kg,ejected_ox_kg";

    /// `n` rows every `step_s`; thrust = row index, masses grow by 0.1 per row.
    fn file(n: usize, step_s: f64) -> String {
        let mut s = format!("{HEADER}\n");
        for k in 0..n {
            let on = u8::from(!k.is_multiple_of(3));
            s.push_str(&format!(
                "{},{c},{c},{c},{c},{on},1,1,1,{k},{k},{k},{k},2e7,{m},{m}\n",
                k as f64 * step_s,
                c = 400 + k,
                m = 0.1 * k as f64
            ));
        }
        s
    }

    fn read_str(text: &str, sample_ns: u64) -> Result<RecordedRun, DataError> {
        read(text.as_bytes(), Path::new("rec.csv"), sample_ns)
    }

    #[test]
    fn one_row_per_sample_is_taken_as_it_is() {
        let r = read_str(&file(5, 0.01), 10_000_000).unwrap();
        let d = &r.dataset;
        assert_eq!(d.len(), 4);
        assert_eq!(d.initial[0], 0.0);
        // Row k ends step k - 1: its command is that step's input, its state the result.
        assert_eq!(d.inputs[0][0], 0.0 + 401.0);
        assert_eq!(d.states[0][0], 1.0);
        // Row 3 has engine 1 off: its command reads 0.
        assert_eq!(d.inputs[2][0], 0.0);
        assert_eq!(d.inputs[2][ENGINE_COUNT], 0.0);
        assert_eq!(r.dropped_rows, 0);
        assert_eq!(r.reference_output.fuel_tank_pressure_pa, 0.0);
    }

    #[test]
    fn a_finer_file_is_decimated() {
        // 1 ms rows, 10 ms samples: state every 10th row, input from each sample's first.
        let r = read_str(&file(26, 0.001), 10_000_000).unwrap();
        let d = &r.dataset;
        assert_eq!(d.len(), 2);
        assert_eq!(d.states[0][0], 10.0);
        assert_eq!(d.states[1][0], 20.0);
        assert_eq!(d.inputs[0][1], 401.0);
        assert_eq!(d.inputs[1][1], 411.0);
        assert_eq!(r.file_step_ns, 1_000_000);
        assert_eq!(r.dropped_rows, 5);
    }

    #[test]
    fn columns_in_any_order_and_extra_ones_are_read() {
        let text = file(3, 0.01);
        let mut out = String::new();
        for l in text.lines() {
            let mut f: Vec<&str> = l.split(',').collect();
            f.reverse();
            out.push_str(&format!("{},extra\n", f.join(",")));
        }
        let out = out
            .replacen(",extra\n", ",fuel_tank_pa\n", 1)
            .replace(",extra", ",1.5e6");
        let r = read_str(&out, 10_000_000).unwrap();
        assert_eq!(r.dataset, read_str(&text, 10_000_000).unwrap().dataset);
        assert_eq!(r.reference_output.fuel_tank_pressure_pa, 1.5e6);
    }

    fn err(text: &str, sample_ns: u64) -> String {
        read_str(text, sample_ns).unwrap_err().to_string()
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let good = file(5, 0.01);
        // A missing column.
        let e = err(&good.replace("gas_pressure_pa", "gas_pa"), 10_000_000);
        assert_eq!(
            e,
            "rec.csv: line 1: missing column `gas_pressure_pa` (the layout: docs/recorded-data.md)"
        );
        // A non-finite value: line 3 (second data row), field 14.
        let bad = good
            .replacen(",2e7,", ",NaN,", 2)
            .replacen(",NaN,", ",2e7,", 1);
        assert_eq!(
            err(&bad, 10_000_000),
            "rec.csv: line 3, column 14 (`gas_pressure_pa`): `NaN` is not a finite number"
        );
        let bad = good.replacen(",2e7,", ",abc,", 1);
        assert!(err(&bad, 10_000_000)
            .contains("line 2, column 14 (`gas_pressure_pa`): `abc` is not a number"));
        // A switch that is not 0/1.
        let bad = good.replacen("\n0.01,401,401,401,401,1,", "\n0.01,401,401,401,401,2,", 1);
        assert!(err(&bad, 10_000_000).contains("(`on1`): `2` is not 0 or 1"));
        // Time not increasing.
        let bad = good.replace("\n0.03,", "\n0.02,");
        assert_eq!(
            err(&bad, 10_000_000),
            "rec.csv: line 5, column 1 (`t_s`): 0.02 s is not after the previous row's 0.02 s"
        );
        // A gap.
        let bad = good
            .replace("\n0.03,", "\n0.05,")
            .replace("\n0.04,", "\n0.06,");
        assert!(err(&bad, 10_000_000).starts_with("rec.csv: line 5: a gap: 0.02 s to 0.05 s"));
        // An irregular step.
        let bad = good.replace("\n0.03,", "\n0.0312,");
        assert!(err(&bad, 10_000_000).starts_with("rec.csv: line 5: the step"));
        // A sample time that does not fit the file's step.
        assert!(err(&good, 15_000_000)
            .starts_with("rec.csv: the surrogate's sample time 0.015 s is not a whole multiple of the file's step 0.01 s"));
        // Too few rows; a wrong field count; no header.
        assert!(err(&file(1, 0.01), 10_000_000).contains("1 data rows make no whole sample"));
        let bad = good.replacen("\n0.01,", "\n0.01,7,", 1);
        assert_eq!(
            err(&bad, 10_000_000),
            "rec.csv: line 3: 17 fields, the header has 16"
        );
        assert!(err("\n# only a comment\n", 10_000_000).contains("no header line"));
        let dup = good.replacen("on4", "on3", 1);
        assert!(err(&dup, 10_000_000).contains("column `on3` appears twice (fields 8 and 9)"));
    }

    #[test]
    fn joined_runs_keep_masses_cumulative() {
        let a = read_str(&file(3, 0.01), 10_000_000).unwrap();
        let b = read_str(&file(4, 0.01), 10_000_000).unwrap();
        let (d, _) = join(&[a.clone(), b]).unwrap();
        assert_eq!(d.len(), 2 + 3);
        assert_eq!(d.initial, a.dataset.initial);
        // a ends at 0.2 kg; b's first sample (0.1 kg after its start) follows at 0.3.
        assert!((d.states[2][STATE_MF] - 0.3).abs() < 1e-12);
        assert!((d.states[4][STATE_MO] - 0.5).abs() < 1e-12);
        assert_eq!(d.states[2][0], 1.0);
    }
}
