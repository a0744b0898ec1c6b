//! Checkpoint evaluation: success rate and mean episode length per objective and overall,
//! over episodes on tasks drawn with a fixed seed (the paper's Table I).

use std::collections::BTreeMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use crm_api::{EvalReport, EvalSpec, Row};
use crm_learn::{Actor, Checkpoint, Layout, Noise, Ppo, PpoConfig, SacNets};
use grasp_sim::SimConfig;
use serde::{Deserialize, Serialize};

use crate::Env;
use crate::error::{Context, Error, Result, invalid};
pub use crate::record::EpisodeRecord;
use crate::record::{Recorded, SharedRecorder};

/// A checkpoint's networks: the PPO family's actor-critic or SAC's actor and critics.
pub enum PolicyNet {
    Ppo(Box<Ppo>),
    Sac(Box<SacNets>),
}

/// A loaded checkpoint ready to act deterministically in its machine.
pub struct LoadedPolicy {
    pub net: PolicyNet,
    pub machine: crm::Machine,
    pub algorithm: String,
    pub trained_steps: u64,
    /// Union action dimensions the environment takes the magnitude of
    /// ([`grasp_sim::SimConfig::folded_actions`]): a deterministic PPO action takes the
    /// sampled action's mean magnitude there (`crm_learn::folded`).
    pub folded: Vec<bool>,
}

impl LoadedPolicy {
    /// Loads `path` for the machine its algorithm trains in (the flat one for `ppo`), to act
    /// in the world's settings `config` (which say the dimensions it folds).
    pub fn load(path: &Path, env: &Env, config: &SimConfig) -> Result<Self> {
        let header = Checkpoint::read_header(path)?;
        crate::check_world(&header, env.world()?, path)?;
        let algorithm = header.algorithm;
        let machine = if algorithm == "ppo" {
            env.machine_or(grasp_sim::spec::flat_spec())?
        } else {
            env.machine()?
        };
        let hash = machine.spec().hash();
        let (net, header) = if algorithm == "crm-sac" {
            let (nets, header) = Checkpoint::load_sac(path, &hash, grasp_sim::ENV_VERSION)?;
            (PolicyNet::Sac(Box::new(nets)), header)
        } else {
            let (net, header) = Checkpoint::load(path, &hash, grasp_sim::ENV_VERSION)?;
            let config = PpoConfig {
                hidden: header.hidden.clone(),
                ..PpoConfig::default()
            };
            let mut ppo = Ppo::new(net.layout(), config, 0)?;
            ppo.net = net;
            (PolicyNet::Ppo(Box::new(ppo)), header)
        };
        if header.layout != Layout::of(&machine) {
            return Err(invalid!(
                "checkpoint {}: network layout {:?} does not fit the machine",
                path.display(),
                header.layout
            ));
        }
        Ok(Self {
            net,
            machine,
            algorithm: header.algorithm,
            trained_steps: header.steps,
            folded: config.folded_actions(),
        })
    }

    /// The policy's action, zero outside the stage's action set: sampled with `noise`, or
    /// without it the deterministic one (the Gaussian's mean, the mean magnitude of a sampled
    /// action on the [`Self::folded`] dimensions; SAC: `tanh` of the mean).
    pub fn act(
        &mut self,
        state: &[f32],
        stage: usize,
        mask: &[f32],
        noise: Option<&mut Noise>,
    ) -> Result<Vec<f32>> {
        let action = match (&mut self.net, noise) {
            (PolicyNet::Ppo(ppo), None) => ppo.act_folded(state, stage, mask, &self.folded)?,
            (PolicyNet::Ppo(ppo), Some(noise)) => ppo.act_one(state, stage, mask, noise)?.0,
            (PolicyNet::Sac(nets), noise) => {
                let input = nets.input(&[state.to_vec()], &[stage])?;
                let mask = Tensor::from_vec(mask.to_vec(), (1, mask.len()), &Device::Cpu)?;
                let action = match noise {
                    None => nets.mean_action(&input, &mask)?,
                    Some(noise) => {
                        let eps: Vec<f32> = (0..mask.dim(1)?).map(|_| noise.normal()).collect();
                        let eps = Tensor::from_vec(eps, (1, mask.dim(1)?), &Device::Cpu)?;
                        nets.sample_action(&input, &mask, &eps)?
                    }
                };
                action.squeeze(0)?.to_vec1()?
            }
        };
        Ok(action.iter().zip(mask).map(|(a, m)| a * m).collect())
    }

    /// The critic's value of the state (SAC: `min Q` of the deterministic action).
    pub fn value(&self, state: &[f32], stage: usize, mask: &[f32]) -> Result<f32> {
        let value = match &self.net {
            PolicyNet::Ppo(ppo) => {
                let input = ppo.net.input(&[state.to_vec()], &[stage])?;
                ppo.net.value(&input)?
            }
            PolicyNet::Sac(nets) => {
                let input = nets.input(&[state.to_vec()], &[stage])?;
                let mask = Tensor::from_vec(mask.to_vec(), (1, mask.len()), &Device::Cpu)?;
                let action = nets.mean_action(&input, &mask)?;
                nets.min_q(&input, &action)?
            }
        };
        Ok(value.to_vec1::<f32>()?.first().copied().unwrap_or(0.0))
    }
}

/// Running sums of one row of the report.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Sums {
    episodes: u64,
    successes: u64,
    control_steps: u64,
    seconds: f64,
    outcomes: BTreeMap<String, u64>,
    authors: u64,
}

impl Sums {
    fn add(&mut self, success: bool, authors: bool, length: usize, seconds: f64, outcome: &str) {
        self.episodes += 1;
        self.authors += u64::from(authors);
        self.successes += u64::from(success);
        self.control_steps += length as u64;
        self.seconds += seconds;
        *self.outcomes.entry(outcome.to_string()).or_default() += 1;
    }

    fn row(&self) -> Row {
        let n = self.episodes.max(1) as f64;
        Row {
            success_rate: self.successes as f64 / n,
            mean_episode_length: self.control_steps as f64 / n,
            episodes: self.episodes,
            mean_sim_seconds: self.seconds / n,
            outcomes: self.outcomes.clone(),
            authors_judge: Some(self.authors as f64 / n),
        }
    }
}

/// Where an evaluation stands after its first `done` episodes: all it needs to go on from the
/// next one exactly as if it had never stopped (each episode's seed follows from its index;
/// the policy's noise generator and the report's running sums are here). A worker stopped
/// mid-evaluation gives it back to the coordinator with the job, and the next worker goes on
/// from it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalProgress {
    pub done: u64,
    /// The policy's noise generator (a sampled evaluation's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<u64>,
    per_objective: BTreeMap<String, Sums>,
    per_task: BTreeMap<String, Sums>,
    overall: Sums,
}

/// Evaluates the checkpoint at `path`. After each episode `progress(done, total, record)` is
/// called; returning `false` stops the evaluation with an error ("cancelled").
pub fn evaluate(
    path: &Path,
    spec: &EvalSpec,
    env: &Env,
    recorder: Option<SharedRecorder>,
    progress: impl FnMut(u64, u64, &EpisodeRecord) -> bool,
) -> Result<EvalReport> {
    evaluate_from(
        path,
        spec,
        env,
        recorder,
        &mut EvalProgress::default(),
        progress,
    )
}

/// [`evaluate`] going on from `from` (a fresh one: `EvalProgress::default()`), which it keeps
/// current after each episode: when `progress` stops the evaluation, `from` says where to go
/// on.
pub fn evaluate_from(
    path: &Path,
    spec: &EvalSpec,
    env: &Env,
    recorder: Option<SharedRecorder>,
    from: &mut EvalProgress,
    progress: impl FnMut(u64, u64, &EpisodeRecord) -> bool,
) -> Result<EvalReport> {
    let config = env.config_for(spec.objective, spec.hold_s)?;
    run_from(path, spec, env, config, recorder, from, progress)
}

/// [`evaluate`] in the world's settings `config` (benchmarks compare settings on the same
/// episodes; evaluations take the job's).
pub fn evaluate_in(
    path: &Path,
    spec: &EvalSpec,
    env: &Env,
    config: SimConfig,
    recorder: Option<SharedRecorder>,
    progress: impl FnMut(u64, u64, &EpisodeRecord) -> bool,
) -> Result<EvalReport> {
    let mut fresh = EvalProgress::default();
    run_from(path, spec, env, config, recorder, &mut fresh, progress)
}

fn run_from(
    path: &Path,
    spec: &EvalSpec,
    env: &Env,
    config: SimConfig,
    recorder: Option<SharedRecorder>,
    from: &mut EvalProgress,
    mut progress: impl FnMut(u64, u64, &EpisodeRecord) -> bool,
) -> Result<EvalReport> {
    spec.validate().map_err(|err| invalid!("{err}"))?;
    if from.done > spec.episodes || (from.done > 0 && from.noise.is_some() == spec.deterministic) {
        return Err(invalid!(
            "the evaluation's progress ({} episodes done, {}) does not fit its spec ({} \
             episodes, {})",
            from.done,
            if from.noise.is_some() {
                "sampled"
            } else {
                "deterministic"
            },
            spec.episodes,
            if spec.deterministic {
                "deterministic"
            } else {
                "sampled"
            }
        ));
    }
    let benchmark = env.benchmark()?;
    let mut policy = LoadedPolicy::load(path, env, &config)?;
    let (algorithm, trained_steps) = (policy.algorithm.clone(), policy.trained_steps);
    let machine = policy.machine.clone();
    let choice = crate::EnvChoice::of(&benchmark, &spec.task, &spec.tasks, &spec.topology)?;
    let grasp = env.grasp_env(config, &choice)?;
    let recorded = Recorded::new(grasp, machine.clone(), recorder);
    let mut crm_env = crm::CrmEnv::new(machine, recorded, crm::RewardMode::Crm);
    // The policy's noise when it samples (the default, as the paper's evaluation): seeded, or
    // where the progress left it.
    let mut noise = if from.done == 0 {
        (!spec.deterministic).then(|| Noise::new(spec.seed ^ 0x00E7_A1ED_5EED))
    } else {
        from.noise.map(Noise::new)
    };
    for k in from.done..spec.episodes {
        let seed = spec.seed.wrapping_mul(1_000_003).wrapping_add(k);
        let (mut stage, mut state) = crm_env.reset(seed).context("reset")?;
        let objective = crm_env.env().inner().objective();
        let (success, length, outcome) = loop {
            let mask = crm_env.machine().action_mask(stage);
            let action = policy.act(&state, stage, &mask, noise.as_mut())?;
            let step = crm_env.step(&action)?;
            if step.done || step.truncated {
                let end = if step.done {
                    crm_env.machine().stage_name(step.stage)
                } else {
                    "truncated"
                };
                let outcome = crm_env.env().inner().outcome_label(end);
                let success = end == "success";
                break (success, crm_env.episode().steps(), outcome);
            }
            (stage, state) = (step.stage, step.abstract_state);
        };
        let seconds = f64::from(crm_env.env().inner().sim_seconds());
        let authors = crm_env.env().inner().authors_judge();
        let task = crm_env.env().inner().task().id.clone();
        // Per objective and per task, and overall: episodes, successes, control steps,
        // simulated seconds, outcomes.
        for entry in [
            from.per_objective
                .entry(objective.name().to_string())
                .or_default(),
            from.per_task.entry(task).or_default(),
            &mut from.overall,
        ] {
            entry.add(success, authors, length, seconds, &outcome);
        }
        from.done = k + 1;
        from.noise = noise.as_ref().map(Noise::state);
        let machine = crm_env.machine();
        let episode = crm_env.episode();
        let record = EpisodeRecord {
            task: crm_env.env().inner().task().id.clone(),
            success,
            outcome: outcome.clone(),
            sim_seconds: seconds,
            length,
            total_return: episode.total_return(),
            transitions: episode
                .history()
                .iter()
                .map(|t| {
                    (
                        t.step,
                        machine.stage_name(t.from).to_string(),
                        machine.stage_name(t.to).to_string(),
                        machine.event_name(t.event).to_string(),
                        t.reward,
                    )
                })
                .collect(),
        };
        if !progress(k + 1, spec.episodes, &record) {
            return Err(Error::Cancelled {
                done: k + 1,
                total: spec.episodes,
            });
        }
    }
    let overall = from.overall.row();
    Ok(EvalReport {
        algorithm,
        trained_steps,
        episodes: spec.episodes,
        seed: spec.seed,
        success_rate: overall.success_rate,
        mean_episode_length: overall.mean_episode_length,
        mean_sim_seconds: overall.mean_sim_seconds,
        objective: spec.objective,
        deterministic: spec.deterministic,
        per_objective: from
            .per_objective
            .iter()
            .map(|(o, s)| (o.clone(), s.row()))
            .collect(),
        per_task: from
            .per_task
            .iter()
            .map(|(t, s)| (t.clone(), s.row()))
            .collect(),
        outcomes: overall.outcomes,
        hold_s: spec.hold_s,
        authors_judge: overall.authors_judge,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/crm-ppo.safetensors")
    }

    fn spec(deterministic: bool) -> EvalSpec {
        serde_json::from_value(serde_json::json!({
            "episodes": 6,
            "seed": 11,
            "deterministic": deterministic,
            "tasks": ["mouse-press", "mug-wrap", "valve-twist"],
        }))
        .expect("spec")
    }

    #[test]
    fn an_evaluation_stopped_and_gone_on_from_its_progress_gives_the_same_report() {
        let env = Env::default();
        for deterministic in [false, true] {
            let spec = spec(deterministic);
            let whole = evaluate(&shipped(), &spec, &env, None, |_, _, _| true).expect("whole");
            let mut progress = EvalProgress::default();
            let stopped = evaluate_from(
                &shipped(),
                &spec,
                &env,
                None,
                &mut progress,
                |done, _, _| done < 4,
            );
            assert!(stopped.is_err(), "stopped after 4 episodes");
            assert_eq!(progress.done, 4);
            assert_eq!(progress.noise.is_some(), !deterministic);
            // As the coordinator keeps it: JSON.
            let text = serde_json::to_string(&progress).expect("json");
            let mut back: EvalProgress = serde_json::from_str(&text).expect("json");
            assert_eq!(back, progress);
            let mut seen = Vec::new();
            let gone_on = evaluate_from(&shipped(), &spec, &env, None, &mut back, |done, _, _| {
                seen.push(done);
                true
            })
            .expect("gone on");
            assert_eq!(seen, [5, 6], "only the episodes not done");
            assert_eq!(gone_on, whole);
            // Progress of the other kind of evaluation is refused.
            let mut other = progress.clone();
            other.noise = if deterministic { Some(1) } else { None };
            let err = evaluate_from(&shipped(), &spec, &env, None, &mut other, |_, _, _| true)
                .expect_err("refused");
            assert!(err.to_string().contains("does not fit its spec"), "{err}");
        }
    }
}
