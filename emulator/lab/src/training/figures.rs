//! The report's PNG figures (through the bench's `plot` module): the paper's Fig. 2 and
//! Fig. 3, the excitation, and a free-run comparison against the reference model.

use super::cv::{CvResult, GridPoint};
use super::report::{at_chosen_n, best_per_n};
use super::TrainOutcome;
use crate::plot::{write_png, Panel, PlotError, Series};
use oils_emulator::propulsion::surrogate::features::{StateVec, STATE_DIM};
use oils_emulator::propulsion::surrogate::predictor::Predictor;
use oils_shared::ENGINE_COUNT;
use std::path::{Path, PathBuf};

fn pts(
    points: &[&GridPoint],
    x: impl Fn(&GridPoint) -> f64,
    y: impl Fn(&GridPoint) -> f64,
) -> Vec<(f64, f64)> {
    points.iter().map(|p| (x(p), y(p))).collect()
}

/// Fig. 2: error against history length (the best mu of each n).
fn fig2(res: &CvResult, path: &Path) -> Result<(), PlotError> {
    let best = best_per_n(res);
    let n = |p: &GridPoint| p.n as f64;
    let test = pts(&best, n, |p| GridPoint::thrust(&p.test_rmse));
    let free = pts(&best, n, |p| GridPoint::thrust(&p.free_rmse));
    let score = pts(&best, n, |p| p.score);
    let title = format!(
        "Fig. 2 ({}): model error vs history length",
        res.variant.as_str()
    );
    write_png(
        path,
        &title,
        &[
            Panel {
                log_y: false,
                ..Panel::new(
                    "thrust RMSE, CV mean, best mu per n",
                    "history length n",
                    "RMSE (N)",
                    vec![
                        Series {
                            label: "one-step (test folds)",
                            points: &test,
                        },
                        Series {
                            label: "free-run (test folds)",
                            points: &free,
                        },
                    ],
                )
            },
            Panel {
                log_y: false,
                ..Panel::new(
                    "selection score (mean free-run RMSE / output std)",
                    "history length n",
                    "score (-)",
                    vec![Series {
                        label: "score",
                        points: &score,
                    }],
                )
            },
        ],
    )
}

/// Fig. 3: train and test RMSE, and sparsity, against mu at the chosen n.
fn fig3(res: &CvResult, path: &Path) -> Result<(), PlotError> {
    let at = at_chosen_n(res);
    let mu = |p: &GridPoint| p.mu;
    let train = pts(&at, mu, |p| GridPoint::thrust(&p.train_rmse));
    let test = pts(&at, mu, |p| GridPoint::thrust(&p.test_rmse));
    let free = pts(&at, mu, |p| GridPoint::thrust(&p.free_rmse));
    let sparsity = pts(&at, mu, |p| p.sparsity_pct);
    let title = format!(
        "Fig. 3 ({}): error and sparsity vs mu at n = {}",
        res.variant.as_str(),
        res.chosen().n
    );
    write_png(
        path,
        &title,
        &[
            Panel {
                log_x: true,
                log_y: true,
                ..Panel::new(
                    "thrust RMSE, CV mean",
                    "mu (sklearn alpha, standardised)",
                    "RMSE (N)",
                    vec![
                        Series {
                            label: "train one-step",
                            points: &train,
                        },
                        Series {
                            label: "test one-step",
                            points: &test,
                        },
                        Series {
                            label: "test free-run",
                            points: &free,
                        },
                    ],
                )
            },
            Panel {
                log_x: true,
                ..Panel::new(
                    "sparsity",
                    "mu (sklearn alpha, standardised)",
                    "zero coefficients (%)",
                    vec![Series {
                        label: "sparsity",
                        points: &sparsity,
                    }],
                )
            },
        ],
    )
}

/// The excitation's four commands against time.
fn excitation(out: &TrainOutcome, path: &Path) -> Result<(), PlotError> {
    let dt = out.excitation.sample_time_ns as f64 * 1e-9;
    let engines: Vec<Vec<(f64, f64)>> = (0..ENGINE_COUNT)
        .map(|e| {
            out.excitation
                .inputs
                .iter()
                .enumerate()
                .map(|(k, v)| (k as f64 * dt, v[e]))
                .collect()
        })
        .collect();
    let labels = ["cmd 1", "cmd 2", "cmd 3", "cmd 4"];
    let panels: Vec<Panel> = (0..2)
        .map(|h| {
            Panel::new(
                if h == 0 {
                    "engines 1 and 2"
                } else {
                    "engines 3 and 4"
                },
                "time (s)",
                "thrust command (N)",
                (2 * h..2 * h + 2)
                    .map(|e| Series {
                        label: labels[e],
                        points: &engines[e],
                    })
                    .collect(),
            )
        })
        .collect();
    write_png(
        path,
        "Excitation (4-sphere levels, stairs, ramps, switching)",
        &panels,
    )
}

/// Free run of every trained model over the last CV fold's span, against the data.
fn free_run(out: &TrainOutcome, path: &Path) -> Result<(), PlotError> {
    let d = &out.dataset;
    let dt = d.sample_time_ns as f64 * 1e-9;
    let a = d.len() - d.len() / 5;
    let truth: Vec<(f64, f64)> = (a..d.len())
        .map(|t| (t as f64 * dt, d.states[t][0]))
        .collect();
    let mut runs: Vec<(String, Vec<StateVec>)> = Vec::new();
    for m in &out.models {
        let mut p = Predictor::new(&m.model);
        p.seed_history(&d.history_at(a));
        runs.push((
            m.variant.as_str().to_string(),
            (a..d.len()).map(|t| p.step(&d.inputs[t])).collect(),
        ));
    }
    let series_of = |o: usize| -> Vec<(String, Vec<(f64, f64)>)> {
        runs.iter()
            .map(|(name, ys)| {
                (
                    name.clone(),
                    ys.iter()
                        .enumerate()
                        .map(|(i, y)| ((a + i) as f64 * dt, y[o] - d.states[a + i][o]))
                        .collect(),
                )
            })
            .collect()
    };
    let err_t = series_of(0);
    let err_m: Vec<(String, Vec<(f64, f64)>)> = series_of(STATE_DIM - 2);
    let mut thrust = vec![Series {
        label: "reference",
        points: &truth,
    }];
    let fitted: Vec<(String, Vec<(f64, f64)>)> = runs
        .iter()
        .map(|(n, ys)| {
            (
                n.clone(),
                ys.iter()
                    .enumerate()
                    .map(|(i, y)| ((a + i) as f64 * dt, y[0]))
                    .collect(),
            )
        })
        .collect();
    for (n, p) in &fitted {
        thrust.push(Series {
            label: n,
            points: p,
        });
    }
    write_png(
        path,
        "Free run over the last fold (models trained on all data)",
        &[
            Panel::new("engine 1 thrust", "time (s)", "thrust (N)", thrust),
            Panel::new(
                "engine 1 thrust error",
                "time (s)",
                "model - reference (N)",
                err_t
                    .iter()
                    .map(|(n, p)| Series {
                        label: n,
                        points: p,
                    })
                    .collect(),
            ),
            Panel::new(
                "ejected fuel error",
                "time (s)",
                "model - reference (kg)",
                err_m
                    .iter()
                    .map(|(n, p)| Series {
                        label: n,
                        points: p,
                    })
                    .collect(),
            ),
        ],
    )
}

/// Writes every figure into `dir`; returns the paths.
pub fn write_figures(out: &TrainOutcome, dir: &Path) -> Result<Vec<PathBuf>, PlotError> {
    let mut written = Vec::new();
    for res in &out.cv {
        let v = res.variant.as_str();
        let p = dir.join(format!("fig2_error_vs_history_{v}.png"));
        fig2(res, &p)?;
        written.push(p);
        let p = dir.join(format!("fig3_error_sparsity_vs_mu_{v}.png"));
        fig3(res, &p)?;
        written.push(p);
    }
    let p = dir.join("excitation.png");
    excitation(out, &p)?;
    written.push(p);
    let p = dir.join("free_run.png");
    free_run(out, &p)?;
    written.push(p);
    Ok(written)
}

/// Held-out case: engine 1 thrust of the reference and of each model, and the error.
pub fn holdout(
    r: &super::holdout::CaseResult,
    names: &[&str],
    path: &Path,
) -> Result<(), PlotError> {
    let d = &r.truth;
    let dt = d.sample_time_ns as f64 * 1e-9;
    let t = |k: usize| (k + 1) as f64 * dt;
    let truth: Vec<(f64, f64)> = (0..d.len()).map(|k| (t(k), d.states[k][0])).collect();
    let cmd: Vec<(f64, f64)> = (0..d.len()).map(|k| (t(k), d.inputs[k][0])).collect();
    let fitted: Vec<Vec<(f64, f64)>> = r
        .runs
        .iter()
        .map(|(_, ys)| ys.iter().enumerate().map(|(k, y)| (t(k), y[0])).collect())
        .collect();
    let errs: Vec<Vec<(f64, f64)>> = r
        .runs
        .iter()
        .map(|(_, ys)| {
            ys.iter()
                .enumerate()
                .map(|(k, y)| (t(k), y[0] - d.states[k][0]))
                .collect()
        })
        .collect();
    let mut thrust = vec![
        Series {
            label: "command",
            points: &cmd,
        },
        Series {
            label: "hifi",
            points: &truth,
        },
    ];
    for (i, p) in fitted.iter().enumerate() {
        thrust.push(Series {
            label: names.get(i).copied().unwrap_or("?"),
            points: p,
        });
    }
    let err: Vec<Series> = errs
        .iter()
        .enumerate()
        .map(|(i, p)| Series {
            label: names.get(i).copied().unwrap_or("?"),
            points: p,
        })
        .collect();
    let title = format!("Held-out case `{}`: free run against hifi", r.case.name);
    write_png(
        path,
        &title,
        &[
            Panel::new("engine 1 thrust", "time (s)", "thrust (N)", thrust),
            Panel::new(
                "engine 1 thrust error",
                "time (s)",
                "surrogate - hifi (N)",
                err,
            ),
        ],
    )
}
