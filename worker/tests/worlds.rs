//! A world folder through the `crm` binary, as a user runs it: check, oracle on two tasks, two
//! training iterations, evaluation and a recording; a checkpoint from another hand refused;
//! a broken world refused with exit code 2 naming the file and the field; a world drafted by
//! `crm world init` for a four-finger hand.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

/// Runs `crm` with `CRM_ASSETS` pointing at the test world's assets.
fn crm(root: &Path, args: &[&str]) -> (i32, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_crm"))
        .args(args)
        .env("CRM_ASSETS", root.join("assets"))
        .output()
        .expect("crm runs");
    (
        output.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

/// A fresh test world (`scripts/make-test-world`) in a folder of its own per test.
fn test_world(tag: &str) -> PathBuf {
    let root = std::env::temp_dir().join(format!("crm-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    common::scripted("make-test-world", &root);
    root
}

/// Two training iterations of 128 steps in `world`, written to `out`.
fn train_two_iterations(root: &Path, world: &Path, out: &Path) {
    let config = root.join("ppo.json");
    std::fs::write(
        &config,
        r#"{"rollout_steps": 128, "minibatch_size": 64, "hidden": [32]}"#,
    )
    .expect("config");
    let (code, _, stderr) = crm(
        root,
        &[
            "train",
            "--world",
            world.to_str().expect("utf-8"),
            "--steps",
            "256",
            "--envs",
            "2",
            "--seed",
            "3",
            "--config",
            config.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    let metrics = std::fs::read_to_string(out.join("metrics.jsonl")).expect("metrics");
    assert_eq!(metrics.lines().count(), 2, "two iterations of 128 steps");
}

#[test]
fn a_world_folder_round_trip_and_a_checkpoint_from_another_hand_refused() {
    let root = test_world("world");
    let world = root.join("world");
    let world_arg = world.to_str().expect("utf-8 path");

    let (code, stdout, stderr) = crm(&root, &["world", "check", world_arg]);
    assert_eq!(code, 0, "{stderr}");
    let check: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
    assert_eq!(check["world"], "test-hand");
    assert_eq!(check["hand"]["source"], "urdf");
    assert_eq!(check["hand"]["joints"], 14);
    assert_eq!(check["hand"]["fingers"], 5);
    assert_eq!(
        (check["objects"].as_u64(), check["tasks"].as_u64()),
        (Some(2), Some(3))
    );

    let (code, stdout, stderr) = crm(
        &root,
        &[
            "oracle",
            "--world",
            world_arg,
            "--json",
            "--seeds",
            "1",
            "--task",
            "mug-wrap",
            "--task",
            "blocks-lift",
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    let oracle: serde_json::Value = serde_json::from_str(&stdout).expect("oracle JSON");
    assert_eq!(oracle["episodes"], 2);

    let out = root.join("run");
    train_two_iterations(&root, &world, &out);
    let checkpoint = out.join("crm-ppo.safetensors");
    let checkpoint = checkpoint.to_str().expect("utf-8");

    let (code, stdout, stderr) = crm(
        &root,
        &[
            "eval",
            "--world",
            world_arg,
            "--checkpoint",
            checkpoint,
            "--episodes",
            "2",
            "--json",
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("eval JSON");
    assert_eq!(report["episodes"], 2);

    let recording = root.join("episode.rrd");
    let (code, stdout, stderr) = crm(
        &root,
        &[
            "record",
            "--world",
            world_arg,
            "--checkpoint",
            checkpoint,
            "--task",
            "mug-wrap",
            "--out",
            recording.to_str().expect("utf-8"),
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("mug-wrap"), "{stdout}");
    let recording = recording.to_str().expect("utf-8");
    let (code, stdout, stderr) = crm(&root, &["record", "--inspect", recording]);
    assert_eq!(code, 0, "{stderr}");
    let summary: serde_json::Value = serde_json::from_str(&stdout).expect("inspect JSON");
    // The mesh object (VHACD's hulls) and the URDF hand's mesh links are drawn as meshes.
    for entity in ["/world/object/part_0", "/world/hand/palm"] {
        let archetypes = &summary["entities"][entity]["archetypes"];
        assert!(
            archetypes.to_string().contains("Mesh3D"),
            "{entity}: {archetypes}"
        );
    }

    // The same checkpoint in the built-in world, and the shipped model in this one: refused.
    let (code, _, stderr) = crm(
        &root,
        &["eval", "--checkpoint", checkpoint, "--episodes", "1"],
    );
    assert_eq!(code, 2);
    assert!(
        stderr.contains("test-hand") && stderr.contains("world"),
        "{stderr}"
    );
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/crm-ppo.safetensors");
    let (code, _, stderr) = crm(
        &root,
        &[
            "eval",
            "--world",
            world_arg,
            "--checkpoint",
            shipped.to_str().expect("utf-8"),
            "--episodes",
            "1",
        ],
    );
    assert_eq!(code, 2);
    assert!(
        stderr.contains("\"crm\"") && stderr.contains("differ"),
        "{stderr}"
    );

    // A profile naming a joint the description lacks.
    let profile = world.join("hand.json");
    let text = std::fs::read_to_string(&profile).expect("profile");
    std::fs::write(&profile, text.replacen("\"thumb_ip\"", "\"thumb_tip\"", 1)).expect("write");
    for args in [
        vec!["world", "check", world_arg],
        vec!["oracle", "--world", world_arg, "--seeds", "1"],
        vec!["bench", "env", "--world", world_arg],
    ] {
        let (code, _, stderr) = crm(&root, &args);
        assert_eq!(code, 2, "{args:?}");
        assert!(
            stderr.contains("hand.json") && stderr.contains("fingers.thumb.joints[1].joint"),
            "{args:?}: {stderr}"
        );
    }
    std::fs::remove_dir_all(root).ok();
}

/// `crm world init` drafts a world for the test world's four-finger hand that `crm world
/// check` loads, and two training iterations run there with the little finger's action
/// masked.
#[test]
fn a_drafted_four_finger_world_checks_and_trains() {
    let root = test_world("init");
    let out = root.join("drafted");
    let out_arg = out.to_str().expect("utf-8");
    let hand = root.join("assets/my_hand/urdf/hand4.urdf");
    let (code, stdout, stderr) = crm(
        &root,
        &[
            "world",
            "init",
            "--hand",
            hand.to_str().expect("utf-8"),
            "--out",
            out_arg,
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    let mut lines = stdout.lines();
    let first: serde_json::Value =
        serde_json::from_str(lines.next().expect("a first line")).expect("the world's line");
    assert_eq!(first["world"], "hand4");
    assert_eq!(first["hand"]["fingers"], 4);
    let rest: Vec<&str> = lines.collect();
    assert!(rest[0].starts_with("confirm in "), "{stdout}");
    assert!(
        rest.iter().any(|l| l.contains("little left out")),
        "{stdout}"
    );
    let (code, stdout, stderr) = crm(&root, &["world", "check", out_arg]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("\"fingers\":4"), "{stdout}");
    let (code, _, stderr) = crm(
        &root,
        &["world", "init", "--hand", "nowhere.urdf", "--out", out_arg],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("not empty"), "{stderr}");

    train_two_iterations(&root, &root.join("world4"), &root.join("run4"));
    std::fs::remove_dir_all(root).ok();
}

/// `crm world check` refuses a profile that couples a joint otherwise than the hand's
/// description, naming the joint and both couplings, until the profile overrides it by name.
#[test]
fn world_check_refuses_a_coupling_against_the_description_unless_overridden() {
    let root = test_world("check-couplings");
    let world = root.join("world");
    let dir = world.to_str().expect("utf-8");
    let (code, stdout, stderr) = crm(&root, &["world", "check", dir]);
    assert_eq!(code, 0, "{stderr}");
    let before: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    let profile_path = world.join("hand.json");
    let text = std::fs::read_to_string(&profile_path).expect("hand.json");
    let mut profile: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    // The paper's thumb coupling where the description says thumb_ip = 0.5 thumb_tmcp.
    for joint in profile["fingers"]["thumb"]["joints"]
        .as_array_mut()
        .expect("joints")
    {
        if joint["joint"] == "thumb_ip" {
            joint["ratio"] = serde_json::json!(0.9);
        }
    }
    std::fs::write(&profile_path, profile.to_string()).expect("write");
    let (code, _, stderr) = crm(&root, &["world", "check", dir]);
    assert_ne!(code, 0);
    assert!(
        stderr.contains("joint \"thumb_ip\"")
            && stderr.contains("thumb_ip = 0.5 x thumb_tmcp + 0")
            && stderr.contains("thumb_ip = 0.9 x thumb_tmcp + 0")
            && stderr.contains("description_overrides"),
        "{stderr}"
    );
    profile["description_overrides"] = serde_json::json!(["thumb_ip"]);
    std::fs::write(&profile_path, profile.to_string()).expect("write");
    let (code, stdout, stderr) = crm(&root, &["world", "check", dir]);
    assert_eq!(code, 0, "{stderr}");
    let after: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    let overrides = after["description_overrides"].as_array().expect("listed");
    assert_eq!(overrides.len(), 1);
    assert!(overrides[0].as_str().expect("text").contains("thumb_ip"));
    // Another coupling is another world; the override itself is not in the hash.
    assert_ne!(after["hash"], before["hash"]);
    profile
        .as_object_mut()
        .expect("object")
        .remove("description_overrides");
    std::fs::write(&profile_path, profile.to_string()).expect("write");
    let loaded = grasp_sim::World::load_with(
        &world,
        &grasp_sim::assets::Assets::parse(&root.join("assets").display().to_string()),
    )
    .expect("loads");
    assert_eq!(serde_json::json!(loaded.hash), after["hash"]);
    std::fs::remove_dir_all(root).ok();
}

/// `crm world fit-grasps` on a test world with a task broken on purpose (its grasp location
/// 4 cm above where the hand holds the blocks): it finds an offset the oracle succeeds with on
/// seeds the search did not use, writes a world of its own hash whose corrections are data,
/// leaves the source as it was, and refuses to fit a fitted world.
#[test]
fn fit_grasps_corrects_a_task_broken_on_purpose() {
    let root = test_world("fit-grasps");
    let world = root.join("world");
    let benchmark_path = world.join("benchmark.json");
    let mut benchmark: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&benchmark_path).expect("read"))
            .expect("JSON");
    for task in benchmark["tasks"].as_array_mut().expect("tasks") {
        if task["id"] == "blocks-lift" {
            task["grasp"]["offset"] = serde_json::json!([0.0, 0.0, 0.09]);
        }
    }
    std::fs::write(&benchmark_path, benchmark.to_string()).expect("write");
    let source = std::fs::read_to_string(&benchmark_path).expect("read");
    let oracle = |dir: &Path| -> serde_json::Value {
        let (code, stdout, stderr) = crm(
            &root,
            &[
                "oracle",
                "--world",
                dir.to_str().expect("utf-8"),
                "--seed",
                "200",
                "--seeds",
                "4",
                "--json",
            ],
        );
        assert_eq!(code, 0, "{stderr}");
        serde_json::from_str(&stdout).expect("JSON")
    };
    assert_eq!(
        oracle(&world)["per_task"]["blocks-lift"]["success_rate"],
        0.0
    );

    let out = root.join("fitted");
    let args = [
        "world",
        "fit-grasps",
        world.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "--seeds",
        "3",
        "--check-seeds",
        "3",
    ];
    let (code, stdout, stderr) = crm(&root, &args);
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("| blocks-lift |"), "{stderr}");
    let line: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    let offset = line["corrections"]["blocks-lift"]
        .as_array()
        .expect("corrected")
        .clone();
    assert_eq!(
        line["corrections"].as_object().map(|o| o.len()),
        Some(1),
        "{line}"
    );
    assert!(offset[2].as_f64().expect("dz") < -0.01, "{offset:?}");
    let corrections: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("corrections.json")).expect("written"),
    )
    .expect("JSON");
    let task = &corrections["tasks"]["blocks-lift"];
    assert_eq!(task["before"], 0.0);
    assert!(
        task["after"].as_f64() > Some(0.6) && task["after_check"].as_f64() > Some(0.6),
        "{task}"
    );
    assert!(
        corrections["command"]
            .as_str()
            .expect("command")
            .contains("fit-grasps")
    );
    // The fitted world: its own hash, its corrections printed by `world check`, and the
    // oracle holds the blocks on seeds neither the search nor the check used.
    let (code, stdout, stderr) = crm(&root, &["world", "check", out.to_str().expect("utf-8")]);
    assert_eq!(code, 0, "{stderr}");
    let checked: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    assert_eq!(checked["corrections"], line["corrections"]);
    let (_, before, _) = crm(&root, &["world", "check", world.to_str().expect("utf-8")]);
    let before: serde_json::Value = serde_json::from_str(&before).expect("JSON");
    assert_ne!(checked["hash"], before["hash"]);
    assert!(oracle(&out)["per_task"]["blocks-lift"]["success_rate"].as_f64() > Some(0.5));
    assert_eq!(
        std::fs::read_to_string(&benchmark_path).expect("read"),
        source
    );
    // A policy trained in the corrected world runs in the world as written: corrections move
    // grasp locations, not what an observation or an action means. Its lineage names the
    // corrected world's hash.
    let trained = root.join("trained");
    train_two_iterations(&root, &out, &trained);
    let checkpoint = trained.join("crm-ppo.safetensors");
    let (code, _, stderr) = crm(
        &root,
        &[
            "eval",
            "--world",
            world.to_str().expect("utf-8"),
            "--checkpoint",
            checkpoint.to_str().expect("utf-8"),
            "--episodes",
            "2",
            "--json",
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    let (code, shown, stderr) = crm(
        &root,
        &["checkpoint", "show", checkpoint.to_str().expect("utf-8")],
    );
    assert_eq!(code, 0, "{stderr}");
    // The header: the policy hash, the world as written's; the lineage: the corrected world's.
    assert!(
        shown.contains(before["hash"].as_str().expect("hash")),
        "{shown}"
    );
    assert!(
        shown.contains(&checked["hash"].as_str().expect("hash")[..12]),
        "{shown}"
    );
    // ... and the fit that made it: its command and the offsets.
    assert!(
        shown.contains("the world's grasp corrections, found by: crm world fit-grasps"),
        "{shown}"
    );
    assert!(shown.contains("offsets: {\""), "{shown}");
    // A fitted world is not fitted again; a non-empty --out is refused.
    let (code, _, stderr) = crm(
        &root,
        &[
            "world",
            "fit-grasps",
            out.to_str().expect("utf-8"),
            "--out",
            root.join("again").to_str().expect("utf-8"),
        ],
    );
    assert_ne!(code, 0);
    assert!(stderr.contains("already corrects"), "{stderr}");
    let (code, _, stderr) = crm(&root, &args);
    assert_ne!(code, 0);
    assert!(stderr.contains("not empty"), "{stderr}");
    std::fs::remove_dir_all(root).ok();
}
