//! Anchor states for behaviour cloning: the starting policy's own episodes on the tasks that
//! are not demonstrated, each step labelled with its mean action. Cloned beside the oracle's
//! demonstrations they hold a trained policy to what it does there: one network serves every
//! task and stage, so a regression on one task's rows alone moves every weight (measured in
//! docs/notebook/worlds.md, "Teaching `t07` by demonstration").

use crm_learn::Demos;
use grasp_sim::GraspEnv;
use rayon::prelude::*;

use crate::demos::{BLOCK, DemoSource, keeps};
use crate::error::Result;

pub use crate::train::PolicyActions;

/// Anchor states: `episodes` episodes of the policy that `act` runs (episode `k` resets with
/// `seed + k`; those of a block run side by side, their physics in parallel), every row of
/// `source.stages` except those of the tasks in `source.skip`, labelled with the policy's
/// own means. Cloned beside demonstrations they hold the policy to what it does on those
/// tasks: a shared network taught one task by regression otherwise drifts on all of them.
/// `None` when `progress` answers `false`.
pub fn policy_anchors(
    source: &DemoSource,
    episodes: u64,
    mut act: impl FnMut(&[Vec<f32>], &[usize]) -> Result<PolicyActions>,
    mut progress: impl FnMut(u64) -> bool,
) -> Result<Option<Demos>> {
    struct Running {
        env: crm::CrmEnv<GraspEnv>,
        stage: usize,
        state: Vec<f32>,
        over: bool,
        rows: Demos,
    }
    let mut all = Demos::default();
    let mut start = 0;
    while start < episodes {
        let end = (start + BLOCK).min(episodes);
        let mut running = (start..end)
            .map(|k| {
                let grasp = source.choice.env(source.benchmark, source.config.clone())?;
                let mut env = crm::CrmEnv::new(source.machine.clone(), grasp, crm::RewardMode::Crm);
                let (stage, state) = env.reset(source.seed.wrapping_add(k))?;
                let over = source.skip.contains(&env.env().task_index());
                Ok(Running {
                    env,
                    stage,
                    state,
                    over,
                    rows: Demos::default(),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        loop {
            let live: Vec<usize> = (0..running.len()).filter(|&i| !running[i].over).collect();
            if live.is_empty() {
                break;
            }
            let states: Vec<Vec<f32>> = live.iter().map(|&i| running[i].state.clone()).collect();
            let stages: Vec<usize> = live.iter().map(|&i| running[i].stage).collect();
            let (executed, means) = act(&states, &stages)?;
            let mut actions = vec![None; running.len()];
            for (j, &i) in live.iter().enumerate() {
                let r = &mut running[i];
                if keeps(source.stages, r.stage) {
                    r.rows.states.push(states[j].clone());
                    r.rows.stages.push(r.stage);
                    r.rows.masks.push(r.env.machine().action_mask(r.stage));
                    r.rows.actions.push(means[j].clone());
                }
                actions[i] = executed.get(j).cloned();
            }
            running
                .par_iter_mut()
                .zip(actions)
                .filter_map(|(r, action)| action.map(|a| (r, a)))
                .try_for_each(|(r, action)| -> Result<()> {
                    let step = r.env.step(&action)?;
                    r.over = step.done || step.truncated;
                    (r.stage, r.state) = (step.stage, step.abstract_state);
                    Ok(())
                })?;
        }
        for r in running {
            all.extend(r.rows);
        }
        start = end;
        if !progress(end) {
            return Ok(None);
        }
    }
    Ok(Some(all))
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use grasp_sim::{Benchmark, SimConfig, TaskChoice};

    use super::*;
    use crate::EnvChoice;

    #[test]
    fn anchor_states_are_the_policys_own_rows_but_the_skipped_tasks_and_stages_filter_rows() {
        let benchmark = Arc::new(Benchmark::builtin());
        let machine = crm::Machine::from_spec(grasp_sim::spec::grasping_spec()).expect("machine");
        let mouse = benchmark.task_index("mouse-press").expect("task");
        let stapler = benchmark.task_index("stapler-press").expect("task");
        let choice = EnvChoice {
            tasks: TaskChoice::Subset(vec![mouse, stapler]),
            topologies: None,
        };
        let config = SimConfig {
            max_episode_steps: 12,
            ..SimConfig::default()
        };
        let grasp = machine.stage_id("grasp").expect("grasp stage");
        let skip = [stapler];
        let source = DemoSource {
            benchmark: &benchmark,
            config: &config,
            machine: &machine,
            choice: &choice,
            seed: 5,
            noise: 0.0,
            shifts: &[],
            stages: &[],
            skip: &skip,
        };
        // A policy that holds still and means 0.25 everywhere: each mouse episode gives its 12
        // steps, labelled 0.25; the stapler's give none.
        let width = grasp_sim::observation::ACTIONS.len();
        let idle = |states: &[Vec<f32>], _: &[usize]| {
            Ok((
                vec![vec![0.0; width]; states.len()],
                vec![vec![0.25; width]; states.len()],
            ))
        };
        let mut told = Vec::new();
        let rows = policy_anchors(&source, 10, idle, |done| {
            told.push(done);
            true
        })
        .expect("anchors")
        .expect("not cancelled");
        assert_eq!(told, vec![10]);
        assert!(
            !rows.is_empty() && rows.len() % 12 == 0,
            "{} rows",
            rows.len()
        );
        assert!(rows.len() < 12 * 10, "the stapler's episodes give no rows");
        assert!(rows.actions.iter().all(|a| a.iter().all(|&v| v == 0.25)));
        assert_eq!(rows.stages.len(), rows.len());
        // An idle hand never reaches the grasp stage: keeping only it keeps nothing.
        let only_grasp = [grasp];
        let none = policy_anchors(
            &DemoSource {
                stages: &only_grasp,
                ..source
            },
            10,
            idle,
            |_| true,
        )
        .expect("anchors")
        .expect("not cancelled");
        assert!(none.is_empty());
    }
}
