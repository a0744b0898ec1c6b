//! A topology's own grasp point: the world built from the test world with one for the
//! platform topology brings that point, not the profile's, to a press task's grasp location,
//! and leaves every other topology's episodes as they were.

use grasp_sim::benchmark::Topology;
use grasp_sim::{GraspEnv, SimConfig, World};

mod common;
use common::{load, test_world};

/// The palm's position and the grasp point's distance to the grasp location at reset.
fn start(world: &World, task: &str) -> ([f32; 3], f32) {
    let index = world
        .benchmark
        .tasks
        .iter()
        .position(|t| t.id == task)
        .expect("the task");
    let mut env = GraspEnv::new(world.benchmark.clone(), SimConfig::deterministic());
    env.reset_task(index, 0).expect("reset");
    let scene = env.scene().expect("a scene");
    let palm = scene.hand.palm_pose(&scene.world).translation;
    let relative = env.observation_parts().relative;
    let gap = relative.iter().map(|v| v * v).sum::<f32>().sqrt();
    (palm.to_array(), gap)
}

#[test]
fn a_topologys_grasp_point_is_the_one_its_tasks_bring_to_the_grasp_location() {
    let root = test_world("topology");
    let before = load(&root);
    let hand = root.join("world/hand.json");
    let text = std::fs::read_to_string(&hand).expect("profile");
    let mut profile: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let own = [0.01f32, 0.02, -0.03];
    profile["topologies"]["platform"]["grasp_point"] = serde_json::json!(own);
    std::fs::write(&hand, profile.to_string()).expect("write");
    let after = load(&root);
    assert_ne!(before.hash, after.hash);

    let model = &after.benchmark.hand;
    assert_eq!(model.grasp_point_of(Topology::Platform).to_array(), own);
    assert_eq!(model.grasp_point_of(Topology::PPdAb25), model.grasp_point);

    // The press starts as far from its grasp location as before, from another palm position.
    let (palm_before, gap_before) = start(&before, "blocks-press");
    let (palm_after, gap_after) = start(&after, "blocks-press");
    assert!(
        (gap_before - gap_after).abs() < 1e-4,
        "{gap_before} {gap_after}"
    );
    let moved: f32 = (0..3)
        .map(|i| (palm_before[i] - palm_after[i]).powi(2))
        .sum::<f32>()
        .sqrt();
    let offset = (own[0] - model.grasp_point.x).hypot(own[1] - model.grasp_point.y);
    let offset = offset.hypot(own[2] - model.grasp_point.z);
    assert!((moved - offset).abs() < 1e-4, "{moved} {offset}");
    // Another topology's task starts where it did.
    assert_eq!(start(&before, "blocks-lift"), start(&after, "blocks-lift"));
    std::fs::remove_dir_all(root).ok();
}
