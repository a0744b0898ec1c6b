//! Oracle demonstrations for behaviour cloning: the scripted controller (`grasp_sim::oracle`,
//! with privileged state) runs episodes through the grasping machine; its successful
//! episodes become (abstract state, stage, action, mask) rows for `Ppo::imitate`.

use std::sync::Arc;

use crm_learn::Demos;
use grasp_sim::oracle::Oracle;
use grasp_sim::{Benchmark, GraspEnv, SimConfig};
use rayon::prelude::*;

use super::EnvChoice;

/// Runs `episodes` oracle episodes (seeds `seed`, `seed + 1`, ...) on the job's task choice;
/// returns the rows of the successful ones and how many succeeded.
pub fn oracle_demos(
    benchmark: &Arc<Benchmark>,
    config: &SimConfig,
    machine: &crm::Machine,
    choice: &EnvChoice,
    episodes: u64,
    seed: u64,
) -> anyhow::Result<(Demos, u64)> {
    let results: Vec<anyhow::Result<Option<Demos>>> = (0..episodes)
        .into_par_iter()
        .map(|k| {
            let mut grasp = GraspEnv::new(benchmark.clone(), config.clone());
            choice.apply(&mut grasp)?;
            let mut env = crm::CrmEnv::new(machine.clone(), grasp, crm::RewardMode::Crm);
            let (mut stage, mut state) = env.reset(seed.wrapping_add(k))?;
            let mut oracle = Oracle::new();
            let mut demos = Demos::default();
            loop {
                let name = env.machine().stage_name(stage).to_string();
                let action: Vec<f32> = oracle
                    .act(env.env(), &name)
                    .iter()
                    .map(|a| a.clamp(-1.0, 1.0))
                    .collect();
                demos.states.push(state.clone());
                demos.stages.push(stage);
                demos.masks.push(env.machine().action_mask(stage));
                demos.actions.push(action.clone());
                let step = env.step(&action)?;
                if step.done || step.truncated {
                    let success = step.done && env.machine().stage_name(step.stage) == "success";
                    return Ok(success.then_some(demos));
                }
                (stage, state) = (step.stage, step.abstract_state);
            }
        })
        .collect();
    let mut all = Demos::default();
    let mut successes = 0;
    for result in results {
        if let Some(demos) = result? {
            successes += 1;
            all.extend(demos);
        }
    }
    Ok((all, successes))
}
