//! Intra-stage reward terms and the reward modes that give the paper's baselines.

use serde::{Deserialize, Serialize};

/// One term of a stage reward `r^(i)`, evaluated on an observation.
///
/// The paper's forms (section IV-D) are sums of these: the approach reward
/// `r_appr = -e^{|o_dist|} - rho_appr * n_c` is `neg_exp_norm(dist) + linear(n_c, -rho_appr)`,
/// the grasp reward `r_equil + rho_grasp * n_c` is two `neg_exp_norm` terms and a `linear` one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RewardTerm {
    /// `coef * feature`.
    Linear { feature: String, coef: f32 },
    /// `-coef * exp(min(scale * |v|, cap))` where `v` is the vector of the named features.
    /// The cap keeps the term finite when a feature is far off (default 10).
    NegExpNorm {
        features: Vec<String>,
        #[serde(default = "one")]
        coef: f32,
        #[serde(default = "one")]
        scale: f32,
        #[serde(default = "default_cap")]
        cap: f32,
    },
    /// A constant per step (a time penalty when negative).
    Constant { value: f32 },
}

fn one() -> f32 {
    1.0
}

fn default_cap() -> f32 {
    10.0
}

/// A term with its feature names resolved to observation indices.
#[derive(Clone, Debug)]
pub(crate) enum CompiledTerm {
    Linear {
        index: usize,
        coef: f32,
    },
    NegExpNorm {
        indices: Vec<usize>,
        coef: f32,
        scale: f32,
        cap: f32,
    },
    Constant {
        value: f32,
    },
}

impl CompiledTerm {
    pub(crate) fn evaluate(&self, observation: &[f32]) -> f32 {
        match self {
            CompiledTerm::Linear { index, coef } => coef * observation[*index],
            CompiledTerm::NegExpNorm {
                indices,
                coef,
                scale,
                cap,
            } => {
                let norm = indices
                    .iter()
                    .map(|&i| observation[i] * observation[i])
                    .sum::<f32>()
                    .sqrt();
                -coef * (scale * norm).min(*cap).exp()
            }
            CompiledTerm::Constant { value } => *value,
        }
    }

    /// The largest value this term can take (used to check `R_arrive` against the best
    /// approach reward, as the paper requires).
    pub(crate) fn upper_bound(&self) -> f32 {
        match self {
            // Features such as n_c are counts >= 0; a positive coefficient is unbounded.
            CompiledTerm::Linear { coef, .. } => {
                if *coef <= 0.0 {
                    0.0
                } else {
                    f32::INFINITY
                }
            }
            CompiledTerm::NegExpNorm { coef, .. } => -coef,
            CompiledTerm::Constant { value } => *value,
        }
    }
}

/// Which reward parts reach the learner (DESIGN.md, "Reward modes").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RewardMode {
    /// Intra-stage and transition rewards: CRM-PPO and CRM-SAC.
    #[default]
    Crm,
    /// Intra-stage rewards only: LPPO's hierarchical dense rewards.
    Dense,
    /// Transition rewards only: IPPO's stage-wise sparse rewards.
    Sparse,
}

impl RewardMode {
    /// Splits the raw parts into what the learner sees: `(intra, transition)`.
    pub fn apply(self, intra: f32, transition: f32) -> (f32, f32) {
        match self {
            RewardMode::Crm => (intra, transition),
            RewardMode::Dense => (intra, 0.0),
            RewardMode::Sparse => (0.0, transition),
        }
    }

    /// All modes, for listings and tests.
    pub const ALL: [RewardMode; 3] = [RewardMode::Crm, RewardMode::Dense, RewardMode::Sparse];
}

impl std::str::FromStr for RewardMode {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "crm" => Ok(RewardMode::Crm),
            "dense" => Ok(RewardMode::Dense),
            "sparse" => Ok(RewardMode::Sparse),
            other => Err(format!(
                "unknown reward mode {other:?} (expected crm, dense or sparse)"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neg_exp_norm_matches_the_paper_form_and_is_capped() {
        let term = CompiledTerm::NegExpNorm {
            indices: vec![0, 1],
            coef: 1.0,
            scale: 1.0,
            cap: 10.0,
        };
        // |(0.3, 0.4)| = 0.5, so -e^{0.5}.
        let value = term.evaluate(&[0.3, 0.4]);
        assert!((value - -(0.5f32.exp())).abs() < 1e-6);
        assert_eq!(term.evaluate(&[1e6, 0.0]), -(10.0f32.exp()));
    }

    #[test]
    fn modes_keep_the_right_parts() {
        assert_eq!(RewardMode::Crm.apply(1.0, 2.0), (1.0, 2.0));
        assert_eq!(RewardMode::Dense.apply(1.0, 2.0), (1.0, 0.0));
        assert_eq!(RewardMode::Sparse.apply(1.0, 2.0), (0.0, 2.0));
        assert!("bogus".parse::<RewardMode>().is_err());
    }
}
