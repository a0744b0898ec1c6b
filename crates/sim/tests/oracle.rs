//! The physics can grasp: the scripted oracle meets each kind of success test in rapier, and
//! a hand that does nothing never succeeds.

use std::sync::Arc;

use grasp_sim::oracle::{Oracle, run_episode};
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

#[test]
fn an_oracle_with_a_palm_shift_moves_the_palm_that_far_from_the_grasp_location_before_closing() {
    let benchmark = Arc::new(Benchmark::builtin());
    let task = task_index(&benchmark, "box-lift");
    // Where the palm stands, against the grasp location, when the oracle first closes a
    // finger (the shift takes 4 control steps at 3 mm a step).
    let relative_after_aligning = |shift: [f32; 3]| {
        let mut env = GraspEnv::new(benchmark.clone(), SimConfig::deterministic());
        env.set_task_choice(TaskChoice::Fixed(task)).expect("task");
        let mut crm_env = crm::CrmEnv::new(grasping_machine(), env, crm::RewardMode::Crm);
        let (mut stage, _) = crm_env.reset(0).expect("reset");
        let mut oracle = Oracle::with_shift(shift);
        loop {
            let name = crm_env.machine().stage_name(stage).to_string();
            let action = oracle.act(crm_env.env(), &name);
            if name == "grasp" && action[3..].iter().any(|&a| a > 0.0) {
                return crm_env.env().observation_parts().relative;
            }
            let step = crm_env.step(&action).expect("step");
            assert!(!step.done && !step.truncated, "{name}: the episode ended");
            stage = step.stage;
        }
    };
    let plain = relative_after_aligning([0.0; 3]);
    let shifted = relative_after_aligning([0.012, 0.0, 0.0]);
    // `relative` is the grasp location minus the palm: 1.2 cm further along +x, within the
    // oracle's 3 mm tolerance.
    assert!(plain.iter().all(|r| r.abs() < 0.004), "{plain:?}");
    assert!((shifted[0] + 0.012).abs() < 0.004, "{shifted:?}");
    assert!(
        shifted[1].abs() < 0.004 && shifted[2].abs() < 0.004,
        "{shifted:?}"
    );
}
