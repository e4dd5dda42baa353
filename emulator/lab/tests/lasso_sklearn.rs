//! Validation against an external reference: our Gram-based Lasso (an active-set method,
//! not scikit-learn's coordinate descent, but the same minimiser) against scikit-learn's
//! `Lasso(precompute=True, fit_intercept=True)` on a committed fixture
//! (`tools/gen_lasso_fixture.py` made it; this test needs no Python).

use oils_lab::training::lasso::{
    lasso_gram, GramProblem, GramStats, LassoSettings, LassoWorkspace,
};
use std::path::PathBuf;

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lasso_fixture")
}

fn read_csv(name: &str) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(data_dir().join(name)).unwrap();
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect()
}

#[test]
fn lasso_matches_sklearn() {
    let x = read_csv("x.csv");
    let y: Vec<f64> = read_csv("y.csv").into_iter().map(|r| r[0]).collect();
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data_dir().join("expected.json")).unwrap())
            .unwrap();
    let p = x[0].len();
    let flat: Vec<f64> = x.iter().flatten().copied().collect();
    let stats = GramStats::from_block(&flat, &y, p, 1);
    let c = stats.centred();
    let prob = GramProblem {
        gram: &c.gram,
        xty: &c.xty,
        yty: c.yty[0],
        n_samples: c.n,
    };
    let settings = LassoSettings {
        tol: 1e-11,
        max_iter: 1_000_000,
    };
    let fits = expected["fits"].as_array().unwrap();
    assert_eq!(fits.len(), 4);
    let mut w = vec![0.0; p];
    let mut ws = LassoWorkspace::new(p);
    for fit in fits {
        let alpha = fit["alpha"].as_f64().unwrap();
        let reference: Vec<f64> = fit["coef"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        // Warm start from the previous (larger) penalty, as the training path does.
        let report = lasso_gram(&prob, alpha, &settings, &mut w, &mut ws);
        assert!(report.converged, "alpha {alpha}: {report:?}");
        let intercept = c.mean_y[0] - w.iter().zip(&c.mean_x).map(|(a, b)| a * b).sum::<f64>();
        let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (j, (ours, theirs)) in w.iter().zip(&reference).enumerate() {
            assert!(
                (ours - theirs).abs() <= 1e-6 * scale,
                "alpha {alpha} coef {j}: ours {ours} sklearn {theirs}"
            );
            // Same support: a coefficient sklearn zeroes is zero (or negligible) here.
            if *theirs == 0.0 {
                assert!(ours.abs() <= 1e-6 * scale);
            }
        }
        let b_ref = fit["intercept"].as_f64().unwrap();
        assert!(
            (intercept - b_ref).abs() <= 1e-6 * b_ref.abs(),
            "alpha {alpha}: intercept {intercept} vs {b_ref}"
        );
    }
}
