//! Checkpoint evaluation: success rate and mean episode length per objective and overall,
//! over episodes on tasks drawn with a fixed seed (the paper's Table I).

use std::collections::BTreeMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use crm_api::{EvalReport, EvalSpec, Row};
use crm_learn::{Actor, Checkpoint, Layout, Noise, Ppo, PpoConfig, SacNets};
use grasp_sim::SimConfig;
use grasp_sim::benchmark::Objective;

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
#[derive(Default)]
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

    fn row(self) -> Row {
        let n = self.episodes.max(1) as f64;
        Row {
            success_rate: self.successes as f64 / n,
            mean_episode_length: self.control_steps as f64 / n,
            episodes: self.episodes,
            mean_sim_seconds: self.seconds / n,
            outcomes: self.outcomes,
            authors_judge: Some(self.authors as f64 / n),
        }
    }
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
    let config = env.config_for(spec.objective, spec.hold_s)?;
    evaluate_in(path, spec, env, config, recorder, progress)
}

/// [`evaluate`] in the world's settings `config` (benchmarks compare settings on the same
/// episodes; evaluations take the job's).
pub fn evaluate_in(
    path: &Path,
    spec: &EvalSpec,
    env: &Env,
    config: SimConfig,
    recorder: Option<SharedRecorder>,
    mut progress: impl FnMut(u64, u64, &EpisodeRecord) -> bool,
) -> Result<EvalReport> {
    spec.validate().map_err(|err| invalid!("{err}"))?;
    let benchmark = env.benchmark()?;
    let mut policy = LoadedPolicy::load(path, env, &config)?;
    let (algorithm, trained_steps) = (policy.algorithm.clone(), policy.trained_steps);
    let machine = policy.machine.clone();
    let choice = crate::EnvChoice::of(&benchmark, &spec.task, &spec.tasks, &spec.topology)?;
    let grasp = env.grasp_env(config, &choice)?;
    let recorded = Recorded::new(grasp, machine.clone(), recorder);
    let mut crm_env = crm::CrmEnv::new(machine, recorded, crm::RewardMode::Crm);
    // The policy's noise when it samples (the default, as the paper's evaluation): seeded.
    let mut noise = (!spec.deterministic).then(|| Noise::new(spec.seed ^ 0x00E7_A1ED_5EED));
    // Per objective and per task: episodes, successes, control steps, simulated seconds,
    // outcomes.
    let mut sums: BTreeMap<Objective, Sums> = BTreeMap::new();
    let mut task_sums: BTreeMap<String, Sums> = BTreeMap::new();
    let mut overall = Sums::default();
    for k in 0..spec.episodes {
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
        for entry in [
            sums.entry(objective).or_default(),
            task_sums.entry(task).or_default(),
            &mut overall,
        ] {
            entry.add(success, authors, length, seconds, &outcome);
        }
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
    let overall = overall.row();
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
        per_objective: sums
            .into_iter()
            .map(|(o, s)| (o.name().to_string(), s.row()))
            .collect(),
        per_task: task_sums.into_iter().map(|(t, s)| (t, s.row())).collect(),
        outcomes: overall.outcomes,
        hold_s: spec.hold_s,
        authors_judge: overall.authors_judge,
    })
}
