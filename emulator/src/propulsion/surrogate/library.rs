//! The library phi: every monomial of the (scaled) features up to a degree, each with a
//! readable name such as `T_o1[t-2]*P[t-1]`, so a fitted model can be printed and read.
//!
//! A term is stored as three factor indices into the feature vector extended by one slot
//! that always holds 1.0; lower-degree terms are padded with that slot. Evaluation is then
//! the same branch-free product for every term, in training and in the runtime.

use crate::propulsion::surrogate::features::Role;
pub use crate::propulsion::surrogate::model::{eval_term, term_name, Term, MAX_DEGREE};

/// All monomials of degree 1..=`degree` over `dim` features (no constant: the intercept is
/// fitted separately and not penalised). Powers of binary features are left out: they
/// equal the feature itself; so are products of two binary features of one exclusion
/// group (see `FeatureSpec::binary_groups`), which are zero or equal to one of them.
#[derive(Debug, Clone, PartialEq)]
pub struct Library {
    /// Number of features.
    pub dim: usize,
    /// Degree.
    pub degree: usize,
    /// Terms in a fixed order (by degree, then lexicographic).
    pub terms: Vec<Term>,
}

impl Library {
    /// Enumerates the library over features with the given roles (binary exclusion
    /// groups, phase indicators and their partners). Terms with a phase indicator have
    /// degree up to `phase_degree` instead (0: `degree`), so a start transient can be a
    /// per-step quadratic in the command while the rest of the library stays degree 2.
    pub fn new(dim: usize, degree: usize, roles: &[Role], phase_degree: usize) -> Self {
        let phase_degree = if phase_degree == 0 {
            degree
        } else {
            phase_degree
        };
        assert!((1..=MAX_DEGREE).contains(&degree) && dim < u16::MAX as usize);
        assert!(phase_degree <= MAX_DEGREE);
        let allowed = |d: usize, f: &[usize]| {
            if f.iter().any(|&i| roles[i].phase) {
                d <= phase_degree
            } else {
                d <= degree
            }
        };
        let one = dim as u16;
        let mut terms = Vec::new();
        let left_out = |a: usize, b: usize| {
            let (ra, rb) = (roles[a], roles[b]);
            (ra.group != 0 && ra.group == rb.group)
                // A phase indicator multiplies only its partners (and vice versa).
                || (ra.phase && !rb.phase_partner)
                || (rb.phase && !ra.phase_partner)
        };
        for i in 0..dim {
            terms.push([i as u16, one, one]);
        }
        let top = degree.max(phase_degree);
        if top >= 2 {
            for i in 0..dim {
                for j in i..dim {
                    if !left_out(i, j) && allowed(2, &[i, j]) {
                        terms.push([i as u16, j as u16, one]);
                    }
                }
            }
        }
        if top >= 3 {
            for i in 0..dim {
                for j in i..dim {
                    for k in j..dim {
                        if !left_out(i, j)
                            && !left_out(j, k)
                            && !left_out(i, k)
                            && allowed(3, &[i, j, k])
                        {
                            terms.push([i as u16, j as u16, k as u16]);
                        }
                    }
                }
            }
        }
        Self { dim, degree, terms }
    }

    /// The powers of each feature alone, `x_j, x_j^2, ..., x_j^degree` (no products of
    /// two features): the reading of the paper's polynomial phi that keeps its
    /// `K in R^{7 x (11n+10)}` one block per power. Powers of a binary feature equal the
    /// feature and are left out.
    pub fn powers(dim: usize, degree: usize, roles: &[Role]) -> Self {
        assert!((1..=MAX_DEGREE).contains(&degree) && dim < u16::MAX as usize);
        let one = dim as u16;
        let mut terms: Vec<Term> = (0..dim).map(|i| [i as u16, one, one]).collect();
        let continuous = || (0..dim).filter(|&i| roles[i].group == 0).map(|i| i as u16);
        if degree >= 2 {
            terms.extend(continuous().map(|i| [i, i, one]));
        }
        if degree >= 3 {
            terms.extend(continuous().map(|i| [i, i, i]));
        }
        Self { dim, degree, terms }
    }

    /// Number of terms.
    pub fn len(&self) -> usize {
        self.terms.len()
    }

    /// True when there are no terms.
    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }

    /// Name of a term from the feature names: factors joined by `*`, repeats as powers.
    pub fn term_name(&self, term: &Term, feature_names: &[String]) -> String {
        term_name(term, self.dim, feature_names)
    }

    /// Evaluates every term. `x_ext` is the scaled feature vector followed by 1.0.
    #[inline]
    pub fn eval(&self, x_ext: &[f64], out: &mut [f64]) {
        debug_assert_eq!(x_ext.len(), self.dim + 1);
        for (o, t) in out.iter_mut().zip(&self.terms) {
            *o = eval_term(t, x_ext);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn choose(n: usize, k: usize) -> usize {
        (0..k).fold(1, |acc, i| acc * (n - i) / (i + 1))
    }

    #[test]
    fn powers_are_each_feature_alone_up_to_the_degree() {
        let roles = [
            Role::default(),
            Role {
                group: 1,
                ..Role::default()
            },
            Role::default(),
        ];
        let names: Vec<String> = ["a", "s", "b"].iter().map(|s| s.to_string()).collect();
        let lib = Library::powers(3, 3, &roles);
        let got: Vec<String> = lib.terms.iter().map(|t| lib.term_name(t, &names)).collect();
        assert_eq!(got, ["a", "s", "b", "a^2", "b^2", "a^3", "b^3"]);
        assert_eq!(Library::powers(3, 1, &roles), Library::new(3, 1, &roles, 0));
    }

    #[test]
    fn counts_match_multiset_formula() {
        for dim in 1..6 {
            for degree in 1..=3 {
                let lib = Library::new(dim, degree, &vec![Role::default(); dim], 0);
                // Monomials of degree 1..=d in dim variables: C(dim+d, d) - 1.
                assert_eq!(
                    lib.len(),
                    choose(dim + degree, degree) - 1,
                    "{dim} {degree}"
                );
            }
        }
    }

    #[test]
    fn binary_powers_are_dropped_and_names_read() {
        let names: Vec<String> = ["T_o1[t-2]", "P[t-1]", "S_e1[t]"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let lib = Library::new(
            3,
            2,
            &[
                Role::default(),
                Role::default(),
                Role {
                    group: 1,
                    ..Role::default()
                },
            ],
            0,
        );
        let all: Vec<String> = lib.terms.iter().map(|t| lib.term_name(t, &names)).collect();
        assert!(all.contains(&"T_o1[t-2]*P[t-1]".to_string()));
        assert!(all.contains(&"P[t-1]^2".to_string()));
        assert!(!all.contains(&"S_e1[t]^2".to_string()));
        assert_eq!(all.len(), 3 + 6 - 1);
        let x = [2.0, 3.0, 1.0, 1.0];
        let mut out = vec![0.0; lib.len()];
        lib.eval(&x, &mut out);
        let at = |n: &str| out[all.iter().position(|s| s == n).unwrap()];
        assert_eq!(at("T_o1[t-2]*P[t-1]"), 6.0);
        assert_eq!(at("P[t-1]^2"), 9.0);
        assert_eq!(at("T_o1[t-2]"), 2.0);
    }

    #[test]
    fn phase_indicators_multiply_only_their_partners() {
        use crate::propulsion::surrogate::features::FeatureSpec;
        let spec = FeatureSpec {
            start_steps: 2,
            stop_steps: 1,
            phase_degree: 3,
            command_sum: true,
            ..FeatureSpec::per_engine(1)
        };
        let names = spec.names();
        let lib = Library::new(spec.dim(), 2, &spec.roles(), spec.phase_degree);
        let all: Vec<String> = lib.terms.iter().map(|t| lib.term_name(t, &names)).collect();
        let has = |n: &str| all.iter().any(|s| s == n);
        assert!(has("T_r[t]*start0[t]"));
        assert!(has("T_r[t]*T_rsum[t]*start1[t]"));
        assert!(has("T_o[t-1]^2*stop0[t]"));
        // Not with a non-partner, not with the switch or another indicator, no powers.
        assert!(!has("T_r[t-1]*start0[t]"));
        assert!(!has("S_e[t]*start0[t]"));
        assert!(!has("start0[t]*stop0[t]"));
        assert!(!has("start0[t]^2"));
        // Degree 3 only for phase terms.
        assert!(!all.iter().any(|s| s.matches('*').count() == 2
            && !s.contains("start")
            && !s.contains("stop")
            && !s.contains('^')));
        assert!(!has("T_r[t]^2*T_o[t-1]"));
    }
}
