//! `Batch`: N grasping environments, each inside the grasping machine, stepped together on
//! rayon's threads with Gymnasium's same-step autoreset. No Python here: `lib.rs` binds it.
//!
//! An environment's step is the Rust one (`crm::CrmEnv<GraspEnv>`), so an episode from Python
//! is the episode `crm replay` prints, bit for bit (python/tests).

use crm::{CrmEnv, EnvStep, Environment, Machine, RewardMode, StageId};
use grasp_sim::{EnvSettings, GraspEnv, Protocol, World, render};
use rayon::prelude::*;

/// What every environment of a batch is made with (the Python constructor's arguments).
#[derive(Clone, Debug)]
pub struct Options {
    /// A world folder (`world.json`); the built-in world when absent.
    pub world: Option<std::path::PathBuf>,
    /// Task ids to draw from (uniformly, with each episode's seed); all tasks when empty.
    pub tasks: Vec<String>,
    pub protocol: Protocol,
    pub randomize: bool,
    pub reward_mode: RewardMode,
    /// Seconds of steady hold the judge asks (default: the paper's 5 s).
    pub hold_s: Option<f64>,
}

/// A `GraspEnv` that keeps the global observation and the events of its last step, which the
/// machine consumes and the Python side returns.
struct Observed {
    inner: GraspEnv,
    observation: Vec<f32>,
    events: Vec<&'static str>,
}

impl Environment for Observed {
    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
        self.observation = self.inner.reset(seed)?;
        self.events.clear();
        Ok(self.observation.clone())
    }

    fn set_stage(&mut self, stage: &str) {
        self.inner.set_stage(stage);
    }

    fn step(&mut self, action: &[f32]) -> Result<EnvStep, String> {
        let step = self.inner.step(action)?;
        self.observation.clone_from(&step.observation);
        self.events.clone_from(&step.events);
        Ok(step)
    }
}

/// The state right after a reset: what `reset` returns and an autoreset puts in `info`.
#[derive(Clone, Debug)]
pub struct Start {
    pub observation: Vec<f32>,
    pub stage: StageId,
    pub task: String,
}

/// One environment's step: the Gymnasium 5-tuple's parts and the CRM's.
#[derive(Clone, Debug)]
pub struct Step {
    pub observation: Vec<f32>,
    /// The stage after the step, the reward parts after the reward mode, the event that moved
    /// the machine, every event that held.
    pub stage: StageId,
    pub intra: f32,
    pub transition: f32,
    pub event: Option<String>,
    pub events: Vec<&'static str>,
    pub terminated: bool,
    pub truncated: bool,
    /// How the episode ended as reports count it (`success`, `failure (dropped)`, ...), at
    /// its end only.
    pub outcome: Option<String>,
    pub task: String,
    /// The next episode's start when this step ended one and the batch autoresets.
    pub reset: Option<Start>,
}

struct Slot {
    env: CrmEnv<Observed>,
    stage: StageId,
    /// Where the renderer looks from this episode (framed on its start).
    camera: render::Camera,
    /// The seed of the last explicit reset and the episodes since: autoresets draw from them.
    seed: u64,
    episode: u64,
}

/// N environments.
pub struct Batch {
    slots: Vec<Slot>,
    machine: Machine,
}

/// The seed of an environment's `episode`-th episode after a reset with `seed` (SplitMix64
/// of both: distinct, reproducible streams).
fn episode_seed(seed: u64, episode: u64) -> u64 {
    let mut z = seed ^ episode.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Batch {
    /// `count` environments of the options' world; an unknown task id is an error naming it.
    pub fn new(count: usize, options: &Options) -> Result<Self, String> {
        let world = match &options.world {
            Some(dir) => World::load(dir).map_err(|e| format!("world: {e}"))?,
            None => World::builtin(),
        };
        let choice = world
            .task_choice(&options.tasks)
            .map_err(|e| format!("task: {e}"))?;
        let config = world.sim_config(&EnvSettings {
            randomization: options.randomize,
            protocol: options.protocol,
            hold_s: options.hold_s,
            ..EnvSettings::default()
        });
        let machine = world.machine().map_err(|e| format!("world: {e}"))?;
        let slots = (0..count)
            .map(|_| {
                let inner = world
                    .env(config.clone(), choice.clone())
                    .map_err(|e| e.to_string())?;
                let observed = Observed {
                    inner,
                    observation: Vec::new(),
                    events: Vec::new(),
                };
                Ok(Slot {
                    env: CrmEnv::new(machine.clone(), observed, options.reward_mode),
                    stage: machine.initial(),
                    camera: render::Camera::framing([0.0; 3], 0.6, 1, 1),
                    seed: 0,
                    episode: 0,
                })
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok(Self { slots, machine })
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }

    pub fn machine(&self) -> &Machine {
        &self.machine
    }

    /// Resets environment `k` with `seed`; its later autoresets draw from that seed.
    pub fn reset(&mut self, k: usize, seed: u64) -> Result<Start, String> {
        let slot = self.slots.get_mut(k).ok_or("no such environment")?;
        slot.seed = seed;
        slot.episode = 0;
        slot.start(seed)
    }

    /// Steps every environment with its row of `actions` (`len() x 8`, union space, checked
    /// by the caller) on rayon's threads; with `autoreset`, an environment whose episode
    /// ended starts its next one in the same call.
    pub fn step(&mut self, actions: &[f32], autoreset: bool) -> Result<Vec<Step>, String> {
        let width = grasp_sim::observation::ACTIONS.len();
        if actions.len() != self.slots.len() * width {
            return Err(format!(
                "action: {} values for {} environments of {width}",
                actions.len(),
                self.slots.len()
            ));
        }
        if self
            .slots
            .iter()
            .any(|slot| slot.env.machine().is_terminal(slot.stage))
        {
            return Err("an episode is over: reset first (or step with autoreset)".into());
        }
        self.slots
            .par_iter_mut()
            .zip(actions.par_chunks(width))
            .map(|(slot, action)| slot.step(action, autoreset))
            .collect()
    }

    /// Environment `k`'s scene now, `width` x `height` RGB, with its stage and task as a
    /// caption: the frames of `crm record --video`, from a camera fixed for the episode.
    pub fn render(&self, k: usize, width: u32, height: u32) -> Result<render::Frame, String> {
        let slot = self.slots.get(k).ok_or("no such environment")?;
        let env = &slot.env.env().inner;
        let parts = env.parts();
        let camera = render::Camera {
            width,
            height,
            ..slot.camera.clone()
        };
        let mut frame = render::render(&parts, env.grasp_location().map(Into::into), &camera);
        if !parts.is_empty() {
            let stage = self.machine.stage_name(slot.stage);
            frame.caption(&[(&env.task().id, [255; 3]), (stage, [255; 3])]);
        }
        Ok(frame)
    }
}

impl Slot {
    fn start(&mut self, seed: u64) -> Result<Start, String> {
        let (stage, _) = self.env.reset(seed).map_err(|e| e.to_string())?;
        self.stage = stage;
        let parts = self.env.env().inner.parts();
        self.camera = render::Camera::on_scene(&parts, 1, 1);
        Ok(Start {
            observation: self.env.env().observation.clone(),
            stage,
            task: self.env.env().inner.task().id.clone(),
        })
    }

    fn step(&mut self, action: &[f32], autoreset: bool) -> Result<Step, String> {
        let task = self.env.env().inner.task().id.clone();
        let out = self.env.step(action).map_err(|e| e.to_string())?;
        self.stage = out.stage;
        let ended = out.done || out.truncated;
        let outcome = ended.then(|| {
            let end = if out.done {
                self.env.machine().stage_name(out.stage)
            } else {
                "truncated"
            };
            self.env.env().inner.outcome_label(end)
        });
        let observed = self.env.env();
        let mut step = Step {
            observation: observed.observation.clone(),
            stage: out.stage,
            intra: out.intra_reward,
            transition: out.transition_reward,
            event: out.event,
            events: observed.events.clone(),
            terminated: out.done,
            truncated: out.truncated,
            outcome,
            task,
            reset: None,
        };
        if ended && autoreset {
            self.episode += 1;
            step.reset = Some(self.start(episode_seed(self.seed, self.episode))?);
        }
        Ok(step)
    }
}
