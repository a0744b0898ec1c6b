//! A run's environments: which world ([`EnvSpec`]: a world folder, or the built-in world with
//! another benchmark or spec file) and how the job runs it ([`grasp_sim::EnvSettings`]).
//! [`Env`] loads the world once and answers the machine, the settings and the environments
//! every job, command and benchmark builds from it.

use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use crm_api::ObjectiveMode;
use grasp_sim::{Benchmark, EnvSettings, GraspEnv, Protocol, SimConfig, World};
use serde::{Deserialize, Serialize};

use crate::error::{Context, Result};

/// Which world a run uses and how.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvSpec {
    /// A world folder (`world.json`), its files found in the folder or in `CRM_ASSETS`; the
    /// built-in world when absent.
    pub world: Option<PathBuf>,
    /// A benchmark file replacing the built-in world's objects and tasks (no `world` then).
    pub benchmark: Option<PathBuf>,
    /// A CRM spec file replacing the world's spec.
    pub spec: Option<PathBuf>,
    /// Randomization, protocol, finger actions, hold.
    pub settings: EnvSettings,
}

/// The world's protocol for a job's objective mode.
pub fn protocol(mode: ObjectiveMode) -> Protocol {
    match mode {
        ObjectiveMode::Scripted => Protocol::Scripted,
        ObjectiveMode::Learned => Protocol::Learned,
    }
}

/// An [`EnvSpec`] with its world loaded on first use (clones share it).
#[derive(Clone, Debug, Default)]
pub struct Env {
    spec: EnvSpec,
    loaded: Arc<OnceLock<World>>,
}

impl Env {
    pub fn new(spec: EnvSpec) -> Self {
        Self {
            spec,
            loaded: Arc::default(),
        }
    }

    /// The world in `dir` (a job's `world`), run with the default settings.
    pub fn in_world(dir: PathBuf) -> Self {
        Self::new(EnvSpec {
            world: Some(dir),
            ..EnvSpec::default()
        })
    }

    pub fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    /// The world of the spec's folder, or the built-in one (with the spec's benchmark).
    pub fn world(&self) -> Result<&World> {
        if let Some(world) = self.loaded.get() {
            return Ok(world);
        }
        let world = match (&self.spec.world, &self.spec.benchmark) {
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

    pub fn benchmark(&self) -> Result<Arc<Benchmark>> {
        Ok(self.world()?.benchmark.clone())
    }

    /// The machine of the spec file, the world's spec, or the built-in grasping machine;
    /// a finger the hand lacks is masked ([`World::machine_with`]).
    pub fn machine(&self) -> Result<crm::Machine> {
        match &self.spec.spec {
            Some(_) => self.machine_or(grasp_sim::spec::grasping_spec()),
            None => Ok(self.world()?.machine()?),
        }
    }

    /// The machine of the spec file, or of `default`, in this world.
    pub fn machine_or(&self, default: crm::Spec) -> Result<crm::Machine> {
        let spec = match &self.spec.spec {
            Some(path) => crm::Spec::load(path).context("loading the crm spec")?,
            None => default,
        };
        grasp_sim::spec::check_compatible(&spec)?;
        Ok(self.world()?.machine_with(spec)?)
    }

    /// One environment in `config` drawing `choice`'s tasks and topologies.
    pub fn grasp_env(&self, config: SimConfig, choice: &crate::EnvChoice) -> Result<GraspEnv> {
        choice.env(&self.world()?.benchmark, config)
    }

    /// The world's settings as the spec runs it.
    pub fn config(&self) -> Result<SimConfig> {
        Ok(self.world()?.sim_config(&self.spec.settings))
    }

    /// The world's settings with a job's objective mode and, when given, its `hold_s` seconds
    /// of steady hold, else the paper's 5 s (a job's spec carries the hold it asks).
    pub fn config_for(&self, objective: ObjectiveMode, hold_s: Option<f64>) -> Result<SimConfig> {
        let settings = EnvSettings {
            protocol: protocol(objective),
            hold_s,
            ..self.spec.settings.clone()
        };
        Ok(self.world()?.sim_config(&settings))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_world_and_a_job_s_settings() {
        let env = Env::default();
        assert_eq!(env.world().expect("world").name, "crm");
        assert_eq!(env.config().expect("config"), SimConfig::default());
        let config = env
            .config_for(ObjectiveMode::Learned, Some(2.0))
            .expect("config");
        assert_eq!((config.protocol, config.hold_s), (Protocol::Learned, 2.0));
        let machine = env.machine().expect("machine");
        assert_eq!(
            machine.spec().hash(),
            grasp_sim::spec::grasping_machine().spec().hash()
        );
        let missing = Env::new(EnvSpec {
            world: Some("/no/such/world".into()),
            ..EnvSpec::default()
        });
        let err = missing.world().expect_err("no world");
        assert!(
            err.to_string()
                .starts_with("loading the world /no/such/world: "),
            "{err}"
        );
    }
}
