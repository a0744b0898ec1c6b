//! One check per job document: [`TrainSpec::validate`] and [`EvalSpec::validate`] hold every
//! rule a spec obeys before any world is in sight. The coordinator calls them on a submission
//! (then checks the world's tasks and a stored checkpoint), `crm train` and `crm eval` on what
//! their flags and `--spec` file make, and the runtime (`crm_run::Trainer`) on what it runs.

use crate::jobs::{EvalSpec, TrainSpec, check_hold_s, check_settle_s, check_start_log_std};

/// Most environment steps one training job may ask.
pub const MAX_STEPS: u64 = 10_000_000_000;
/// Most episodes one evaluation may ask.
pub const MAX_EPISODES: u64 = 1_000_000;
/// Most environments one job may step side by side.
pub const MAX_ENVS: usize = 1024;

/// A field of a job's document out of its domain: its path in the document
/// (`config.minibatch_size`) and what is wrong.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct SpecError {
    pub field: String,
    pub message: String,
}

impl SpecError {
    fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            message: message.into(),
        }
    }

    /// A nested settings error (`ConfigError`'s field) under `prefix`.
    fn under(prefix: &str, err: crate::ConfigError) -> Self {
        Self::new(format!("{prefix}.{}", err.field), err.message)
    }
}

impl TrainSpec {
    /// Every rule of a training job's document that needs no world.
    pub fn validate(&self) -> Result<(), SpecError> {
        self.sac
            .validate()
            .map_err(|e| SpecError::under("sac", e))?;
        if self.steps == 0 || self.steps > MAX_STEPS {
            return Err(SpecError::new(
                "steps",
                format!("must be between 1 and {MAX_STEPS}"),
            ));
        }
        check_envs(self.envs)?;
        check_record(&self.record)?;
        if let Some(imitation) = &self.imitation {
            if !crate::ImitationSpec::supports(self.algorithm) {
                return Err(SpecError::new(
                    "imitation",
                    format!(
                        "behaviour cloning is for the PPO learners of the grasping machine (crm-ppo, ippo, lppo), not {}",
                        self.algorithm.name()
                    ),
                ));
            }
            imitation
                .validate()
                .map_err(|e| SpecError::under("imitation", e))?;
        }
        check_hold_s(self.hold_s).map_err(|message| SpecError::new("hold_s", message))?;
        check_settle_s(self.settle_s).map_err(|message| SpecError::new("settle_s", message))?;
        check_start_log_std(self.algorithm, self.start_log_std, self.config.init_log_std)
            .map_err(|message| SpecError::new("start_log_std", message))?;
        self.config
            .validate()
            .map_err(|e| SpecError::under("config", e))?;
        if self.fine_tune.is_some_and(|id| id <= 0) {
            return Err(SpecError::new(
                "fine_tune",
                "must be a checkpoint's id (a positive integer)",
            ));
        }
        Ok(())
    }
}

impl EvalSpec {
    /// Every rule of an evaluation's document that needs no world.
    pub fn validate(&self) -> Result<(), SpecError> {
        if self.episodes == 0 || self.episodes > MAX_EPISODES {
            return Err(SpecError::new(
                "episodes",
                format!("must be between 1 and {MAX_EPISODES}"),
            ));
        }
        check_record(&self.record)?;
        if let Some(video) = &self.video {
            video.validate().map_err(|e| SpecError::under("video", e))?;
        }
        check_hold_s(self.hold_s).map_err(|message| SpecError::new("hold_s", message))
    }
}

fn check_envs(envs: Option<usize>) -> Result<(), SpecError> {
    if envs.is_some_and(|n| n == 0 || n > MAX_ENVS) {
        return Err(SpecError::new(
            "envs",
            format!("must be between 1 and {MAX_ENVS}"),
        ));
    }
    Ok(())
}

fn check_record(record: &Option<crate::RecordSpec>) -> Result<(), SpecError> {
    match record {
        Some(record) => record.validate().map_err(|e| SpecError::under("record", e)),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn train(json: serde_json::Value) -> TrainSpec {
        serde_json::from_value(json).expect("a training spec")
    }

    #[test]
    fn each_rule_names_its_field() {
        let ok = train(serde_json::json!({"algorithm": "crm-ppo", "steps": 100}));
        assert_eq!(ok.validate(), Ok(()));
        for (json, field) in [
            (
                serde_json::json!({"algorithm": "crm-ppo", "steps": 0}),
                "steps",
            ),
            (
                serde_json::json!({"algorithm": "crm-ppo", "steps": 1, "envs": 0}),
                "envs",
            ),
            (
                serde_json::json!({"algorithm": "crm-ppo", "steps": 1, "config": {"minibatch_size": 0}}),
                "config.minibatch_size",
            ),
            (
                serde_json::json!({"algorithm": "crm-sac", "steps": 1, "imitation": {"episodes": 10}}),
                "imitation",
            ),
            (
                serde_json::json!({"algorithm": "crm-sac", "steps": 1, "start_log_std": -1.0}),
                "start_log_std",
            ),
            (
                serde_json::json!({"algorithm": "crm-ppo", "steps": 1, "hold_s": 9.0}),
                "hold_s",
            ),
            (
                serde_json::json!({"algorithm": "crm-ppo", "steps": 1, "settle_s": 0.0}),
                "settle_s",
            ),
            (
                serde_json::json!({"algorithm": "crm-ppo", "steps": 1, "fine_tune": 0}),
                "fine_tune",
            ),
        ] {
            let err = train(json.clone()).validate().expect_err("refused");
            assert_eq!(err.field, field, "{json}: {err}");
        }
        let eval: EvalSpec =
            serde_json::from_value(serde_json::json!({"episodes": 0})).expect("spec");
        assert_eq!(eval.validate().expect_err("refused").field, "episodes");
    }
}
