//! The environment's contract: bad actions, determinism, randomization ranges, coupling.

use std::sync::Arc;

use grasp_sim::hand::{ALPHA_DIP, ALPHA_MCP, ALPHA_TMCP, coupled_angles};
use grasp_sim::observation::{ACTIONS, FEATURES};
use grasp_sim::{Benchmark, GraspEnv, SimConfig};
use rapier3d::prelude::*;

fn env(config: SimConfig) -> GraspEnv {
    GraspEnv::new(Arc::new(Benchmark::builtin()), config)
}

#[test]
fn a_non_finite_action_is_refused_naming_the_dimension() {
    let mut env = env(SimConfig::deterministic());
    env.reset_task(0, 1).expect("reset");
    let mut action = vec![0.0; ACTIONS.len()];
    action[4] = f32::NAN;
    let err = env.step_action(&action).expect_err("nan").to_string();
    assert!(err.contains("dimension 4 (index)"), "{err}");
    action[4] = f32::INFINITY;
    assert!(env.step_action(&action).is_err());
    let err = env.step_action(&[0.0; 3]).expect_err("short").to_string();
    assert!(err.contains("3 values, expected 8"), "{err}");
    // Nothing was stepped by the refused actions.
    assert_eq!(env.steps(), 0);
}

#[test]
fn out_of_range_actions_are_clipped_and_counted() {
    let mut env = env(SimConfig::deterministic());
    let start = env.reset_task(0, 1).expect("reset");
    let before = env
        .scene()
        .map(|s| s.hand.mount_pose(&s.world).translation)
        .expect("scene");
    env.step_action(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        .expect("step");
    let after = env
        .scene()
        .map(|s| s.hand.mount_pose(&s.world).translation)
        .expect("scene");
    assert_eq!(env.clipped_actions(), 1);
    assert!(((after.x - before.x) - grasp_sim::observation::MAX_PALM_STEP).abs() < 1e-5);
    assert_eq!(start.len(), FEATURES.len());
}

#[test]
fn the_same_seed_gives_a_bitwise_identical_trajectory() {
    let run = || {
        let mut env = env(SimConfig::default());
        let mut bits = Vec::new();
        let first = env.reset_seeded(42).expect("reset");
        bits.extend(first.iter().map(|v| v.to_bits()));
        for k in 0..40 {
            let t = k as f32 * 0.1;
            let action = [
                0.006 * t.sin(),
                0.004 * t.cos(),
                -0.005,
                0.05,
                0.05,
                0.05,
                0.05,
                0.05,
            ];
            let step = env.step_action(&action).expect("step");
            bits.extend(step.observation.iter().map(|v| v.to_bits()));
        }
        (env.task_index(), bits)
    };
    assert_eq!(run(), run());
}

#[test]
fn randomization_stays_in_the_papers_ranges_and_is_off_when_disabled() {
    let benchmark = Arc::new(Benchmark::builtin());
    let config = SimConfig::default();
    let mut yaw_seen = 0.0f32;
    let mut offset_seen = 0.0f32;
    for seed in 0..40 {
        let mut env = GraspEnv::new(benchmark.clone(), config.clone());
        env.reset_task(2, seed).expect("reset");
        let scene = env.scene().expect("scene");
        let start = scene.object_start;
        assert!(
            start.translation.x.abs() <= 0.003 + 1e-6 && start.translation.y.abs() <= 0.003 + 1e-6
        );
        let (axis, angle) = start.rotation.to_axis_angle();
        let yaw = angle * axis.z.signum();
        assert!(yaw.abs() <= 11.5f32.to_radians() + 1e-5, "yaw {yaw}");
        yaw_seen = yaw_seen.max(yaw.abs());
        for offsets in &scene.hand.joint_offsets {
            for offset in offsets {
                assert!(offset.abs() <= 0.02 + 1e-6);
                offset_seen = offset_seen.max(offset.abs());
            }
        }
    }
    // The ranges are used, not just bounded.
    assert!(
        yaw_seen > 0.15 && offset_seen > 0.015,
        "yaw {yaw_seen}, joint {offset_seen}"
    );

    let mut env = GraspEnv::new(benchmark, SimConfig::deterministic());
    env.reset_task(2, 7).expect("reset");
    let scene = env.scene().expect("scene");
    assert_eq!(scene.object_start.translation.x, 0.0);
    assert_eq!(scene.object_start.rotation, Rotation::IDENTITY);
    assert!(scene.hand.joint_offsets.iter().flatten().all(|o| *o == 0.0));
}

#[test]
fn one_pip_command_sets_the_coupled_joints() {
    assert_eq!(ALPHA_DIP, [0.77, 0.75, 0.75, 0.57]);
    let index = coupled_angles(1, 1.0);
    assert_eq!(index, vec![ALPHA_MCP, 1.0, 0.77]);
    let little = coupled_angles(4, 1.0);
    assert_eq!(little, vec![0.67, 1.0, 0.57]);
    let thumb = coupled_angles(0, 0.8);
    assert_eq!(thumb, vec![0.8, ALPHA_TMCP * 0.8]);
}

#[test]
fn commanded_fingers_reach_their_coupled_angles_in_free_space() {
    let mut env = env(SimConfig::deterministic());
    env.reset_task(0, 3).expect("reset"); // mug-wrap, power grasp: every finger active
    // Raise the hand clear of everything, then close the index to a PIP of 0.6 rad.
    for _ in 0..10 {
        env.step_action(&[0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0, 0.0])
            .expect("step");
    }
    for _ in 0..6 {
        env.step_action(&[0.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0])
            .expect("step");
    }
    for _ in 0..30 {
        env.step_action(&[0.0; 8]).expect("step");
    }
    let scene = env.scene().expect("scene");
    let links = &scene.hand.links[1];
    let rotation =
        |handle: RigidBodyHandle| *scene.world.bodies.get(handle).expect("link").rotation();
    let palm = *scene
        .world
        .bodies
        .get(scene.hand.palm)
        .expect("palm")
        .rotation();
    let mut previous = palm;
    let mut angles = Vec::new();
    for &link in links {
        let current = rotation(link);
        let (axis, angle) = (previous.inverse() * current).to_axis_angle();
        angles.push(angle * axis.y.signum());
        previous = current;
    }
    let expected = coupled_angles(1, 0.6);
    for (got, want) in angles.iter().zip(&expected) {
        assert!(
            (got - want).abs() < 0.03,
            "joint angles {angles:?}, expected {expected:?}"
        );
    }
}

#[test]
fn task_weights_draw_within_the_task_choice_and_bad_weights_are_refused() {
    use grasp_sim::TaskChoice;
    let mut env = env(SimConfig::default());
    let tasks = env.benchmark().tasks.len();
    let draws = |env: &mut GraspEnv| -> Vec<usize> {
        (0..200)
            .map(|seed| {
                env.reset_seeded(seed).expect("reset");
                env.task_index()
            })
            .collect()
    };
    // Weight on tasks 3 and 7 only, 3 four times 7's.
    let mut weights = vec![0.0; tasks];
    weights[3] = 4.0;
    weights[7] = 1.0;
    env.set_task_weights(Some(weights.clone()))
        .expect("weights");
    let seen = draws(&mut env);
    let threes = seen.iter().filter(|&&t| t == 3).count();
    assert!(seen.iter().all(|&t| t == 3 || t == 7), "{seen:?}");
    assert!(
        (140..=180).contains(&threes),
        "task 3 drawn {threes} of 200"
    );
    // The same seeds give the same draws.
    assert_eq!(draws(&mut env), seen);
    // Within a subset, weights outside it do not count.
    env.set_task_choice(TaskChoice::Subset(vec![7, 9]))
        .expect("subset");
    assert!(draws(&mut env).iter().all(|&t| t == 7));
    // Back to uniform.
    env.set_task_weights(None).expect("uniform");
    let uniform: std::collections::BTreeSet<usize> = draws(&mut env).into_iter().collect();
    assert_eq!(uniform, [7, 9].into());
    // Wrong length, negative or not finite: refused, the old weights stay.
    for bad in [
        vec![1.0; tasks - 1],
        {
            let mut w = vec![1.0; tasks];
            w[0] = -1.0;
            w
        },
        vec![f32::NAN; tasks],
    ] {
        assert!(env.set_task_weights(Some(bad)).is_err());
    }
}

#[test]
fn task_subsets_and_forced_topologies_apply_from_the_next_reset() {
    use grasp_sim::TaskChoice;
    use grasp_sim::benchmark::Topology;
    let mut env = env(SimConfig::default());
    let tasks = env.benchmark().tasks.len();
    env.set_task_choice(TaskChoice::Subset(vec![2, 5]))
        .expect("subset");
    let mut seen = std::collections::BTreeSet::new();
    for seed in 0..20 {
        env.reset_seeded(seed).expect("reset");
        seen.insert(env.task_index());
    }
    assert_eq!(seen, [2, 5].into());
    assert!(env.set_task_choice(TaskChoice::Subset(vec![])).is_err());
    assert!(
        env.set_task_choice(TaskChoice::Subset(vec![1, tasks]))
            .is_err()
    );

    let one_hot = |env: &GraspEnv| -> Vec<f32> {
        let observation = env.observation_parts().to_vec();
        FEATURES
            .iter()
            .zip(observation)
            .filter(|(name, _)| name.starts_with("topology_"))
            .map(|(_, v)| v)
            .collect()
    };
    env.reset_task(0, 1).expect("reset");
    let assigned = env.benchmark().tasks[0].topology;
    assert_eq!(env.topology(), assigned);
    assert_eq!(one_hot(&env)[assigned.index()], 1.0);
    let forced = Topology::ALL
        .into_iter()
        .find(|t| *t != assigned)
        .expect("another topology");
    env.set_topologies(Some(vec![forced; tasks]))
        .expect("force");
    env.reset_task(0, 1).expect("reset");
    assert_eq!(env.topology(), forced);
    let hot = one_hot(&env);
    assert_eq!(hot[forced.index()], 1.0);
    assert_eq!(hot.iter().sum::<f32>(), 1.0);
    assert!(env.set_topologies(Some(vec![forced; 3])).is_err());
    env.set_topologies(None).expect("back");
    env.reset_task(0, 1).expect("reset");
    assert_eq!(env.topology(), assigned);
}

#[test]
fn the_authors_approach_keeps_the_grasp_point_between_its_start_and_1_cm_past_the_target() {
    let point = |env: &GraspEnv| {
        env.scene()
            .map(|s| s.hand.grasp_point(&s.world))
            .expect("scene")
    };
    let push = |approach: grasp_sim::Approach, toward: bool, steps: usize| {
        let mut env = env(SimConfig {
            approach,
            ..SimConfig::deterministic()
        });
        env.reset_task(0, 1).expect("reset");
        let start = point(&env);
        let target = env.grasp_location().expect("target");
        let sign = (target - start).signum() * if toward { 1.0 } else { -1.0 };
        for _ in 0..steps {
            let action = [
                0.01 * sign.x,
                0.01 * sign.y,
                0.01 * sign.z,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ];
            env.step_action(&action).expect("step");
        }
        // Where the grasp point went, along each axis's way from the start to the target (the
        // target as the object stands now: the hand may nudge it).
        let way = (target - start).signum();
        let now = env.grasp_location().expect("target");
        ((point(&env) - start) * way, (point(&env) - now) * way)
    };
    // Pushed back from the target, the clamp holds it at its start (the wrist's lag aside).
    let (from_start, _) = push(grasp_sim::Approach::Authors, false, 20);
    assert!(from_start.min_element() > -0.003, "{from_start:?}");
    let (from_start, _) = push(grasp_sim::Approach::Free, false, 20);
    assert!(from_start.max_element() < -0.1, "free: {from_start:?}");
    // Pushed on to the target and beyond, it stops 1 cm past the target on every axis.
    let (_, past) = push(grasp_sim::Approach::Authors, true, 120);
    assert!(
        past.max_element() < 0.013 && past.min_element() > -0.006,
        "{past:?}"
    );
    let (_, past) = push(grasp_sim::Approach::Free, true, 120);
    assert!(past.max_element() > 0.1, "free: {past:?}");
}
