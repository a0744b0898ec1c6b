//! The paper's protocol in rapier: once the grasp is ready the arm executes the objective
//! inside one environment step and the judge grades that execution; a firm grasp passes,
//! a loose one does not.

use std::sync::Arc;

use rapier3d::prelude::Vec3;

use grasp_sim::benchmark::Fragility;
use grasp_sim::env::script::{objective_action, wanted_grip};
use grasp_sim::events::FailCause;
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

/// An episode of `task` under the learned protocol (no step hands over to the arm), reset
/// with seed 0.
fn learned(benchmark: &Arc<Benchmark>, task: usize) -> (crm::CrmEnv<GraspEnv>, crm::StageId) {
    let config = SimConfig {
        protocol: Protocol::Learned,
        ..SimConfig::deterministic()
    };
    let mut env = GraspEnv::new(benchmark.clone(), config);
    env.set_task_choice(TaskChoice::Fixed(task)).expect("task");
    let mut crm_env = crm::CrmEnv::new(grasping_machine(), env, crm::RewardMode::Crm);
    let (stage, _) = crm_env.reset(0).expect("reset");
    (crm_env, stage)
}

/// The arm's twist, driven step by step (the learned protocol, so that no step hands over),
/// on a valve made fragile so that its push reaches the grip limit: the palm pushes along
/// the tangent, backs off when the grip nears the limit, and the valve is not crushed.
#[test]
fn a_scripted_twist_backs_off_before_the_grip_crushes_the_object() {
    let mut benchmark = Benchmark::builtin();
    let task = task_index(&benchmark, "valve-twist");
    let valve = benchmark.tasks[task].object.clone();
    let object = benchmark
        .objects
        .iter_mut()
        .find(|o| o.name == valve)
        .expect("the valve");
    object.fragility = Fragility::Fragile;
    let limit = Fragility::Fragile.grasp_force_limit();
    let benchmark = Arc::new(benchmark);
    let (mut crm_env, mut stage) = learned(&benchmark, task);
    let mut oracle = Oracle::new();
    let motion = Vec3::from(benchmark.tasks[task].motion);
    let (mut pushed, mut backed) = (0, 0);
    for _ in 0..400 {
        let name = crm_env.machine().stage_name(stage).to_string();
        let env = crm_env.env();
        let action = oracle.act(env, &name);
        if name == "grasp" && action == objective_action(env, wanted_grip(env)) {
            let start = env.scene().expect("scene").object_start.rotation;
            let along = Vec3::new(action[0], action[1], action[2]).dot(start * motion);
            let grip = env.hand_contacts().grip;
            if grip > 0.8 * limit {
                assert!(along < 0.0, "no back-off at a grip of {grip} N: {along}");
                backed += 1;
            } else {
                assert!(along > 0.0, "no push at a grip of {grip} N: {along}");
                pushed += 1;
            }
        }
        let step = crm_env.step(&action).expect("step");
        stage = step.stage;
        if step.done || step.truncated {
            break;
        }
    }
    let env = crm_env.env();
    assert_ne!(
        env.last_fail(),
        Some(FailCause::Crushed),
        "pushed {pushed}, backed off {backed}"
    );
    assert!(
        pushed > 0 && backed > 0,
        "pushed {pushed}, backed off {backed}"
    );
}

/// The arm's twist turns the wrist about the object's axis: from the oracle's closed grasp of
/// the built-in jar, the execution moves the mount on a circle about that axis and turns it
/// about the axis, in the direction of the task's torque, and the lid turns.
#[test]
fn a_scripted_twist_turns_the_wrist_about_the_objects_axis() {
    let benchmark = Arc::new(Benchmark::builtin());
    let task = task_index(&benchmark, "jar-twist");
    let (mut crm_env, mut stage) = learned(&benchmark, task);
    let mut oracle = Oracle::new();
    // Close as the oracle does, up to its objective phase.
    for _ in 0..200 {
        let name = crm_env.machine().stage_name(stage).to_string();
        let env = crm_env.env();
        let action = oracle.act(env, &name);
        if name == "grasp" && action == objective_action(env, wanted_grip(env)) {
            break;
        }
        stage = crm_env.step(&action).expect("step").stage;
    }
    let (_, mut env) = crm_env.into_parts();
    let scene = env.scene().expect("scene");
    let (pivot, axis) = (
        scene.object_start.translation,
        scene.object_start.rotation * Vec3::Z,
    );
    let radius = |p: Vec3| {
        let arm = p - pivot;
        (arm - arm.dot(axis) * axis).length()
    };
    let before = scene.hand.mount_pose(&scene.world);
    let events = env.execute_objective().expect("execute");
    assert!(events.contains(&"succ"), "{events:?}");
    let scene = env.scene().expect("scene");
    let after = scene.hand.mount_pose(&scene.world);
    let (turn_axis, angle) = (after.rotation * before.rotation.inverse()).to_axis_angle();
    let required = benchmark.tasks[task].required.expect("a twist's torque");
    assert!(angle > 0.01, "the wrist turned {angle} rad");
    assert!(
        turn_axis.dot(axis) * required.signum() > 0.99,
        "turned about {turn_axis:?}, the axis is {axis:?}"
    );
    let (r0, r1) = (radius(before.translation), radius(after.translation));
    assert!(
        (r0 - r1).abs() < 1e-3,
        "the mount left its circle: {r0} -> {r1}"
    );
    assert!(
        (after.translation - before.translation).dot(axis).abs() < 1e-3,
        "the mount moved along the axis"
    );
}
