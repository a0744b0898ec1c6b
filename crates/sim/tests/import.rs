//! `import::dexmobile` on a stand-in of the authors' repository made by
//! `scripts/make-dexmobile-standin` (CI has no copy of theirs): the world it writes loads,
//! points at the copy without copying it, has the same hash wherever the copy and the world
//! lie, places the hand at the task's orientation with the thumb opposed as the authors' code
//! drives it, stands up an object that cannot stand alone, and bad copies are refused naming
//! the file (and the CSV's line and column) with nothing written.

use std::path::{Path, PathBuf};

use grasp_sim::assets::Assets;
use grasp_sim::hand::Hand;
use grasp_sim::import::dexmobile::{Options, import};
use grasp_sim::{GraspEnv, SimConfig, World};

mod common;

/// A fresh stand-in under the temporary folder.
fn standin(tag: &str) -> PathBuf {
    common::scripted("make-dexmobile-standin", &format!("crm-standin-{tag}"))
}

/// The index of the hand's joint `name` in its model.
fn joint(hand: &Hand, name: &str) -> usize {
    hand.model
        .joints
        .iter()
        .position(|joint| joint.name == name)
        .unwrap_or_else(|| panic!("no joint {name}"))
}

fn out(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("crm-imported-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn the_import_loads_points_at_the_copy_and_does_not_depend_on_where_it_lies() {
    let copy = standin("a");
    let world_dir = out("a");
    let imported = import(&copy, &world_dir, &Options::default()).expect("imports");
    assert_eq!((imported.objects, imported.tasks), (2, 3));
    // Nothing of the copy is in the world: three JSON files and the sources note.
    let mut files: Vec<String> = std::fs::read_dir(&world_dir)
        .expect("world folder")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(
        files,
        ["benchmark.json", "hand.json", "sources.json", "world.json"]
    );
    let world = World::load_with(&world_dir, &Assets::default()).expect("loads");
    assert_eq!(world.name, "dexmobile");
    assert_eq!(world.hash, imported.hash);
    assert_eq!(world.summary()["hand"]["source"], "urdf");

    // Another copy elsewhere, imported elsewhere: the same hash, so checkpoints carry over.
    let other = standin("b");
    let elsewhere = out("b").join("deeper/world");
    let again = import(&other, &elsewhere, &Options::default()).expect("imports");
    assert_eq!(again.hash, imported.hash);
    // The real robot's sensors make another world.
    let options = Options {
        name: "dexmobile-real".into(),
        without: vec!["o_force".into(), "o_torque".into(), "o_cone".into()],
        ..Options::default()
    };
    let real = import(&copy, &out("real"), &options).expect("imports");
    assert_ne!(real.hash, imported.hash);
    // So does the authors' approach geometry, which the world then runs.
    let options = Options {
        name: "dexmobile-authors".into(),
        approach: Some(grasp_sim::Approach::Authors),
        ..Options::default()
    };
    let authors = import(&copy, &out("authors"), &options).expect("imports");
    assert_ne!(authors.hash, imported.hash);
    let world = grasp_sim::World::load(&authors.dir).expect("loads");
    assert_eq!(world.approach, grasp_sim::Approach::Authors);
}

#[test]
fn the_hand_starts_at_the_tasks_orientation_and_an_object_that_tips_gets_a_stand() {
    let copy = standin("pose");
    let world_dir = out("pose");
    import(&copy, &world_dir, &Options::default()).expect("imports");
    let world = World::load_with(&world_dir, &Assets::default()).expect("loads");
    let hook = world.benchmark.object("hook-1002").expect("the hook");
    assert_eq!(hook.parts.len(), 2, "the hook stands on a plate");
    let sources: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(world_dir.join("sources.json")).expect("sources"),
    )
    .expect("json");
    assert!(sources["objects"]["hook-1002"]["stand"].is_string());
    assert!(sources["objects"]["box-1001"]["stand"].is_null());

    for (t, task) in world.benchmark.tasks.iter().enumerate() {
        let mut env = GraspEnv::new(world.benchmark.clone(), SimConfig::default());
        env.reset_task(t, 5).expect("reset");
        let scene = env.scene().expect("scene");
        let q = task.grasp.orientation.expect("an orientation");
        let wanted = scene.object_start.rotation
            * rapier3d::math::Rotation::from_xyzw(q[0], q[1], q[2], q[3])
            * scene.hand.model.grasp_frame.inverse();
        let palm = scene.hand.palm_pose(&scene.world).rotation;
        assert!(
            palm.angle_between(wanted) < 1e-3,
            "{}: palm {palm:?}, task {wanted:?}",
            task.id
        );
        // The stand-in's tasks turn the palm to face the object, or to face down.
        let normal = palm * scene.hand.model.approach_axis;
        let expected = if task.id.contains("press") {
            rapier3d::math::Vec3::NEG_Z
        } else {
            scene.object_start.rotation * rapier3d::math::Vec3::Y
        };
        assert!(normal.dot(expected) > 0.99, "{}: {normal:?}", task.id);
    }
}

#[test]
fn the_thumb_opposes_as_the_authors_code_drives_it() {
    // `Dualcontrol.applyAction` drives joint 78, the opposition, to the grasp pose's element 6
    // (the index PIP), and PyBullet stops it at the joint's limit: 0.7369 rad for poPmAb25
    // (the stand-in's task 0) and the limit for inSiAd2 (task 2; its element 6 is 1.105; the
    // limit is 0.9879 in theirs, 0.99 in the stand-in). Element 0 (0.1 and 0) would leave the
    // thumb 36 and 57 degrees off.
    let copy = standin("thumb");
    let world_dir = out("thumb");
    import(&copy, &world_dir, &Options::default()).expect("imports");
    let world = World::load_with(&world_dir, &Assets::default()).expect("loads");
    for (t, wanted) in [(0, 0.7369), (2, 0.9879)] {
        let mut env = GraspEnv::new(world.benchmark.clone(), SimConfig::deterministic());
        env.reset_task(t, 1).expect("reset");
        let scene = env.scene().expect("scene");
        let j = joint(&scene.hand, "right_hand_Thumb_Opposition");
        let angle = scene.hand.joint_angle(&scene.world, j);
        assert!(
            (angle - wanted).abs() < 0.01,
            "task {t}: opposition at {angle} rad, the authors' code drives it to {wanted}"
        );
    }
}

#[test]
fn fingers_behind_a_chain_of_fixed_links_hold_their_pose_while_the_arm_moves() {
    // The stand-in's index finger hangs off three massless links joined by fixed joints,
    // as the SVH's does; welded into the palm, it keeps its relaxed angle as the arm moves.
    let copy = standin("weld");
    let world_dir = out("weld");
    import(&copy, &world_dir, &Options::default()).expect("imports");
    let world = World::load_with(&world_dir, &Assets::default()).expect("loads");
    let mut env = GraspEnv::new(world.benchmark.clone(), SimConfig::deterministic());
    env.reset_task(0, 1).expect("reset");
    {
        let scene = env.scene().expect("scene");
        for (j, joint) in scene.hand.model.joints.iter().enumerate() {
            eprintln!(
                "reset {} {}",
                joint.name,
                scene.hand.joint_angle(&scene.world, j)
            );
        }
    }
    for k in 0..40 {
        let dz = if k < 20 { 1.0 } else { -1.0 };
        env.step_action(&[0.7, -0.7, dz, 0.0, 0.0, 0.0, 0.0, 0.0])
            .expect("step");
        let scene = env.scene().expect("scene");
        let j = joint(&scene.hand, "right_hand_Index_Finger_Proximal");
        eprintln!(
            "step {k} n_c {} angle {}",
            env.observation_parts().n_c,
            scene.hand.joint_angle(&scene.world, j)
        );
    }
    let scene = env.scene().expect("scene");
    let hand = &scene.hand;
    let unique: std::collections::HashSet<_> = hand.bodies.iter().collect();
    assert!(unique.len() < hand.bodies.len(), "fixed links are welded");
    for (name, ratio) in [
        ("right_hand_Index_Finger_Proximal", 0.67),
        ("right_hand_Index_Finger_Distal", 1.0),
        ("right_hand_Middle_Finger_Proximal", 0.67),
    ] {
        let j = joint(hand, name);
        let angle = hand.joint_angle(&scene.world, j);
        assert!(
            (angle - ratio * 0.1).abs() < 0.05,
            "{name}: {angle} rad, relaxed at {}",
            ratio * 0.1
        );
    }
}

#[test]
fn a_relaxed_hand_takes_its_preshape_at_the_preshape_speed_once_the_grasp_begins() {
    // The stand-in approaches relaxed, as the SVH does; in the grasp stage each finger's
    // command moves toward the topology's preshape by at most the preshape speed's share
    // of a control step (the authors' 1 rad/s), and gets there; at speed 0 at once.
    use crm::Environment;
    let copy = standin("ramp");
    let world_dir = out("ramp");
    import(&copy, &world_dir, &Options::default()).expect("imports");
    let world = World::load_with(&world_dir, &Assets::default()).expect("loads");
    for speed in [1.0, 0.0] {
        let config = SimConfig {
            preshape_speed: speed,
            ..SimConfig::deterministic()
        };
        let most = speed * config.control_dt();
        let mut env = GraspEnv::new(world.benchmark.clone(), config);
        env.reset_task(0, 1).expect("reset");
        let shape = env.hand_shape();
        let relaxed = env.scene().expect("scene").hand.commands;
        assert!(
            (0..5).any(|f| (relaxed[f] - shape[f].preshape).abs() > 2.0 * most),
            "the stand-in's relaxed pose {relaxed:?} is its preshape"
        );
        env.set_stage("grasp");
        let mut before = relaxed;
        let mut steps = 0;
        loop {
            env.step_action(&[0.0; 8]).expect("step");
            steps += 1;
            let now = env.scene().expect("scene").hand.commands;
            for f in 0..5 {
                let moved = (now[f] - before[f]).abs();
                let toward =
                    (now[f] - shape[f].preshape).abs() <= (before[f] - shape[f].preshape).abs();
                assert!(toward, "finger {f}: {} -> {}", before[f], now[f]);
                if speed > 0.0 {
                    assert!(
                        moved <= most + 1e-6,
                        "finger {f} moved {moved} rad in a step"
                    );
                }
            }
            before = now;
            let there = |f: usize| {
                now[f] == shape[f].preshape || (shape[f].active && now[f] >= shape[f].preshape)
            };
            if (0..5).all(there) {
                break;
            }
            assert!(steps < 200, "not preshaped after {steps} steps: {now:?}");
        }
        if speed > 0.0 {
            assert!(steps > 1, "preshaped in one step at {speed} rad/s");
        } else {
            assert_eq!(steps, 1, "at speed 0 the preshape is taken at once");
        }
    }
    // Fingers the policy closes while the hand is on its way are never opened by it.
    let config = SimConfig::deterministic();
    let mut env = GraspEnv::new(world.benchmark.clone(), config);
    env.reset_task(0, 1).expect("reset");
    let shape = env.hand_shape();
    assert!(shape.iter().any(|f| f.active), "task 0 moves no finger");
    env.set_stage("grasp");
    let mut before = env.scene().expect("scene").hand.commands;
    for k in 0..20 {
        // Closing, then still: neither may open them.
        let close = if k < 8 { 1.0 } else { 0.0 };
        env.step_action(&[0.0, 0.0, 0.0, close, close, close, close, close])
            .expect("step");
        let now = env.scene().expect("scene").hand.commands;
        for f in (0..5).filter(|&f| shape[f].active) {
            assert!(
                now[f] >= before[f],
                "finger {f} opened: {} -> {}",
                before[f],
                now[f]
            );
        }
        before = now;
    }
    for f in (0..5).filter(|&f| shape[f].active) {
        assert!(
            before[f] > shape[f].preshape,
            "finger {f} did not close past its preshape"
        );
    }
}

fn refusal(copy: &Path, tag: &str) -> (String, PathBuf) {
    let dir = out(tag);
    let message = import(copy, &dir, &Options::default())
        .expect_err("refused")
        .to_string();
    (message, dir)
}

#[test]
fn bad_copies_are_refused_naming_the_file_line_and_column_and_nothing_is_written() {
    // Not the repository at all.
    let empty = std::env::temp_dir().join(format!("crm-not-a-repo-{}", std::process::id()));
    std::fs::create_dir_all(&empty).expect("mkdir");
    let (message, dir) = refusal(&empty, "empty");
    assert!(message.contains("crm_ppo/topo/pos_all.csv"), "{message}");
    assert!(message.contains("hhelium/DexMobile"), "{message}");
    assert!(!dir.exists());

    // The first missing file is named.
    let copy = standin("missing");
    std::fs::remove_file(copy.join("robots/dual_2hand.urdf")).expect("rm");
    let (message, _) = refusal(&copy, "missing");
    assert!(message.contains("robots/dual_2hand.urdf"), "{message}");

    // A missing mesh: the CSV's line and column, and the mesh.
    let copy = standin("mesh");
    std::fs::remove_file(copy.join("objects/1002_hook/target.obj")).expect("rm");
    let (message, dir) = refusal(&copy, "mesh");
    assert!(message.contains("pos_all.csv"), "{message}");
    assert!(
        message.contains("line 4, column \"Object ID\""),
        "{message}"
    );
    assert!(message.contains("target.obj"), "{message}");
    assert!(!dir.exists());

    // A bad number, an unknown topology, an unknown objective.
    for (tag, from, to, column) in [
        ("number", "0.085000", "0.08.5", "Trans"),
        ("topology", "poPmAb25", "power", "Topology"),
        ("objective", "Wrap-grasp", "Juggle", "Affordance"),
    ] {
        let copy = standin(tag);
        let csv = copy.join("crm_ppo/topo/pos_all.csv");
        let text = std::fs::read_to_string(&csv).expect("csv");
        std::fs::write(&csv, text.replacen(from, to, 1)).expect("write");
        let (message, dir) = refusal(&copy, tag);
        assert!(
            message.contains(&format!("line 2, column \"{column}\"")),
            "{tag}: {message}"
        );
        assert!(!dir.exists(), "{tag}: a partial world was written");
    }

    // An occupied --out is not overwritten.
    let copy = standin("occupied");
    let dir = out("occupied");
    std::fs::create_dir_all(&dir).expect("mkdir");
    std::fs::write(dir.join("keep.txt"), "mine").expect("write");
    let message = import(&copy, &dir, &Options::default())
        .expect_err("refused")
        .to_string();
    assert!(message.contains("not empty"), "{message}");
    assert_eq!(
        std::fs::read_to_string(dir.join("keep.txt")).expect("kept"),
        "mine"
    );
}
