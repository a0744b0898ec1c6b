//! Jobs the worker runs, shared by the command line (`crm train`, `crm eval`) and the service
//! worker (`crm worker`): a training run that advances one PPO iteration at a time and can
//! resume from a checkpoint, and a checkpoint evaluation over random tasks (Table I).

pub mod anchors;
pub mod demos;
pub mod eval;
pub mod train;

pub use train::Init;

use crm_api::Algorithm;
use grasp_sim::benchmark::Topology;
use grasp_sim::{Benchmark, GraspEnv, TaskChoice};

/// The reward mode each algorithm learns from (paper, section V-A).
/// Refuses a checkpoint trained in a world whose hand profile, spec, sensors or hand files
/// differ from `world`'s (a checkpoint without a world was trained in the built-in one). A
/// checkpoint that recorded the profile hash alone (written before the hand's files were in
/// the hash) is held to the profile, the spec and the sensors.
pub fn check_world(
    header: &crm_learn::checkpoint::CheckpointHeader,
    world: &grasp_sim::World,
    path: &std::path::Path,
) -> anyhow::Result<()> {
    static BUILTIN: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    let builtin = BUILTIN.get_or_init(|| grasp_sim::World::builtin().profile_hash);
    let hash = header.world_hash.as_deref().unwrap_or(builtin);
    if hash != world.hash && hash != world.profile_hash {
        anyhow::bail!(
            "checkpoint {} was trained in world {:?} (hash {hash}), this is world {:?} (hash {}): \
             the hand profile, the CRM spec, the sensors or the hand's files differ, so its \
             observations and actions mean other things here",
            path.display(),
            header.world.as_deref().unwrap_or("crm"),
            world.name,
            world.hash
        );
    }
    Ok(())
}

pub fn reward_mode(algorithm: Algorithm) -> crm::RewardMode {
    match algorithm {
        Algorithm::Ippo => crm::RewardMode::Sparse,
        Algorithm::Lppo => crm::RewardMode::Dense,
        _ => crm::RewardMode::Crm,
    }
}

/// Which tasks and topologies a job's environments use.
#[derive(Clone, Debug)]
pub struct EnvChoice {
    pub tasks: TaskChoice,
    pub topologies: Option<Vec<Topology>>,
}

impl EnvChoice {
    /// From a job's `task`/`tasks` and `topology` (`task`, `auto` or a topology name).
    pub fn of(
        benchmark: &Benchmark,
        task: &Option<String>,
        tasks: &[String],
        topology: &Option<String>,
    ) -> anyhow::Result<Self> {
        let indices = crm_api::jobs::task_list(task, tasks)
            .iter()
            .map(|id| crate::commands::task_index(benchmark, id))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let tasks = match indices.as_slice() {
            [] => TaskChoice::Random,
            [one] => TaskChoice::Fixed(*one),
            _ => TaskChoice::Subset(indices),
        };
        let topologies = match topology.as_deref() {
            None | Some("task") => None,
            Some("auto") => Some(crate::commands::topology::picks(benchmark, None)?),
            Some(name) => {
                let forced = Topology::from_name(name).ok_or_else(|| {
                    anyhow::anyhow!(
                        "topology: unknown topology {name:?} (task, auto, or one of {})",
                        Topology::ALL.map(Topology::name).join(", ")
                    )
                })?;
                Some(vec![forced; benchmark.tasks.len()])
            }
        };
        Ok(Self { tasks, topologies })
    }

    /// Applies the choice to an environment.
    pub fn apply(&self, env: &mut GraspEnv) -> anyhow::Result<()> {
        env.set_task_choice(self.tasks.clone())?;
        env.set_topologies(self.topologies.clone())?;
        Ok(())
    }
}
