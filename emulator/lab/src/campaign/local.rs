//! The local backend: a campaign's cases in process on all cores (rayon), each result
//! written as it finishes, finished cases skipped, a time budget per case.

use super::case::{case_setup, check_targets, load_uncertainty, run_case, CaseResult};
use super::spec::CampaignSpec;
use super::store::Store;
use super::CampaignError;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A contiguous part of a campaign: shard `index` of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, from 0.
    pub index: u64,
    /// Number of shards.
    pub count: u64,
}

impl Shard {
    /// The case indices of this shard of `cases`: [i n / k, (i + 1) n / k).
    pub fn range(&self, cases: u64) -> std::ops::Range<u64> {
        let at = |i: u64| ((i as u128 * cases as u128) / self.count as u128) as u64;
        at(self.index)..at(self.index + 1)
    }

    /// Parses `I/K`; `I` may be `auto`, read from `SLURM_ARRAY_TASK_ID`,
    /// `PBS_ARRAY_INDEX` or `JOB_COMPLETION_INDEX` (Kubernetes Indexed Jobs).
    pub fn parse(text: &str, env: &dyn Fn(&str) -> Option<String>) -> Result<Self, String> {
        let (i, k) = text
            .split_once('/')
            .ok_or_else(|| format!("--shard `{text}`: expected I/K (e.g. 3/8 or auto/8)"))?;
        let count: u64 = k
            .parse()
            .ok()
            .filter(|k| *k >= 1)
            .ok_or_else(|| format!("--shard `{text}`: K must be a whole number >= 1"))?;
        let index_text = if i == "auto" {
            SHARD_INDEX_VARS
                .iter()
                .find_map(|v| env(v))
                .ok_or_else(|| {
                    format!(
                        "--shard auto/{count}: none of {} is set",
                        SHARD_INDEX_VARS.join(", ")
                    )
                })?
        } else {
            i.to_string()
        };
        let index: u64 = index_text
            .trim()
            .parse()
            .map_err(|_| format!("--shard `{text}`: index `{index_text}` is not a whole number"))?;
        if index >= count {
            return Err(format!(
                "--shard `{text}`: index {index} is not below {count}"
            ));
        }
        Ok(Self { index, count })
    }
}

/// Environment variables a shard index is read from, in this order.
pub const SHARD_INDEX_VARS: [&str; 3] = [
    "SLURM_ARRAY_TASK_ID",
    "PBS_ARRAY_INDEX",
    "JOB_COMPLETION_INDEX",
];

/// How to run.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunOptions {
    /// Worker threads (`None`: one per core).
    pub jobs: Option<usize>,
    /// Only this shard.
    pub shard: Option<Shard>,
}

/// What a finished batch reports.
#[derive(Debug, Clone, Default)]
pub struct BatchReport {
    /// Cases this batch was responsible for.
    pub assigned: u64,
    /// Of them, already done before it started.
    pub skipped: u64,
    /// Run and written now.
    pub ran: u64,
    /// Outcomes of the cases run now.
    pub outcomes: BTreeMap<String, u64>,
    /// Wall time, seconds.
    pub wall_s: f64,
    /// Sum of the cases' own wall times, seconds.
    pub case_wall_s: f64,
    /// Stopped by a stop request before all cases ran.
    pub interrupted: bool,
}

/// A case as it finishes, for progress display.
pub struct Progress<'a> {
    /// Cases finished so far in this batch (including skipped ones).
    pub finished: u64,
    /// Cases of the batch.
    pub total: u64,
    /// The case that just finished.
    pub result: &'a CaseResult,
}

/// One running case's stop flag and budget.
struct Watch {
    stop: AtomicBool,
    timed_out: AtomicBool,
    deadline: Instant,
}

/// Runs the cases of `spec` (or of its shard) that `store` does not hold yet.
/// `stop`: a stop request (signal); the cases it interrupts are not written, so a
/// campaign started again runs them.
pub fn run_cases(
    spec: &CampaignSpec,
    store: &Store,
    options: RunOptions,
    stop: &AtomicBool,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BatchReport, CampaignError> {
    let started = Instant::now();
    check_targets(spec)?;
    let uncertainty = load_uncertainty(spec)?;
    store.open(spec)?;
    let range = options.shard.map_or(0..spec.cases, |s| s.range(spec.cases));
    let done = store.done()?;
    let todo: Vec<u64> = range.clone().filter(|i| !done.contains(i)).collect();
    let mut report = BatchReport {
        assigned: range.end - range.start,
        skipped: (range.end - range.start) - todo.len() as u64,
        ..Default::default()
    };
    let finished = AtomicU64::new(report.skipped);
    let budget = Duration::from_secs_f64(spec.case_timeout_s);
    let watches: Mutex<BTreeMap<u64, Arc<Watch>>> = Mutex::new(BTreeMap::new());
    let all_done = AtomicBool::new(false);
    let results: Mutex<Vec<(String, f64)>> = Mutex::new(Vec::new());
    let first_error: Mutex<Option<CampaignError>> = Mutex::new(None);

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.jobs.unwrap_or(0))
        .thread_name(|i| format!("oils-mc-{i}"))
        .build()
        .map_err(|e| CampaignError::Store(format!("cannot start worker threads: {e}")))?;

    std::thread::scope(|scope| {
        // The watchdog: ends cases over their budget, passes a stop request on.
        scope.spawn(|| {
            while !all_done.load(Ordering::Relaxed) {
                let now = Instant::now();
                let stopping = stop.load(Ordering::Relaxed);
                if let Ok(w) = watches.lock() {
                    for watch in w.values() {
                        if now >= watch.deadline {
                            watch.timed_out.store(true, Ordering::Relaxed);
                            watch.stop.store(true, Ordering::Relaxed);
                        }
                        if stopping {
                            watch.stop.store(true, Ordering::Relaxed);
                        }
                    }
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        });
        pool.install(|| {
            use rayon::prelude::*;
            todo.par_iter().with_max_len(1).for_each(|&index| {
                if stop.load(Ordering::Relaxed) || first_error.lock().is_ok_and(|e| e.is_some()) {
                    return;
                }
                let result = (|| -> Result<Option<CaseResult>, CampaignError> {
                    let setup = case_setup(spec, uncertainty.as_ref(), index)?;
                    let watch = Arc::new(Watch {
                        stop: AtomicBool::new(false),
                        timed_out: AtomicBool::new(false),
                        deadline: Instant::now() + budget,
                    });
                    if let Ok(mut w) = watches.lock() {
                        w.insert(index, watch.clone());
                    }
                    let result = run_case(&setup, &watch.stop, &|| {
                        watch.timed_out.load(Ordering::Relaxed)
                    });
                    if let Ok(mut w) = watches.lock() {
                        w.remove(&index);
                    }
                    let interrupted = watch.stop.load(Ordering::Relaxed)
                        && !watch.timed_out.load(Ordering::Relaxed);
                    if interrupted {
                        return Ok(None);
                    }
                    store.write_case(&result)?;
                    Ok(Some(result))
                })();
                match result {
                    Ok(Some(r)) => {
                        if let Ok(mut rs) = results.lock() {
                            rs.push((r.outcome.clone(), r.wall_s));
                        }
                        let n = finished.fetch_add(1, Ordering::Relaxed) + 1;
                        progress(Progress {
                            finished: n,
                            total: report.assigned,
                            result: &r,
                        });
                    }
                    Ok(None) => {}
                    Err(e) => {
                        if let Ok(mut first) = first_error.lock() {
                            first.get_or_insert(e);
                        }
                    }
                }
            });
        });
        all_done.store(true, Ordering::Relaxed);
    });
    if let Some(e) = first_error.into_inner().ok().flatten() {
        return Err(e);
    }
    for (outcome, wall_s) in results.into_inner().unwrap_or_default() {
        *report.outcomes.entry(outcome).or_default() += 1;
        report.ran += 1;
        report.case_wall_s += wall_s;
    }
    report.interrupted = report.skipped + report.ran < report.assigned;
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// Runs the nominal case if the store does not hold it yet, and returns it.
pub fn nominal(
    spec: &CampaignSpec,
    store: &Store,
    stop: &AtomicBool,
) -> Result<CaseResult, CampaignError> {
    if let Some(r) = store.read_result(&store.nominal_path())? {
        return Ok(r);
    }
    let setup = super::case::CaseSetup {
        index: 0,
        config: super::case::nominal_config(spec),
        applied: BTreeMap::new(),
        faults: Vec::new(),
        invalid: None,
    };
    let mut result = run_case(&setup, stop, &|| false);
    result.index = None;
    if stop.load(Ordering::Relaxed) {
        return Err(CampaignError::Interrupted);
    }
    store.write_case(&result)?;
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_cover_every_case_once() {
        for cases in [1u64, 7, 100, 1001] {
            for count in [1u64, 2, 3, 8] {
                let mut next = 0;
                for index in 0..count {
                    let r = Shard { index, count }.range(cases);
                    assert_eq!(r.start, next);
                    next = r.end;
                }
                assert_eq!(next, cases);
            }
        }
    }

    #[test]
    fn shard_index_comes_from_the_flag_or_the_environment() {
        let none = |_: &str| None;
        assert_eq!(
            Shard::parse("2/4", &none).unwrap(),
            Shard { index: 2, count: 4 }
        );
        let slurm = |v: &str| (v == "SLURM_ARRAY_TASK_ID").then(|| "3".to_string());
        assert_eq!(Shard::parse("auto/4", &slurm).unwrap().index, 3);
        let k8s = |v: &str| (v == "JOB_COMPLETION_INDEX").then(|| "1".to_string());
        assert_eq!(Shard::parse("auto/4", &k8s).unwrap().index, 1);
        let pbs = |v: &str| (v == "PBS_ARRAY_INDEX").then(|| "0".to_string());
        assert_eq!(Shard::parse("auto/2", &pbs).unwrap().index, 0);
        assert!(Shard::parse("auto/4", &none)
            .unwrap_err()
            .contains("SLURM_ARRAY_TASK_ID"));
        assert!(Shard::parse("4/4", &none).is_err());
        assert!(Shard::parse("1/0", &none).is_err());
        assert!(Shard::parse("x", &none).is_err());
    }
}
