//! The paper's protocol in rapier: once the grasp is ready the arm executes the objective
//! inside one environment step and the judge grades that execution; a firm grasp passes,
//! a loose one does not.

use std::sync::Arc;

use grasp_sim::oracle::{Oracle, run_episode};
use grasp_sim::spec::grasping_machine;
use grasp_sim::{Benchmark, GraspEnv, Protocol, SimConfig, TaskChoice};

fn task_index(benchmark: &Benchmark, id: &str) -> usize {
    benchmark.task_index(id).expect(id)
}

#[test]
fn the_arm_executes_each_kind_of_objective_inside_one_step() {
    let benchmark = Arc::new(Benchmark::builtin());
    let config = SimConfig::deterministic();
    for id in ["box-lift", "mug-wrap", "valve-twist", "mouse-press"] {
        let task = task_index(&benchmark, id);
        let env = GraspEnv::new(benchmark.clone(), config.clone());
        let (episode, env) = run_episode(env, grasping_machine(), task, 0).expect("episode");
        assert_eq!(episode.outcome, "success", "{id}: {episode:?}");
        assert!(env.executed(), "{id}: the arm did not execute");
        // The policy's part is the approach and the close; the hold's 5 s are the arm's.
        assert!(episode.steps < 100, "{id}: {} learned steps", episode.steps);
        if id != "valve-twist" && id != "mouse-press" {
            assert!(
                env.sim_seconds() >= config.hold_s,
                "{id}: {} s",
                env.sim_seconds()
            );
        }
    }
}

#[test]
fn the_learned_protocol_leaves_the_objective_to_the_policy() {
    let benchmark = Arc::new(Benchmark::builtin());
    let config = SimConfig {
        protocol: Protocol::Learned,
        ..SimConfig::deterministic()
    };
    let task = task_index(&benchmark, "mug-wrap");
    let env = GraspEnv::new(benchmark, config);
    let (episode, env) = run_episode(env, grasping_machine(), task, 0).expect("episode");
    assert_eq!(episode.outcome, "success");
    assert!(!env.executed());
    assert!(episode.steps >= 150, "{}", episode.steps);
}

/// Runs the oracle on `id` until the grasp stage shows a touch with a grip under `below`
/// newtons; returns the environment there, or `None` if no such step came.
fn touching(id: &str, below: f32) -> Option<GraspEnv> {
    let benchmark = Arc::new(Benchmark::builtin());
    let task = task_index(&benchmark, id);
    let mut env = GraspEnv::new(benchmark, SimConfig::deterministic());
    env.set_task_choice(TaskChoice::Fixed(task)).expect("task");
    let mut crm_env = crm::CrmEnv::new(grasping_machine(), env, crm::RewardMode::Crm);
    let (mut stage, _) = crm_env.reset(1).expect("reset");
    let mut oracle = Oracle::new();
    for _ in 0..300 {
        let name = crm_env.machine().stage_name(stage).to_string();
        let action = oracle.act(crm_env.env(), &name);
        let step = crm_env.step(&action).expect("step");
        if step.done || step.truncated {
            return None;
        }
        stage = step.stage;
        let env = crm_env.env();
        let grip = env.hand_contacts().grip;
        if crm_env.machine().stage_name(stage) == "grasp"
            && env.hand_contacts().count() > 0
            && grip < below
        {
            return Some(crm_env.into_parts().1);
        }
    }
    None
}

#[test]
fn a_scripted_lift_of_a_firmly_held_box_succeeds_and_of_a_loosely_held_one_fails() {
    let benchmark = Arc::new(Benchmark::builtin());
    let task = task_index(&benchmark, "box-lift");
    let env = GraspEnv::new(benchmark, SimConfig::deterministic());
    let (firm, env) = run_episode(env, grasping_machine(), task, 1).expect("episode");
    assert_eq!(firm.outcome, "success", "{firm:?}");
    assert!(env.executed());

    let need = env.ready_test().need;
    let mut loose = touching("box-lift", 0.25 * need).expect("a light touch before the grip");
    assert!(!loose.grasp_ready(true));
    let events = loose.execute_objective().expect("execution");
    assert!(
        events.contains(&"fail") && !events.contains(&"succ"),
        "{events:?} ({:?})",
        loose.last_fail()
    );
}
