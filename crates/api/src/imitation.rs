//! Imitation before reinforcement learning: behaviour cloning of the scripted oracle (with
//! privileged state) into a PPO learner's policy, optionally with noise on the oracle's
//! executed actions (DART), then PPO as usual. Off by default; the paper
//! trains from scratch (its section V), this is a warm start for the long holds PPO finds
//! slowly.

use serde::{Deserialize, Serialize};

use crate::config::ConfigError;
use crate::jobs::Algorithm;

/// Imitation settings of a training job (`"imitation": {"episodes": 2080}` in its JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImitationSpec {
    /// Oracle episodes to run; their successful ones are the demonstrations.
    pub episodes: u64,
    /// Passes over the demonstrations.
    #[serde(default = "default_epochs")]
    pub epochs: usize,
    /// Learning rate of the regression (Adam, minibatches of the PPO config's size).
    #[serde(default = "default_learning_rate")]
    pub learning_rate: f64,
    /// Standard deviation of Gaussian noise on the oracle's executed actions, in action units;
    /// the labels stay clean (DART, Laskey et al., 2017). 0: none.
    #[serde(default)]
    pub noise: f64,
}

fn default_epochs() -> usize {
    20
}

fn default_learning_rate() -> f64 {
    1e-3
}

/// Most oracle episodes one job may ask for.
pub const MAX_IMITATION_EPISODES: u64 = 100_000;
/// Most passes over the demonstrations.
pub const MAX_IMITATION_EPOCHS: usize = 1000;

impl ImitationSpec {
    /// Whether `algorithm` can start from a clone: the PPO learners of the grasping machine
    /// (the oracle acts in its stages; SAC's actor is another network).
    pub fn supports(algorithm: Algorithm) -> bool {
        matches!(
            algorithm,
            Algorithm::CrmPpo | Algorithm::Ippo | Algorithm::Lppo
        )
    }

    /// Checks the fields; errors name the field inside `imitation`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |field, message: String| Err(ConfigError { field, message });
        if self.episodes == 0 || self.episodes > MAX_IMITATION_EPISODES {
            return bad(
                "episodes",
                format!("must be between 1 and {MAX_IMITATION_EPISODES}"),
            );
        }
        if self.epochs == 0 || self.epochs > MAX_IMITATION_EPOCHS {
            return bad(
                "epochs",
                format!("must be between 1 and {MAX_IMITATION_EPOCHS}"),
            );
        }
        if !(self.learning_rate > 0.0 && self.learning_rate <= 1.0) {
            return bad("learning_rate", "must be in (0, 1]".to_string());
        }
        if !(0.0..=1.0).contains(&self.noise) {
            return bad("noise", "must be in [0, 1]".to_string());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_fill_in_and_bad_fields_are_named() {
        let spec: ImitationSpec = serde_json::from_str(r#"{"episodes": 100}"#).expect("spec");
        assert_eq!(
            spec,
            ImitationSpec {
                episodes: 100,
                epochs: 20,
                learning_rate: 1e-3,
                noise: 0.0,
            }
        );
        assert!(spec.validate().is_ok());
        let field = |json: &str| {
            serde_json::from_str::<ImitationSpec>(json)
                .expect("spec")
                .validate()
                .expect_err("invalid")
                .field
        };
        assert_eq!(field(r#"{"episodes": 0}"#), "episodes");
        assert_eq!(field(r#"{"episodes": 5, "epochs": 0}"#), "epochs");
        assert_eq!(
            field(r#"{"episodes": 5, "learning_rate": -1}"#),
            "learning_rate"
        );
        assert_eq!(field(r#"{"episodes": 5, "noise": 1.5}"#), "noise");
        assert!(serde_json::from_str::<ImitationSpec>(r#"{"episodes": 5, "beta": 1}"#).is_err());
        assert!(ImitationSpec::supports(Algorithm::Lppo));
        assert!(
            !ImitationSpec::supports(Algorithm::CrmSac) && !ImitationSpec::supports(Algorithm::Ppo)
        );
    }
}
