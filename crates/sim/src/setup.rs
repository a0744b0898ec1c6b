//! How environments are made from a world: the settings every caller shares (the command line,
//! the worker's jobs, the Python package) and the one factory, [`make_env`] ([`World::env`];
//! `crm_run` adds a job's topologies to it). A world gives
//! the hand, objects, tasks, spec and randomization; [`EnvSettings`] says how a job runs it.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::{
    Benchmark, Error, FingerActions, GraspEnv, Protocol, Result, SimConfig, TaskChoice, World,
};

/// How a job runs its world's environments.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvSettings {
    /// Domain randomization: the world's ranges, else the paper's (on by default, as in the
    /// paper); off: [`SimConfig::deterministic`].
    pub randomization: bool,
    /// Who executes the objective once the grasp is ready.
    pub protocol: Protocol,
    /// How finger actions move the fingers.
    pub finger_actions: FingerActions,
    /// Seconds of steady hold the judge asks ([`SimConfig::hold_s`]; default the paper's 5 s).
    pub hold_s: Option<f64>,
    /// Training's hold shortcut ([`SimConfig::settle_s`]; default off).
    pub settle_s: Option<f64>,
}

impl Default for EnvSettings {
    fn default() -> Self {
        Self {
            randomization: true,
            protocol: Protocol::default(),
            finger_actions: FingerActions::default(),
            hold_s: None,
            settle_s: None,
        }
    }
}

impl World {
    /// The physics and judge settings of this world run as `settings` say.
    pub fn sim_config(&self, settings: &EnvSettings) -> SimConfig {
        let mut config = if settings.randomization {
            let mut config = SimConfig::default();
            if let Some(randomization) = &self.randomization {
                config.randomization = randomization.clone();
            }
            config
        } else {
            SimConfig::deterministic()
        };
        config.protocol = settings.protocol;
        config.approach = self.approach;
        config.finger_actions = settings.finger_actions;
        if let Some(hold) = settings.hold_s {
            config.hold_s = hold as f32;
        }
        if let Some(settle) = settings.settle_s {
            config.settle_s = settle as f32;
        }
        config
    }

    /// The tasks named by `ids` (all tasks, drawn per episode, when empty); an unknown id is
    /// [`Error::NoSuchTask`] with the world's task list.
    pub fn task_choice(&self, ids: &[String]) -> Result<TaskChoice> {
        let indices = ids
            .iter()
            .map(|id| {
                self.benchmark.task_index(id).ok_or_else(|| {
                    let known: Vec<&str> =
                        self.benchmark.tasks.iter().map(|t| t.id.as_str()).collect();
                    Error::NoSuchTask {
                        id: id.clone(),
                        world: self.name.clone(),
                        known: known.join(", "),
                    }
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(match indices.as_slice() {
            [] => TaskChoice::Random,
            [one] => TaskChoice::Fixed(*one),
            _ => TaskChoice::Subset(indices),
        })
    }

    /// One environment of this world in `config` ([`Self::sim_config`] of a job's settings),
    /// drawing tasks as `tasks` says.
    pub fn env(&self, config: SimConfig, tasks: TaskChoice) -> Result<GraspEnv> {
        make_env(&self.benchmark, config, tasks)
    }
}

/// One environment of `benchmark` (a world's) in `config`, drawing tasks as `tasks` says:
/// the factory behind [`World::env`], for callers that hold the benchmark alone.
pub fn make_env(
    benchmark: &Arc<Benchmark>,
    config: SimConfig,
    tasks: TaskChoice,
) -> Result<GraspEnv> {
    let mut env = GraspEnv::new(benchmark.clone(), config);
    env.set_task_choice(tasks)?;
    Ok(env)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_reach_the_config_and_unknown_tasks_are_named() {
        let world = World::builtin();
        let settings = EnvSettings {
            randomization: false,
            protocol: Protocol::Learned,
            finger_actions: FingerActions::Signed,
            hold_s: Some(2.0),
            settle_s: Some(0.25),
        };
        let config = world.sim_config(&settings);
        assert_eq!(
            config.randomization,
            SimConfig::deterministic().randomization
        );
        assert_eq!(config.protocol, Protocol::Learned);
        assert_eq!(config.finger_actions, FingerActions::Signed);
        assert_eq!((config.hold_s, config.settle_s), (2.0, 0.25));
        assert_eq!(
            world.sim_config(&EnvSettings::default()),
            SimConfig::default()
        );

        let id = world.benchmark.tasks[3].id.clone();
        assert_eq!(
            world.task_choice(&[id]).expect("known"),
            TaskChoice::Fixed(3)
        );
        assert_eq!(world.task_choice(&[]).expect("all"), TaskChoice::Random);
        let err = world
            .task_choice(&["no-such-task".into()])
            .expect_err("unknown");
        assert!(err.to_string().contains("no-such-task"), "{err}");
        assert!(err.to_string().contains("mouse-press"), "{err}");
        let parsed: EnvSettings = serde_json::from_str(r#"{"hold_s": 1.5}"#).expect("json");
        assert!(parsed.randomization && parsed.hold_s == Some(1.5));
    }
}
