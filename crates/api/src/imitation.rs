//! Imitation before reinforcement learning: behaviour cloning of the scripted oracle (with
//! privileged state) into a PPO learner's policy, optionally with noise on the oracle's
//! executed actions (DART), then PPO as usual. Off by default; the paper
//! trains from scratch (its section V), this is a warm start for the long holds PPO finds
//! slowly.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::algorithm::Algorithm;
use crate::config::ConfigError;

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
    /// Task ids the oracle demonstrates; empty: the job's own tasks. A model fine-tuned on
    /// every task can so be shown the one it fails without being pulled toward the oracle on
    /// the rest.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tasks: Vec<String>,
    /// Per task id, where the oracle moves the palm from the grasp location before it closes
    /// (m, world frame, each axis within [`MAX_SHIFT`]): for a task whose grasp holds only off
    /// the point it arrives at, as the `palm-offset` example finds it (docs/notebook/worlds.md).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub shifts: BTreeMap<String, [f64; 3]>,
    /// The stages whose steps are cloned ([`STAGES`]: `approach`, `grasp`); empty: every
    /// stage. A model that approaches well can so be taught a grasp without its approach
    /// being pulled toward the oracle's, which every task's approach shares.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<String>,
    /// Episodes of the starting policy on the job's tasks other than `tasks` (on every job
    /// task when `tasks` is empty) whose visited states (of `stages`) are cloned with its own
    /// mean actions as labels, so a trained model keeps what it does there while it learns
    /// the demonstrated tasks; 0: none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub anchor_episodes: u64,
}

fn is_zero(value: &u64) -> bool {
    *value == 0
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
/// The grasping machine's stages the oracle acts in, whose steps cloning may keep.
pub const STAGES: [&str; 2] = ["approach", "grasp"];
/// Largest palm shift per axis (m): the oracle's bound (`grasp_sim::oracle::MAX_SHIFT`).
pub const MAX_SHIFT: f64 = 0.1;

/// Reads a palm shift as the command line gives it, `TASK=DX,DY,DZ` (m), checked as
/// [`ImitationSpec::validate`] checks `shifts`.
pub fn parse_shift(text: &str) -> Result<(String, [f64; 3]), String> {
    let (task, numbers) = text
        .split_once('=')
        .ok_or_else(|| format!("{text:?} is not TASK=DX,DY,DZ"))?;
    let values: Vec<&str> = numbers.split(',').collect();
    let [x, y, z] = values.as_slice() else {
        return Err(format!("{text:?}: give three numbers, DX,DY,DZ (m)"));
    };
    let mut shift = [0.0; 3];
    for (slot, value) in shift.iter_mut().zip([x, y, z]) {
        *slot = value
            .trim()
            .parse()
            .map_err(|_| format!("{text:?}: {value:?} is not a number"))?;
    }
    if task.is_empty() {
        return Err(format!("{text:?}: name the task before '='"));
    }
    check_shift(&shift).map_err(|message| format!("{text:?}: {message}"))?;
    Ok((task.to_string(), shift))
}

fn check_shift(shift: &[f64; 3]) -> Result<(), String> {
    if shift.iter().all(|v| v.abs() <= MAX_SHIFT) {
        Ok(())
    } else {
        Err(format!(
            "each axis must be between -{MAX_SHIFT} and {MAX_SHIFT} m"
        ))
    }
}

impl ImitationSpec {
    /// Whether `algorithm` can start from a clone: the PPO learners of the grasping machine
    /// (the oracle acts in its stages; SAC's actor is another network).
    pub fn supports(algorithm: Algorithm) -> bool {
        algorithm.is_machine_ppo()
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
        if let Some(k) = self.tasks.iter().position(String::is_empty) {
            return bad("tasks", format!("tasks[{k}] must be a task id, not empty"));
        }
        if self.anchor_episodes > MAX_IMITATION_EPISODES {
            return bad(
                "anchor_episodes",
                format!("must be between 0 and {MAX_IMITATION_EPISODES}"),
            );
        }
        if let Some((k, name)) = self
            .stages
            .iter()
            .enumerate()
            .find(|(_, name)| !STAGES.contains(&name.as_str()))
        {
            return bad(
                "stages",
                format!(
                    "stages[{k}] {name:?} is not a stage the oracle acts in ({})",
                    STAGES.join(", ")
                ),
            );
        }
        for (task, shift) in &self.shifts {
            check_shift(shift).map_err(|message| ConfigError {
                field: "shifts",
                message: format!("{task:?}: {message}"),
            })?;
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
                tasks: Vec::new(),
                shifts: BTreeMap::new(),
                stages: Vec::new(),
                anchor_episodes: 0,
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
        assert_eq!(field(r#"{"episodes": 5, "tasks": ["t07", ""]}"#), "tasks");
        assert_eq!(field(r#"{"episodes": 5, "stages": [""]}"#), "stages");
        assert_eq!(field(r#"{"episodes": 5, "stages": ["success"]}"#), "stages");
        assert_eq!(
            field(r#"{"episodes": 5, "tasks": ["t07"], "anchor_episodes": 100001}"#),
            "anchor_episodes"
        );
        assert_eq!(
            field(r#"{"episodes": 5, "shifts": {"t07": [0.07, -0.1000000000000001, 0]}}"#),
            "shifts"
        );
        let shifted: ImitationSpec = serde_json::from_str(
            r#"{"episodes": 5, "tasks": ["t07"], "shifts": {"t07": [0.07, -0.1, 0]}, "stages": ["grasp"], "anchor_episodes": 100000}"#,
        )
        .expect("spec");
        assert!(shifted.validate().is_ok());
        assert!(
            serde_json::from_str::<ImitationSpec>(r#"{"episodes": 5, "shifts": {"t07": [0, 0]}}"#)
                .is_err(),
            "a shift has three axes"
        );
        assert!(serde_json::from_str::<ImitationSpec>(r#"{"episodes": 5, "beta": 1}"#).is_err());
        assert!(ImitationSpec::supports(Algorithm::Lppo));
    }

    #[test]
    fn a_command_line_shift_is_task_equals_three_numbers_within_the_bound() {
        assert_eq!(
            parse_shift("t07=0.07,-0.04,0"),
            Ok(("t07".to_string(), [0.07, -0.04, 0.0]))
        );
        for bad in [
            "t07",
            "=0,0,0",
            "t07=0,0",
            "t07=0,0,0,0",
            "t07=0,x,0",
            "t07=0.2,0,0",
            "t07=NaN,0,0",
            "t07=inf,0,0",
        ] {
            assert!(parse_shift(bad).is_err(), "{bad} accepted");
        }
        assert!(
            !ImitationSpec::supports(Algorithm::CrmSac) && !ImitationSpec::supports(Algorithm::Ppo)
        );
    }
}
