//! Demonstrations for behaviour cloning from the scripted controller (`grasp_sim::oracle`, with
//! privileged state), through the grasping machine, as (abstract state, stage, action, mask)
//! rows for `Ppo::imitate` (a training job's imitation stage, [`crate::imitation`], runs it).
//! The oracle's executed actions may carry noise while its labels stay clean (DART, Laskey et
//! al., 2017), so the clone also sees how the oracle recovers from small mistakes.

use std::sync::Arc;

use crm_learn::Demos;
use grasp_sim::oracle::Oracle;
use grasp_sim::{Benchmark, SimConfig};
use rayon::prelude::*;

use crate::EnvChoice;
use crate::error::{Result, invalid};

/// Where demonstrations come from: the environments, the first seed and the noise on the
/// oracle's executed actions.
pub struct DemoSource<'a> {
    pub benchmark: &'a Arc<Benchmark>,
    pub config: &'a SimConfig,
    pub machine: &'a crm::Machine,
    pub choice: &'a EnvChoice,
    /// Episode `k` resets with seed `seed + k`.
    pub seed: u64,
    /// Standard deviation of Gaussian noise added to the oracle's executed action on each
    /// live dimension (DART, Laskey et al., 2017): the rows keep the clean label, so the
    /// clone also sees how the oracle recovers from small mistakes. 0: none.
    pub noise: f32,
    /// Per task index, the palm shift of the oracle ([`Oracle::with_shift`]); empty: none.
    pub shifts: &'a [[f32; 3]],
    /// The stages (indices) whose rows are kept; empty: every stage.
    pub stages: &'a [usize],
    /// Task indices whose episodes give no anchor rows (the demonstrated tasks; see
    /// [`crate::anchors::policy_anchors`]).
    pub skip: &'a [usize],
}

/// What a collection of demonstrations gave.
#[derive(Clone, Debug, Default)]
pub struct Collected {
    pub demos: Demos,
    pub episodes: u64,
    /// Episodes that ended in the `success` stage (their rows are the demonstrations).
    pub successes: u64,
    /// Rows of anchor states among `demos`.
    pub anchors: usize,
}

/// Runs `episodes` oracle episodes; keeps the rows of the successful ones (the tests' form of
/// [`oracle_demos_with`]).
#[cfg(test)]
pub fn oracle_demos(source: &DemoSource, episodes: u64) -> Result<Collected> {
    Ok(oracle_demos_with(source, episodes, |_| true)?.unwrap_or_default())
}

/// Episodes run in parallel per block of this many; progress is told between blocks.
pub(crate) const BLOCK: u64 = 64;

/// [`oracle_demos`], calling `progress(episodes done)` after each block of episodes; `None`
/// when `progress` answers `false` (the job was cancelled). The same demonstrations whatever
/// the block size or thread count: episode `k` runs with seed `seed + k`.
pub fn oracle_demos_with(
    source: &DemoSource,
    episodes: u64,
    mut progress: impl FnMut(u64) -> bool,
) -> Result<Option<Collected>> {
    let mut all = Collected {
        episodes,
        ..Collected::default()
    };
    let mut start = 0;
    while start < episodes {
        let end = (start + BLOCK).min(episodes);
        let results: Vec<Result<(bool, Demos)>> = (start..end)
            .into_par_iter()
            .map(|k| episode(source, source.seed.wrapping_add(k)))
            .collect();
        for result in results {
            let (success, demos) = result?;
            // The oracle's failures teach nothing.
            if success {
                all.successes += 1;
                all.demos.extend(demos);
            }
        }
        start = end;
        if !progress(end) {
            return Ok(None);
        }
    }
    Ok(Some(all))
}

/// One oracle episode; returns whether it succeeded and its rows (the clean labels).
fn episode(source: &DemoSource, seed: u64) -> Result<(bool, Demos)> {
    let grasp = source.choice.env(source.benchmark, source.config.clone())?;
    let mut env = crm::CrmEnv::new(source.machine.clone(), grasp, crm::RewardMode::Crm);
    let (mut stage, mut state) = env.reset(seed)?;
    let shift = source.shifts.get(env.env().task_index()).copied();
    let mut oracle = Oracle::with_shift(shift.unwrap_or_default());
    let mut noise = crm_learn::Noise::new(seed ^ 0x5EED_DA27);
    let mut demos = Demos::default();
    loop {
        let name = env.machine().stage_name(stage).to_string();
        let mask = env.machine().action_mask(stage);
        let label: Vec<f32> = oracle
            .act(env.env(), &name)
            .iter()
            .map(|a| a.clamp(-1.0, 1.0))
            .collect();
        let action: Vec<f32> = if source.noise > 0.0 {
            label
                .iter()
                .zip(&mask)
                .map(|(a, m)| (a + m * source.noise * noise.normal()).clamp(-1.0, 1.0))
                .collect()
        } else {
            label.clone()
        };
        if keeps(source.stages, stage) {
            demos.states.push(state.clone());
            demos.stages.push(stage);
            demos.masks.push(mask);
            demos.actions.push(label);
        }
        let step = env.step(&action)?;
        if step.done || step.truncated {
            let success = step.done && env.machine().stage_name(step.stage) == "success";
            return Ok((success, demos));
        }
        (stage, state) = (step.stage, step.abstract_state);
    }
}

/// Whether a row of `stage` is kept under a stage filter (empty: every stage).
pub(crate) fn keeps(stages: &[usize], stage: usize) -> bool {
    stages.is_empty() || stages.contains(&stage)
}

/// The oracle's palm shift per task index (zero where none is given); an unknown task id is
/// an error.
pub fn shifts_by_task(
    benchmark: &Benchmark,
    shifts: &std::collections::BTreeMap<String, [f64; 3]>,
) -> Result<Vec<[f32; 3]>> {
    let mut by_task = vec![[0.0; 3]; benchmark.tasks.len()];
    for (id, shift) in shifts {
        let Some(task) = benchmark.task_index(id) else {
            return Err(invalid!("unknown task {id:?} (see `crm tasks`)"));
        };
        by_task[task] = shift.map(|v| v as f32);
    }
    Ok(by_task)
}

#[cfg(test)]
mod tests {
    use super::*;
    use grasp_sim::TaskChoice;

    #[test]
    fn the_oracles_successes_are_the_demonstrations_noise_moves_them_and_stages_filter_them() {
        let benchmark = Arc::new(Benchmark::builtin());
        let machine = crm::Machine::from_spec(grasp_sim::spec::grasping_spec()).expect("machine");
        let task = benchmark.task_index("mouse-press").expect("task");
        let choice = EnvChoice {
            tasks: TaskChoice::Fixed(task),
            topologies: None,
        };
        let config = SimConfig::default();
        let source = |noise| DemoSource {
            benchmark: &benchmark,
            config: &config,
            machine: &machine,
            choice: &choice,
            seed: 3,
            noise,
            shifts: &[],
            stages: &[],
            skip: &[],
        };
        // The oracle presses every time: all its rows are demonstrations.
        let clean = oracle_demos(&source(0.0), 2).expect("oracle");
        assert_eq!((clean.episodes, clean.successes), (2, 2));
        let d = &clean.demos;
        assert!(d.len() > 10, "{} rows", d.len());
        assert!(
            d.stages.len() == d.len() && d.actions.len() == d.len() && d.masks.len() == d.len()
        );
        for ((action, mask), stage) in d.actions.iter().zip(&d.masks).zip(&d.stages) {
            assert_eq!(mask, &machine.action_mask(*stage));
            assert!(action.iter().all(|a| (-1.0..=1.0).contains(a)));
        }
        // Seeded: the same source gives the same rows.
        assert_eq!(
            oracle_demos(&source(0.0), 2).expect("again").demos.states,
            d.states
        );
        // Noise on the executed actions leads to other states, from the same first one.
        let noisy = oracle_demos(&source(0.1), 2).expect("noisy");
        assert_eq!(
            noisy.successes, 2,
            "the oracle still presses under small noise"
        );
        assert_eq!(noisy.demos.states[0], d.states[0]);
        assert_ne!(noisy.demos.states, d.states);
        // The labels stay the oracle's clean actions: in approach it heads for the grasp
        // location at full speed on some axis.
        assert!(noisy.demos.actions[0].iter().any(|a| a.abs() == 1.0));
        // A stage filter keeps only those stages' rows.
        let grasp = machine.stage_id("grasp").expect("grasp stage");
        let only_grasp = [grasp];
        let graspy = oracle_demos(
            &DemoSource {
                stages: &only_grasp,
                ..source(0.0)
            },
            2,
        )
        .expect("grasp rows");
        assert_eq!(graspy.successes, 2);
        assert!(!graspy.demos.is_empty() && graspy.demos.len() < d.len());
        assert!(graspy.demos.stages.iter().all(|&s| s == grasp));
    }
}
