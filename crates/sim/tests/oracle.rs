//! The physics can grasp: the scripted oracle meets each kind of success test in rapier, and
//! a hand that does nothing never succeeds.

use std::sync::Arc;

use grasp_sim::oracle::run_episode;
use grasp_sim::spec::grasping_machine;
use grasp_sim::{Benchmark, GraspEnv, SimConfig, TaskChoice};

fn task_index(benchmark: &Benchmark, id: &str) -> usize {
    benchmark.task_index(id).expect(id)
}

/// The outcome and the simulated seconds of one oracle episode.
fn oracle_outcome(id: &str, seed: u64) -> (String, f32) {
    let benchmark = Arc::new(Benchmark::builtin());
    let task = task_index(&benchmark, id);
    let env = GraspEnv::new(benchmark, SimConfig::default());
    let (episode, env) = run_episode(env, grasping_machine(), task, seed).expect("episode runs");
    (episode.outcome, env.sim_seconds())
}

#[test]
fn the_oracle_lifts_and_holds_a_mug_for_five_seconds() {
    let (outcome, seconds) = oracle_outcome("mug-wrap", 0);
    assert_eq!(outcome, "success");
    // The arm's lift and the 5 s hold are simulated time of the episode.
    assert!(seconds >= 5.0, "{seconds}");
}

#[test]
fn the_oracle_twists_a_valve_past_its_required_torque() {
    assert_eq!(oracle_outcome("valve-twist", 0).0, "success");
}

#[test]
fn the_oracle_presses_a_mouse_hard_enough() {
    assert_eq!(oracle_outcome("mouse-press", 0).0, "success");
}

#[test]
fn a_hand_that_does_nothing_never_succeeds() {
    let benchmark = Arc::new(Benchmark::builtin());
    let task = task_index(&benchmark, "box-lift");
    let mut env = GraspEnv::new(benchmark, SimConfig::default());
    env.set_task_choice(TaskChoice::Fixed(task)).expect("task");
    let mut crm_env = crm::CrmEnv::new(grasping_machine(), env, crm::RewardMode::Crm);
    crm_env.reset(3).expect("reset");
    loop {
        let step = crm_env.step(&[0.0; 8]).expect("step");
        assert!(!step.done, "an idle hand reached {:?}", step.event);
        if step.truncated {
            break;
        }
    }
    assert_eq!(crm_env.episode().history().len(), 0);
}
