//! A run's whole training state inside its checkpoint, so that a resumed run is the same run:
//! everything the next iteration depends on besides the weights and observation statistics.
//! Its scalars go in the header ([`RunState`]); its arrays are tensors of the same file:
//! Adam's moments (PPO: `state.adam.m.I`, `state.adam.v.I`, one per parameter, flat;
//! CRM-SAC: `state.sac.actor.m.I` and the same for `critic` and `alpha`), CRM-SAC's replay
//! buffer (`state.replay.*`, [`crate::replay`]) and each
//! environment's running episode as the actions that replay it from its seed
//! (`state.env.K.actions`, steps x action dimensions; absent when the episode has just
//! begun). The environments are deterministic per seed, so replaying those actions puts the
//! physics, the machine's stage and its history back bit for bit, on the same build and CPU
//! type ([`RunState::made_on`] says which).

use std::collections::HashMap;

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::normalize::RunningMeanStd;
use crate::ppo::PpoState;
use crate::replay::ReplayRecord;
use crate::rollout::EnvState;

/// The header's part of a run's training state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunState {
    /// The machine it was made on: the architecture and the CPU's model name. Floating-point
    /// results differ between CPU types, so a resume is the same run only on the same type.
    pub made_on: String,
    /// Iterations done.
    pub iteration: u64,
    /// The early-stop rule's window and the last 100 episodes' outcomes, oldest first.
    pub early_stop: Vec<bool>,
    pub last_100: Vec<bool>,
    /// Each task's recent outcomes (the curriculum's counts), oldest first.
    pub tasks: Vec<Vec<bool>>,
    pub envs: Vec<EnvRecord>,
    /// The PPO learner's scalars (absent for CRM-SAC).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ppo: Option<PpoRecord>,
    /// CRM-SAC's scalars (absent for the PPO learners).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sac: Option<SacRecord>,
}

/// One environment's scalars.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvRecord {
    /// Episodes it has ended (its running episode's seed follows from this).
    pub episode: u64,
    /// Its policy-noise generator.
    pub noise: u64,
    /// Steps of its running episode (the rows of its actions tensor).
    pub steps: usize,
    /// The task weights its running episode was drawn with (`None`: uniformly).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_weights: Option<Vec<f32>>,
}

/// The PPO learner's scalars.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PpoRecord {
    pub adam_step: i32,
    pub noise: u64,
    pub returns: Vec<f64>,
    pub return_stats: RunningMeanStd,
}

/// CRM-SAC's scalars.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SacRecord {
    /// The step counts of the actor's, the critics' and the temperature's optimizers.
    pub adam_steps: Vec<i32>,
    /// The learner's noise (exploration, sampled actions, minibatch picks).
    pub noise: u64,
    pub replay: ReplayRecord,
}

/// This machine as [`RunState::made_on`] names it.
pub fn this_machine() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    format!("{} {model}", std::env::consts::ARCH)
}

fn actions_name(k: usize) -> String {
    format!("state.env.{k}.actions")
}

fn moment_name(prefix: &str, moment: &str, i: usize) -> String {
    format!("state.{prefix}.{moment}.{i}")
}

/// One optimizer's moments as tensors `state.PREFIX.m.I` and `state.PREFIX.v.I`.
pub fn moment_tensors(
    prefix: &str,
    m: &[Vec<f32>],
    v: &[Vec<f32>],
) -> Result<Vec<(String, Tensor)>> {
    let mut out = Vec::new();
    for (moment, lists) in [("m", m), ("v", v)] {
        for (i, values) in lists.iter().enumerate() {
            let tensor = Tensor::from_vec(values.clone(), values.len(), &Device::Cpu)?;
            out.push((moment_name(prefix, moment, i), tensor));
        }
    }
    Ok(out)
}

/// Adam's first and second moments, one list per parameter.
pub type Moments = (Vec<Vec<f32>>, Vec<Vec<f32>>);

/// One optimizer's moments (`params` of each) from the tensors of [`moment_tensors`].
pub fn moments(prefix: &str, params: usize, tensors: &HashMap<String, Tensor>) -> Result<Moments> {
    let read = |moment: &str| -> Result<Vec<Vec<f32>>> {
        (0..params)
            .map(|i| {
                let name = moment_name(prefix, moment, i);
                Ok(tensors
                    .get(&name)
                    .ok_or_else(|| missing(&name))?
                    .to_vec1::<f32>()?)
            })
            .collect()
    };
    Ok((read("m")?, read("v")?))
}

/// The tensors of a state: the environments' running episodes and, for PPO, Adam's moments.
pub fn tensors(envs: &[EnvState], ppo: Option<&PpoState>) -> Result<Vec<(String, Tensor)>> {
    let mut out = Vec::new();
    for (k, env) in envs.iter().enumerate() {
        if let Some(first) = env.actions.first() {
            let flat: Vec<f32> = env.actions.concat();
            let shape = (env.actions.len(), first.len());
            out.push((
                actions_name(k),
                Tensor::from_vec(flat, shape, &Device::Cpu)?,
            ));
        }
    }
    if let Some(ppo) = ppo {
        out.extend(moment_tensors("adam", &ppo.adam_m, &ppo.adam_v)?);
    }
    Ok(out)
}

fn missing(name: &str) -> Error {
    Error::Config {
        field: "state",
        message: format!("the checkpoint's training state lacks tensor {name}"),
    }
}

/// The environments' states of `record` with their actions from `tensors`.
pub fn env_states(record: &RunState, tensors: &HashMap<String, Tensor>) -> Result<Vec<EnvState>> {
    record
        .envs
        .iter()
        .enumerate()
        .map(|(k, env)| {
            let actions = if env.steps == 0 {
                Vec::new()
            } else {
                let name = actions_name(k);
                let rows = tensors
                    .get(&name)
                    .ok_or_else(|| missing(&name))?
                    .to_vec2::<f32>()?;
                if rows.len() != env.steps {
                    return Err(Error::Length {
                        what: "a running episode's actions",
                        expected: env.steps,
                        got: rows.len(),
                    });
                }
                rows
            };
            Ok(EnvState {
                episode: env.episode,
                noise: env.noise,
                actions,
            })
        })
        .collect()
}

/// The PPO learner's state of `record` with Adam's moments (`params` of them) from `tensors`.
pub fn ppo_state(
    record: &PpoRecord,
    params: usize,
    tensors: &HashMap<String, Tensor>,
) -> Result<PpoState> {
    let (adam_m, adam_v) = moments("adam", params, tensors)?;
    Ok(PpoState {
        adam_step: record.adam_step,
        adam_m,
        adam_v,
        noise: record.noise,
        returns: record.returns.clone(),
        return_stats: record.return_stats.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_reads_back_from_its_tensors() {
        let envs = vec![
            EnvState {
                episode: 3,
                noise: u64::MAX - 5,
                actions: vec![vec![0.1, -0.25], vec![1e-7, 3.0]],
            },
            EnvState {
                episode: 0,
                noise: 7,
                actions: Vec::new(),
            },
        ];
        let ppo = PpoState {
            adam_step: 12,
            adam_m: vec![vec![0.5; 3], vec![-1.0]],
            adam_v: vec![vec![0.25; 3], vec![2.0]],
            noise: 99,
            returns: vec![0.1, 0.2],
            return_stats: RunningMeanStd::new(1),
        };
        let tensors: HashMap<String, Tensor> = tensors(&envs, Some(&ppo))
            .expect("tensors")
            .into_iter()
            .collect();
        let record = RunState {
            made_on: this_machine(),
            iteration: 4,
            early_stop: vec![true],
            last_100: vec![true],
            tasks: vec![],
            envs: envs
                .iter()
                .map(|e| EnvRecord {
                    episode: e.episode,
                    noise: e.noise,
                    steps: e.actions.len(),
                    task_weights: None,
                })
                .collect(),
            ppo: None,
            sac: None,
        };
        assert_eq!(env_states(&record, &tensors).expect("envs"), envs);
        let scalars = PpoRecord {
            adam_step: 12,
            noise: 99,
            returns: ppo.returns.clone(),
            return_stats: ppo.return_stats.clone(),
        };
        assert_eq!(ppo_state(&scalars, 2, &tensors).expect("ppo"), ppo);
        let err = ppo_state(&scalars, 3, &tensors).expect_err("a third parameter");
        assert!(err.to_string().contains("state.adam.m.2"), "{err}");
    }
}
