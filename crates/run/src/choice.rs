//! What a job's environments draw (tasks and topologies), the reward its algorithm learns
//! from, and whether a checkpoint belongs to a world.

use crm_api::Algorithm;
use grasp_sim::benchmark::Topology;
use std::sync::Arc;

use grasp_sim::{Benchmark, GraspEnv, SimConfig, TaskChoice};

use crate::error::{Result, invalid};

/// Refuses a checkpoint trained in a world whose hand profile, spec, sensors or hand files
/// differ from `world`'s (a checkpoint without a world was trained in the built-in one). A
/// checkpoint that recorded the profile hash alone (written before the hand's files were in
/// the hash) is held to the profile, the spec and the sensors.
pub fn check_world(
    header: &crm_learn::checkpoint::CheckpointHeader,
    world: &grasp_sim::World,
    path: &std::path::Path,
) -> Result<()> {
    static BUILTIN: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    let builtin = BUILTIN.get_or_init(|| grasp_sim::World::builtin().profile_hash);
    let hash = header.world_hash.as_deref().unwrap_or(builtin);
    if hash != world.hash && hash != world.policy_hash && hash != world.profile_hash {
        return Err(invalid!(
            "checkpoint {} was trained in world {:?} (hash {hash}), this is world {:?} (hash {}): \
             the hand profile, the CRM spec, the sensors or the hand's files differ, so its \
             observations and actions mean other things here",
            path.display(),
            header.world.as_deref().unwrap_or("crm"),
            world.name,
            world.hash
        ));
    }
    Ok(())
}

/// The reward mode each algorithm learns from (paper, section V-A).
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
    ) -> Result<Self> {
        let indices = crm_api::jobs::task_list(task, tasks)
            .iter()
            .map(|id| task_index(benchmark, id))
            .collect::<Result<Vec<_>>>()?;
        let tasks = match indices.as_slice() {
            [] => TaskChoice::Random,
            [one] => TaskChoice::Fixed(*one),
            _ => TaskChoice::Subset(indices),
        };
        let topologies = match topology.as_deref() {
            None | Some("task") => None,
            Some("auto") => Some(crate::topology::picks(benchmark, None)?),
            Some(name) => {
                let forced = Topology::from_name(name).ok_or_else(|| {
                    invalid!(
                        "topology: unknown topology {name:?} (task, auto, or one of {})",
                        Topology::ALL.map(Topology::name).join(", ")
                    )
                })?;
                Some(vec![forced; benchmark.tasks.len()])
            }
        };
        Ok(Self { tasks, topologies })
    }

    /// One environment of `benchmark` in `config` that draws this choice's tasks and
    /// topologies ([`grasp_sim::setup::make_env`], the world's factory).
    pub fn env(&self, benchmark: &Arc<Benchmark>, config: SimConfig) -> Result<GraspEnv> {
        let mut env = grasp_sim::setup::make_env(benchmark, config, self.tasks.clone())?;
        env.set_topologies(self.topologies.clone())?;
        Ok(env)
    }
}

/// The index of a task by id, or a message naming it and pointing at `crm tasks`.
pub fn task_index(benchmark: &Benchmark, id: &str) -> Result<usize> {
    benchmark
        .task_index(id)
        .ok_or_else(|| invalid!("--task: unknown task {id:?} (see `crm tasks`)"))
}
