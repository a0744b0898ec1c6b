//! A training run: vectorized rollouts and learner updates (PPO, or SAC for crm-sac) inside
//! the grasping CRM, one iteration at a time so that a caller (the CLI's progress bar, the
//! service worker's heartbeat) can report between them and save checkpoints. A checkpoint
//! holds the run's whole training state until the run finishes (`crm_learn::state`;
//! CRM-SAC's with its replay buffer, `crm_learn::replay`), and a run resumed from one is the
//! same run: the same metrics and the same final weights, bit for bit, as if it had never
//! stopped (on the same build and CPU type). From a checkpoint without that state (one
//! written before, one a coordinator's size limit kept to the policy, or a finished run's) a
//! run keeps the steps already trained (so the learning-rate steps stay where they were) and
//! reseeds its environments and noise from (seed, steps): reproducible, but not the
//! uninterrupted run; a SAC run so resumed starts with an empty replay buffer.

use std::path::Path;
use std::time::Instant;

use crm_api::{Algorithm, Iteration, TrainSpec};
use crm_learn::checkpoint::FORMAT;
use crm_learn::rollout::Episode;
use crm_learn::state::{self as run_state, EnvRecord, PpoRecord, RunState};
use crm_learn::{
    Checkpoint, CheckpointHeader, EarlyStop, Layout, LineageStage, Ppo, Sac, TaskCurriculum, VecEnv,
};

use crate::Env;
use crate::error::{Context, Error, Result, invalid};
use crate::record::{Recorded, SharedRecorder, lock};

/// The sha256 of a file's bytes, hex.
fn file_sha256(path: &Path) -> Result<String> {
    use sha2::{Digest, Sha256};
    let bytes = crate::error::read(path)?;
    Ok(Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// A policy's actions at a batch of abstract states in their stages: the ones it executes
/// (sampled) and its means (the labels).
pub type PolicyActions = (Vec<Vec<f32>>, Vec<Vec<f32>>);

/// The learner of a run.
enum Learner {
    Ppo(Box<Ppo>),
    Sac(Box<Sac>),
}

/// Where a training starts from, other than fresh weights.
#[derive(Clone, Copy, Debug)]
pub enum Init<'a> {
    /// Go on with this checkpoint of the same world: its steps count.
    Resume(&'a Path),
    /// Start from this checkpoint's weights and normalizer, trained in another world with
    /// the same machine and observation layout (the same hand with fewer sensors: the
    /// paper's real robot); steps count from 0 and checkpoints belong to this world.
    FineTune(&'a Path),
}

impl Init<'_> {
    pub fn path(&self) -> &Path {
        match self {
            Init::Resume(path) | Init::FineTune(path) => path,
        }
    }
}

/// A run in progress.
pub struct Trainer {
    spec: TrainSpec,
    envs: VecEnv<Recorded>,
    /// Records environment 0's episodes and the training series, when the job asks.
    recorder: Option<SharedRecorder>,
    env_count: usize,
    learner: Learner,
    early_stop: EarlyStop,
    /// The last 100 episodes, for `success_rate_last_100` whatever the early-stop window.
    last_100: EarlyStop,
    layout: Layout,
    spec_hash: String,
    /// The world's name, its hash (the lineage's: a corrected world's corrections in it) and
    /// its policy hash (the header's, what a checkpoint's compatibility is checked on).
    world: (String, String, String),
    /// The world's grasp corrections for the lineage: the fit's command and the offsets.
    corrections: Option<serde_json::Value>,
    stage_names: Vec<String>,
    started: Instant,
    start_steps: u64,
    done: u64,
    iteration: u64,
    stopped_early: bool,
    /// Per-task success over each task's last training episodes: logged every iteration,
    /// and the task weights when the job asks for a curriculum.
    tasks: TaskCurriculum,
    task_ids: Vec<String>,
    curriculum: bool,
    /// The stages before this run (its parent's lineage) and what this run adds.
    lineage: Vec<LineageStage>,
    stage_kind: &'static str,
    parent_sha256: Option<String>,
    command: Option<Vec<String>>,
    imitation: Option<serde_json::Value>,
    /// The machine the resumed checkpoint's state was made on, when the run went on from one.
    resumed_state_from: Option<String>,
}

impl Trainer {
    /// Sets up the environments and the learner; `init` is a checkpoint to resume from;
    /// `recorder` records environment 0's episodes (the others never pay for it).
    pub fn new(
        spec: TrainSpec,
        env: &Env,
        init: Option<Init<'_>>,
        recorder: Option<SharedRecorder>,
    ) -> Result<Self> {
        spec.validate().map_err(|err| invalid!("{err}"))?;
        let benchmark = env.benchmark()?;
        let machine = match spec.algorithm {
            Algorithm::Ppo => env.machine_or(grasp_sim::spec::flat_spec())?,
            _ => env.machine()?,
        };
        let choice = crate::EnvChoice::of(&benchmark, &spec.task, &spec.tasks, &spec.topology)?;
        // At least 1: `validate` refuses `envs: 0`, and rayon has a thread.
        let env_count = spec.envs.unwrap_or_else(rayon::current_num_threads);
        let spec_hash = machine.spec().hash();
        let layout = Layout::of(&machine);
        let is_sac = spec.algorithm == Algorithm::CrmSac;
        let resuming = matches!(init, Some(Init::Resume(_)));
        let mut start_steps = 0;
        let mut resume_ppo = None;
        let mut resume_sac = None;
        // A resume from a checkpoint that kept the whole training state: (state, tensors).
        let mut exact = None;
        let (mut lineage, mut parent_sha256) = (Vec::new(), None);
        if let Some(init) = init {
            let path = init.path();
            let header = Checkpoint::read_header(path)?;
            lineage = LineageStage::inherited(&header);
            parent_sha256 = Some(file_sha256(path)?);
            if header.algorithm != spec.algorithm.name() {
                return Err(invalid!(
                    "checkpoint {} was trained with {}, not {}",
                    path.display(),
                    header.algorithm,
                    spec.algorithm.name()
                ));
            }
            match init {
                Init::Resume(_) => {
                    crate::check_world(&header, env.world()?, path)?;
                    start_steps = header.steps;
                    if let Some(state) = header.state.clone() {
                        exact = Some((state, Checkpoint::tensors(path)?));
                    }
                }
                // Another world's weights: `Checkpoint::load` below still asks for the same
                // machine (spec hash) and observation layout (`ENV_VERSION`).
                Init::FineTune(_) => {}
            }
            if is_sac {
                resume_sac =
                    Some(Checkpoint::load_sac(path, &spec_hash, grasp_sim::ENV_VERSION)?.0);
            } else {
                resume_ppo = Some(Checkpoint::load(path, &spec_hash, grasp_sim::ENV_VERSION)?.0);
            }
        }
        // The state replays one episode per environment: with another number of environments
        // the run goes on from the weights as from an older checkpoint.
        if exact
            .as_ref()
            .is_some_and(|(state, _)| state.envs.len() != env_count)
        {
            exact = None;
        }
        let seed = if start_steps == 0 || exact.is_some() {
            spec.seed
        } else {
            spec.seed ^ start_steps.wrapping_mul(0xD1B5_4A32_D192_ED03)
        };
        let learner = if is_sac {
            let masks = (0..machine.stage_count())
                .map(|s| machine.action_mask(s))
                .collect();
            let mut sac = Sac::new(layout, spec.sac.clone(), masks, seed)?;
            if let Some(nets) = &resume_sac {
                sac.load_weights(nets)
                    .context("resuming from the checkpoint")?;
            }
            if let Some((state, tensors)) = &exact
                && let Some(record) = &state.sac
            {
                sac.restore(record, tensors)
                    .context("resuming the optimizers and the replay buffer from the checkpoint")?;
            }
            Learner::Sac(Box::new(sac))
        } else {
            let mut ppo = Ppo::new(layout, spec.config.clone(), seed)?;
            if let Some(net) = &resume_ppo {
                ppo.load_weights(net)
                    .context("resuming from the checkpoint")?;
            }
            // A run's start (fresh or fine-tuned) takes the job's noise; a resumed run keeps
            // what it learned.
            if !resuming && let Some(log_std) = spec.start_log_std() {
                ppo.net.set_log_std(log_std as f32)?;
            }
            if let Some((state, tensors)) = &exact
                && let Some(record) = &state.ppo
            {
                let params = ppo.net.params().len();
                ppo.restore(run_state::ppo_state(record, params, tensors)?)
                    .context("resuming the optimizer from the checkpoint")?;
            }
            Learner::Ppo(Box::new(ppo))
        };
        let (window, threshold) = if is_sac {
            (spec.sac.early_stop_window, spec.sac.early_stop_success)
        } else {
            (
                spec.config.early_stop_window,
                spec.config.early_stop_success,
            )
        };
        let envs = (0..env_count)
            .map(|k| {
                let mut config = env.config_for(spec.objective, spec.hold_s)?;
                config.settle_s = spec.settle_s.unwrap_or(0.0) as f32;
                let grasp = env.grasp_env(config, &choice)?;
                let recorder = if k == 0 { recorder.clone() } else { None };
                Ok(crm::CrmEnv::new(
                    machine.clone(),
                    Recorded::new(grasp, machine.clone(), recorder),
                    crate::reward_mode(spec.algorithm),
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut envs = VecEnv::new(envs, seed)?;
        let stage_names = (0..layout.stages)
            .map(|s| machine.stage_name(s).to_string())
            .collect();
        let mut tasks = TaskCurriculum::new(benchmark.tasks.len());
        let mut early_stop = EarlyStop::new(window, threshold as f32);
        let mut last_100 = EarlyStop::new(100, 1.0);
        let mut iteration = 0;
        let mut resumed_state_from = None;
        if let Some((state, tensors)) = &exact {
            // Each environment draws its running episode's task as it did, then replays it.
            for (env, record) in envs.envs_mut().zip(&state.envs) {
                env.env_mut()
                    .inner_mut()
                    .set_task_weights(record.task_weights.clone())?;
            }
            envs.restore(&run_state::env_states(state, tensors)?)
                .context("replaying the running episodes of the checkpoint")?;
            tasks.restore(&state.tasks);
            early_stop.restore(&state.early_stop);
            last_100.restore(&state.last_100);
            if spec.curriculum {
                let weights = tasks.weights();
                for env in envs.envs_mut() {
                    env.env_mut()
                        .inner_mut()
                        .set_task_weights(Some(weights.clone()))?;
                }
            }
            iteration = state.iteration;
            resumed_state_from = Some(state.made_on.clone());
        }
        Ok(Self {
            tasks,
            task_ids: benchmark.tasks.iter().map(|t| t.id.clone()).collect(),
            curriculum: spec.curriculum,
            early_stop,
            last_100,
            spec,
            envs,
            recorder,
            env_count,
            learner,
            layout,
            spec_hash,
            world: (
                env.world()?.name.clone(),
                env.world()?.hash.clone(),
                env.world()?.policy_hash.clone(),
            ),
            corrections: env
                .world()?
                .corrections
                .as_ref()
                .map(|c| serde_json::json!({"command": c.command, "offsets": c.offsets()})),
            stage_names,
            started: Instant::now(),
            lineage,
            stage_kind: match init {
                None => "train",
                Some(Init::Resume(_)) => "resume",
                Some(Init::FineTune(_)) => "fine-tune",
            },
            parent_sha256,
            command: None,
            imitation: None,
            start_steps,
            done: start_steps,
            iteration,
            stopped_early: false,
            resumed_state_from,
        })
    }

    /// When the run went on from a checkpoint with its whole training state: the machine that
    /// state was made on (the same run only on the same CPU type).
    pub fn resumed_state_from(&self) -> Option<&str> {
        self.resumed_state_from.as_deref()
    }

    /// Behaviour cloning of `demos` into a PPO learner's policy before training (see
    /// `crm_learn::imitation`); returns the last epoch's loss.
    pub fn imitate(
        &mut self,
        demos: &crm_learn::Demos,
        epochs: usize,
        learning_rate: f64,
        on_epoch: impl FnMut(usize, f32) -> bool,
    ) -> Result<f32> {
        let loss = match &mut self.learner {
            Learner::Ppo(ppo) => ppo.imitate_with(demos, epochs, learning_rate, on_epoch)?,
            Learner::Sac(_) => return Err(invalid!("behaviour cloning is for the PPO learners")),
        };
        self.imitation = Some(serde_json::json!({
            "demo_steps": demos.len(),
            "epochs": epochs,
            "learning_rate": learning_rate,
            "final_loss": loss,
            "settings": self.spec.imitation,
        }));
        Ok(loss)
    }

    /// The command line that started this run, kept in its checkpoints' lineage.
    pub fn set_command(&mut self, command: Vec<String>) {
        self.command = Some(command);
    }

    /// This checkpoint's lineage: the parent's stages, then this run so far.
    fn lineage(&self) -> Result<Vec<LineageStage>> {
        let mut lineage = self.lineage.clone();
        lineage.push(LineageStage {
            kind: self.stage_kind.to_string(),
            algorithm: self.spec.algorithm.name().to_string(),
            steps: self.done - self.start_steps,
            wall_s: self.started.elapsed().as_secs_f64(),
            seed: self.spec.seed,
            parent_sha256: self.parent_sha256.clone(),
            world: Some(self.world.0.clone()),
            world_hash: Some(self.world.1.clone()),
            corrections: self.corrections.clone(),
            imitation: self.imitation.clone(),
            command: self.command.clone(),
            job: serde_json::to_value(&self.spec)?,
        });
        Ok(lineage)
    }

    /// The policy's actions at `states` in `stages` (union space): sampled, as it acts in
    /// training, and its means, unclamped (behaviour cloning's anchor states and labels).
    pub fn policy_actions(
        &mut self,
        states: &[Vec<f32>],
        stages: &[usize],
    ) -> Result<PolicyActions> {
        let Learner::Ppo(ppo) = &mut self.learner else {
            return Err(invalid!("behaviour cloning is for the PPO learners"));
        };
        // The masks weigh only the log-probabilities, which are not wanted here.
        let masks = vec![vec![1.0; ppo.net.layout().actions]; states.len()];
        let sampled = ppo.act_batch(states, stages, &masks, false)?.0;
        let means = ppo.act_batch(states, stages, &masks, true)?.0;
        Ok((sampled, means))
    }

    /// The world's name and hash.
    pub fn world(&self) -> (&str, &str) {
        (&self.world.0, &self.world.1)
    }

    /// Environment steps trained so far (a resumed run starts at the checkpoint's).
    pub fn steps(&self) -> u64 {
        self.done
    }

    /// Whether the budget is spent or the early-stop rule fired.
    pub fn finished(&self) -> bool {
        self.done >= self.spec.steps || self.stopped_early
    }

    pub fn stopped_early(&self) -> bool {
        self.stopped_early
    }

    /// Episodes the early-stop rule looks back over.
    pub fn early_stop_window(&self) -> usize {
        match self.learner {
            Learner::Sac(_) => self.spec.sac.early_stop_window,
            Learner::Ppo(_) => self.spec.config.early_stop_window,
        }
    }

    /// One rollout and one learner update (PPO: one update over the rollout; SAC: the
    /// rollout stored, then gradient steps from the replay buffer).
    pub fn iterate(&mut self) -> Result<Iteration> {
        let remaining = self.spec.steps.saturating_sub(self.done) as usize;
        let per_iteration = match self.learner {
            Learner::Ppo(_) => self.spec.config.rollout_steps,
            Learner::Sac(_) => self.spec.sac.rollout_steps,
        };
        let steps_per_env = per_iteration.min(remaining.max(1)).div_ceil(self.env_count);
        let (rollout, stats) = match &mut self.learner {
            Learner::Ppo(ppo) => {
                let rollout = self.envs.collect(ppo.as_mut(), steps_per_env)?;
                let progress = (self.done + rollout.len() as u64) as f64 / self.spec.steps as f64;
                let stats = ppo.update(&rollout, progress)?;
                (rollout, stats)
            }
            Learner::Sac(sac) => {
                let rollout = self.envs.collect(sac.as_mut(), steps_per_env)?;
                sac.store(&rollout);
                let s = sac.update(rollout.len())?;
                let stats = crm_learn::UpdateStats {
                    policy_loss: s.actor_loss,
                    value_loss: s.critic_loss,
                    entropy: s.entropy,
                    approx_kl: 0.0,
                    clipfrac: 0.0,
                    learning_rate: self.spec.sac.learning_rate,
                    ..crm_learn::UpdateStats::default()
                };
                (rollout, stats)
            }
        };
        self.done += rollout.len() as u64;
        self.iteration += 1;
        for episode in &rollout.episodes {
            self.stopped_early |= self.early_stop.record(episode.success);
            self.last_100.record(episode.success);
        }
        for episode in &rollout.episodes {
            if let Some(task) = episode.tag {
                self.tasks.record(task, episode.success);
            }
        }
        if self.curriculum {
            let weights = self.tasks.weights();
            for env in self.envs.envs_mut() {
                env.env_mut()
                    .inner_mut()
                    .set_task_weights(Some(weights.clone()))?;
            }
        }
        let episodes = rollout.episodes.len() as u64;
        let per_episode = |value: fn(&Episode) -> f64| {
            (episodes > 0)
                .then(|| rollout.episodes.iter().map(value).sum::<f64>() / episodes as f64)
        };
        let mut mix = vec![0usize; self.layout.stages];
        for &stage in &rollout.stages {
            mix[stage] += 1;
        }
        let elapsed = self.started.elapsed().as_secs_f64();
        let iteration = Iteration {
            iteration: self.iteration,
            steps: self.done,
            wall_s: elapsed,
            steps_per_s: (self.done - self.start_steps) as f64 / elapsed.max(1e-9),
            episodes,
            successes: rollout.episodes.iter().filter(|e| e.success).count() as u64,
            success_rate_last_100: f64::from(self.last_100.success_rate()),
            mean_return: per_episode(|e| f64::from(e.total_return)),
            mean_intra_return: per_episode(|e| f64::from(e.intra_return)),
            mean_transition_return: per_episode(|e| f64::from(e.transition_return)),
            mean_episode_length: per_episode(|e| e.length as f64),
            stage_mix: mix
                .iter()
                .zip(&self.stage_names)
                .filter(|(count, _)| **count > 0)
                .map(|(count, name)| (name.clone(), *count as f64 / rollout.len().max(1) as f64))
                .collect(),
            policy_loss: f64::from(stats.policy_loss),
            value_loss: f64::from(stats.value_loss),
            entropy: f64::from(stats.entropy),
            approx_kl: f64::from(stats.approx_kl),
            clipfrac: f64::from(stats.clipfrac),
            learning_rate: stats.learning_rate,
            task_success: self
                .task_ids
                .iter()
                .enumerate()
                .filter(|&(task, _)| self.tasks.episodes(task) > 0)
                .map(|(task, id)| (id.clone(), f64::from(self.tasks.success_rate(task))))
                .collect(),
        };
        if let Some(recorder) = &self.recorder {
            lock(recorder).log_iteration(&iteration);
        }
        Ok(iteration)
    }

    /// The run's training state besides the networks: the header's part and the tensors.
    fn state(&self) -> Result<(RunState, Vec<(String, candle_core::Tensor)>)> {
        let envs = self.envs.states();
        let mut tensors = run_state::tensors(&envs, None)?;
        let (mut ppo, mut sac) = (None, None);
        match &self.learner {
            Learner::Ppo(learner) => {
                let learner = learner.state();
                tensors.extend(run_state::moment_tensors(
                    "adam",
                    &learner.adam_m,
                    &learner.adam_v,
                )?);
                ppo = Some(PpoRecord {
                    adam_step: learner.adam_step,
                    noise: learner.noise,
                    returns: learner.returns,
                    return_stats: learner.return_stats,
                });
            }
            Learner::Sac(learner) => {
                let (record, more) = learner.state()?;
                tensors.extend(more);
                sac = Some(record);
            }
        }
        let records = envs
            .iter()
            .zip(self.envs.envs())
            .map(|(env, crm_env)| EnvRecord {
                episode: env.episode,
                noise: env.noise,
                steps: env.actions.len(),
                task_weights: crm_env
                    .env()
                    .inner()
                    .episode_task_weights()
                    .map(<[f32]>::to_vec),
            })
            .collect();
        let state = RunState {
            made_on: run_state::this_machine(),
            iteration: self.iteration,
            early_stop: self.early_stop.outcomes(),
            last_100: self.last_100.outcomes(),
            tasks: self.tasks.outcomes(),
            envs: records,
            ppo,
            sac,
        };
        Ok((state, tensors))
    }

    /// Writes the current networks as a checkpoint (with the training state while the run
    /// is unfinished).
    pub fn save(&self, path: &Path) -> Result<()> {
        self.save_as(path, !self.finished())
    }

    /// Writes the current networks alone, without the training state: for a place that
    /// cannot take the whole state (a coordinator whose checkpoint limit a large replay
    /// buffer exceeds). A run resumed from it goes on as from an older checkpoint.
    pub fn save_policy(&self, path: &Path) -> Result<()> {
        self.save_as(path, false)
    }

    fn save_as(&self, path: &Path, with_state: bool) -> Result<()> {
        let header = CheckpointHeader {
            format: FORMAT.to_string(),
            algorithm: self.spec.algorithm.name().to_string(),
            spec_hash: self.spec_hash.clone(),
            env_version: grasp_sim::ENV_VERSION.to_string(),
            seed: self.spec.seed,
            steps: self.done,
            layout: self.layout,
            hidden: match self.learner {
                Learner::Ppo(_) => self.spec.config.hidden.clone(),
                Learner::Sac(_) => self.spec.sac.hidden.clone(),
            },
            config: match self.learner {
                Learner::Ppo(_) => serde_json::to_value(&self.spec.config)?,
                Learner::Sac(_) => serde_json::to_value(&self.spec.sac)?,
            },
            // `Checkpoint::save_sac` writes CRM-SAC's.
            activation: None,
            world: Some(self.world.0.clone()),
            world_hash: Some(self.world.2.clone()),
            lineage: self.lineage()?,
            state: None,
        };
        // Write beside and rename, so a reader never sees half a checkpoint.
        let partial = path.with_extension("safetensors.partial");
        let (header, tensors) = if !with_state {
            (header, Vec::new())
        } else {
            let (state, tensors) = self.state()?;
            let header = CheckpointHeader {
                state: Some(state),
                ..header
            };
            (header, tensors)
        };
        match &self.learner {
            Learner::Ppo(ppo) => Checkpoint::save_with(&ppo.net, &header, &tensors, &partial)?,
            Learner::Sac(sac) => Checkpoint::save_sac(&sac.nets, &header, &tensors, &partial)?,
        }
        std::fs::rename(&partial, path).map_err(|error| Error::Io {
            path: format!("moving the checkpoint to {}", path.display()),
            error,
        })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(algorithm: Algorithm, init_log_std: Option<f64>) -> TrainSpec {
        let mut spec: TrainSpec = serde_json::from_value(serde_json::json!({
            "algorithm": algorithm.name(),
            "steps": 64,
            "envs": 1,
            "task": "mouse-press",
            "config": {"rollout_steps": 64},
        }))
        .expect("spec");
        spec.config.init_log_std = init_log_std;
        spec
    }

    fn log_std(trainer: &Trainer) -> Vec<f32> {
        let Learner::Ppo(ppo) = &trainer.learner else {
            panic!("a PPO learner");
        };
        ppo.net.std().expect("std").iter().map(|s| s.ln()).collect()
    }

    fn all_near(values: &[f32], expected: f32) -> bool {
        values.iter().all(|v| (v - expected).abs() < 1e-6)
    }

    #[test]
    fn init_log_std_sets_a_fresh_or_fine_tuned_policys_noise_and_a_resume_keeps_its_own() {
        let env = Env::default();
        let new = |start, init| Trainer::new(spec(Algorithm::CrmPpo, start), &env, init, None);
        let fresh = new(None, None).expect("fresh");
        assert!(all_near(&log_std(&fresh), 0.0), "{:?}", log_std(&fresh));
        let started = new(Some(-2.0), None).expect("started");
        assert!(all_near(&log_std(&started), -2.0));

        let dir = std::env::temp_dir().join(format!("crm-start-log-std-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("crm-ppo.safetensors");
        started.save(&path).expect("save");
        // A fine-tune takes the job's noise, or keeps the checkpoint's without one.
        let tuned = new(Some(-1.0), Some(Init::FineTune(&path))).expect("fine-tune");
        assert!(all_near(&log_std(&tuned), -1.0));
        let kept = new(None, Some(Init::FineTune(&path))).expect("fine-tune");
        assert!(all_near(&log_std(&kept), -2.0));
        // The child's header carries its parent's stage and its own, with the parent's hash.
        let child = dir.join("child.safetensors");
        tuned.save(&child).expect("save");
        let lineage = Checkpoint::read_header(&child).expect("header").lineage;
        let kinds: Vec<&str> = lineage.iter().map(|s| s.kind.as_str()).collect();
        assert_eq!(kinds, ["train", "fine-tune"]);
        assert_eq!(lineage[0].parent_sha256, None);
        assert_eq!(
            lineage[1].parent_sha256.as_deref(),
            Some(file_sha256(&path).expect("hash").as_str())
        );
        assert_eq!(lineage[1].job["config"]["init_log_std"], -1.0);
        // The older name does the same.
        let mut old = spec(Algorithm::CrmPpo, None);
        old.start_log_std = Some(-1.0);
        let by_old_name = Trainer::new(old, &env, Some(Init::FineTune(&path)), None);
        assert!(all_near(&log_std(&by_old_name.expect("fine-tune")), -1.0));
        // A resume goes on with what the run learned, whatever the spec says.
        let resumed = new(Some(-1.0), Some(Init::Resume(&path))).expect("resume");
        assert!(all_near(&log_std(&resumed), -2.0));
        std::fs::remove_dir_all(&dir).ok();

        let refused = |spec: TrainSpec, field: &str| {
            let err = Trainer::new(spec, &env, None, None).err().expect("refused");
            assert!(err.to_string().contains(field), "{err}");
        };
        refused(spec(Algorithm::CrmPpo, Some(-6.0)), "config.init_log_std");
        let mut sac = spec(Algorithm::CrmSac, None);
        sac.start_log_std = Some(-1.0);
        refused(sac, "start_log_std");
        let mut both = spec(Algorithm::CrmPpo, Some(-1.0));
        both.start_log_std = Some(-1.0);
        refused(both, "start_log_std");
    }
}
