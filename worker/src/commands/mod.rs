//! One module per subcommand.

pub mod bench;
mod bench_hold;
pub mod certs;
pub mod checkpoint;
pub mod eval;
pub mod oracle;
pub mod record;
pub mod remote;
pub mod replay;
pub mod results;
pub mod service;
pub mod tasks;
pub mod topology;
pub mod train;
pub mod world;

use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use std::io::Write;

use anyhow::Context;
use crm_api::ObjectiveMode;
use grasp_sim::{Benchmark, SimConfig, World};

/// Options every environment-running command shares.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct EnvArgs {
    /// A world folder (`world.json`: hand, objects, tasks, spec, sensors) to run instead of
    /// the built-in world; its files are found in the folder or in `CRM_ASSETS`.
    #[arg(long, value_name = "DIR", conflicts_with = "benchmark")]
    pub world: Option<PathBuf>,
    /// A benchmark file to use instead of the built-in one (with the built-in hand).
    #[arg(long, value_name = "FILE")]
    pub benchmark: Option<PathBuf>,
    /// A CRM spec file to use instead of the built-in grasping spec.
    #[arg(long, value_name = "FILE")]
    pub spec: Option<PathBuf>,
    /// Turn domain randomization off (it is on by default, as in the paper).
    #[arg(long)]
    pub no_randomization: bool,
    /// Who executes the objective once the grasp is ready (a job's `objective`):
    /// `scripted`, the paper's protocol (the arm, by script), or `learned` (the policy).
    #[arg(long, value_enum, default_value_t = ObjectiveMode::Scripted)]
    pub protocol: ObjectiveMode,
    /// How finger actions act: `closing` only (the authors' code, the default), or `signed`
    /// increments that also open the hand.
    #[arg(long, value_enum, default_value_t = FingerMode::Closing)]
    pub finger_actions: FingerMode,
    /// Seconds of steady hold the judge asks of lift, pull, lever, wrap and handle tasks (a
    /// job's `hold_s`; default: the paper's 5 s). A shorter hold simulates less but does not
    /// teach grasps that last 5 s (docs/LEARNING.md); evaluate with the default to report the
    /// paper's test.
    #[arg(long, value_name = "SECONDS", value_parser = parse_hold_s)]
    pub hold_s: Option<f64>,
    /// The world, read once.
    #[arg(skip)]
    loaded: Arc<OnceLock<World>>,
}

/// `--hold-s`: seconds within [`crm_api::jobs::HOLD_S_RANGE`].
fn parse_hold_s(text: &str) -> Result<f64, String> {
    let hold: f64 = text
        .parse()
        .map_err(|_| format!("{text:?} is not a number of seconds"))?;
    crm_api::jobs::check_hold_s(Some(hold))?;
    Ok(hold)
}

/// `--finger-actions`: see [`grasp_sim::FingerActions`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum FingerMode {
    #[default]
    Closing,
    Signed,
}

/// The world's protocol for a job's objective mode.
pub fn protocol(mode: ObjectiveMode) -> grasp_sim::Protocol {
    match mode {
        ObjectiveMode::Scripted => grasp_sim::Protocol::Scripted,
        ObjectiveMode::Learned => grasp_sim::Protocol::Learned,
    }
}

impl EnvArgs {
    /// The same options running the world in `dir` (a job's `world`).
    pub fn in_world(&self, dir: Option<PathBuf>) -> Self {
        Self {
            world: dir,
            loaded: Arc::default(),
            ..self.clone()
        }
    }

    /// The world of `--world`, or the built-in one (with `--benchmark`'s objects and tasks).
    pub fn world(&self) -> anyhow::Result<&World> {
        if let Some(world) = self.loaded.get() {
            return Ok(world);
        }
        let world = match (&self.world, &self.benchmark) {
            (Some(dir), _) => {
                World::load(dir).with_context(|| format!("loading the world {}", dir.display()))?
            }
            (None, Some(path)) => {
                let mut world = World::builtin();
                world.benchmark = Arc::new(Benchmark::load(path).context("loading the benchmark")?);
                world
            }
            (None, None) => World::builtin(),
        };
        Ok(self.loaded.get_or_init(|| world))
    }

    pub fn benchmark(&self) -> anyhow::Result<Arc<Benchmark>> {
        Ok(self.world()?.benchmark.clone())
    }

    /// The machine from `--spec`, the world's spec, or the built-in grasping machine.
    pub fn machine(&self) -> anyhow::Result<crm::Machine> {
        let spec = self.world()?.spec.clone();
        self.machine_or(spec.unwrap_or_else(grasp_sim::spec::grasping_spec))
    }

    /// The machine from `--spec`, or `default`.
    pub fn machine_or(&self, default: crm::Spec) -> anyhow::Result<crm::Machine> {
        let spec = match &self.spec {
            Some(path) => crm::Spec::load(path).context("loading the crm spec")?,
            None => default,
        };
        grasp_sim::spec::check_compatible(&spec)?;
        Ok(crm::Machine::from_spec(spec)?)
    }

    /// The world's settings; a job's `objective` and `hold_s` decide the protocol and the
    /// hold (see [`Self::config_for`]).
    pub fn config(&self) -> SimConfig {
        self.config_for(self.protocol, self.hold_s)
    }

    /// The world's settings with the protocol of `objective` and, when given, `hold_s`
    /// seconds of steady hold (a job's; the CLI commands copy `--hold-s` into their spec),
    /// else the paper's 5 s.
    pub fn config_for(&self, objective: ObjectiveMode, hold_s: Option<f64>) -> SimConfig {
        let mut config = if self.no_randomization {
            SimConfig::deterministic()
        } else {
            let mut config = SimConfig::default();
            // An unreadable world is reported by `benchmark()`, which every command calls.
            if let Ok(World {
                randomization: Some(randomization),
                ..
            }) = self.world()
            {
                config.randomization = randomization.clone();
            }
            config
        };
        config.protocol = protocol(objective);
        if let Some(hold) = hold_s {
            config.hold_s = hold as f32;
        }
        config.finger_actions = match self.finger_actions {
            FingerMode::Signed => grasp_sim::FingerActions::Signed,
            FingerMode::Closing => grasp_sim::FingerActions::Closing,
        };
        config
    }
}

/// A JSON settings file (`--config`-style flags) or, without one, the defaults.
pub fn read_json<T: serde::de::DeserializeOwned + Default>(
    path: &Option<PathBuf>,
) -> anyhow::Result<T> {
    match path {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
        }
        None => Ok(T::default()),
    }
}

/// The index of a task by id, or a message naming the flag and pointing at `crm tasks`.
pub fn task_index(benchmark: &Benchmark, id: &str) -> anyhow::Result<usize> {
    benchmark
        .task_index(id)
        .with_context(|| format!("--task: unknown task {id:?} (see `crm tasks`)"))
}

/// Writes to standard output; a closed pipe (`crm tasks | head`) ends the output quietly.
pub fn emit(text: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(err) if err.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}
