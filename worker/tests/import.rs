//! `crm world import-dexmobile` through the binary, on a stand-in of the authors' repository
//! (`scripts/make-dexmobile-standin`): the import, the oracle and two training iterations in
//! the world it writes, the checkpoint evaluated in a second import of another copy (same
//! hash), exit code 2 naming the file, line and column of a bad CSV value, and a fit's
//! corrections applied to an import as data.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

fn crm(args: &[&str]) -> (i32, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_crm"))
        .args(args)
        .env_remove("CRM_ASSETS")
        .output()
        .expect("crm runs");
    (
        output.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

fn standin(root: &Path, name: &str) -> PathBuf {
    let dir = root.join(name);
    common::scripted("make-dexmobile-standin", &dir);
    dir
}

fn utf8(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

#[test]
fn an_imported_world_trains_and_its_checkpoint_evaluates_in_another_import() {
    let root = std::env::temp_dir().join(format!("crm-cli-import-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let first = standin(&root, "copy-a");
    let world = root.join("worlds/paper");
    let (code, stdout, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&first),
        "--out",
        utf8(&world),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let line: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
    assert_eq!(
        (line["objects"].as_u64(), line["tasks"].as_u64()),
        (Some(2), Some(3))
    );

    let (code, stdout, stderr) = crm(&["world", "check", utf8(&world)]);
    assert_eq!(code, 0, "{stderr}");
    let check: serde_json::Value = serde_json::from_str(stdout.trim()).expect("check JSON");
    assert_eq!(check["hash"], line["hash"]);

    let (code, stdout, stderr) = crm(&[
        "oracle",
        "--world",
        utf8(&world),
        "--json",
        "--seeds",
        "1",
        "--task",
        "t01-box-press",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let oracle: serde_json::Value = serde_json::from_str(&stdout).expect("oracle JSON");
    assert_eq!(oracle["episodes"], 1);

    let config = root.join("ppo.json");
    std::fs::write(
        &config,
        r#"{"rollout_steps": 128, "minibatch_size": 64, "hidden": [32]}"#,
    )
    .expect("config");
    let run = root.join("run");
    let (code, _, stderr) = crm(&[
        "train",
        "--world",
        utf8(&world),
        "--steps",
        "256",
        "--envs",
        "2",
        "--seed",
        "3",
        "--config",
        utf8(&config),
        "--out",
        utf8(&run),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let checkpoint = run.join("crm-ppo.safetensors");

    // Another copy of the same files, imported elsewhere, takes the checkpoint.
    let second = standin(&root, "elsewhere/copy-b");
    let other = root.join("elsewhere/worlds/paper");
    let (code, _, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&second),
        "--out",
        utf8(&other),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (code, stdout, stderr) = crm(&[
        "eval",
        "--world",
        utf8(&other),
        "--checkpoint",
        utf8(&checkpoint),
        "--episodes",
        "2",
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("eval JSON");
    assert_eq!(report["episodes"], 2);
    assert!(report["authors_judge"].is_number(), "{report}");

    // The real robot's sensors: another world, which a resume refuses and a fine-tune takes.
    let real = root.join("worlds/paper-real");
    let (code, _, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&first),
        "--out",
        utf8(&real),
        "--name",
        "paper-real",
        "--without",
        "o_force,o_torque,o_cone",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let tuned = root.join("tuned");
    let train_in_real = |how: &str, out: &Path| {
        crm(&[
            "train",
            "--world",
            utf8(&real),
            "--steps",
            "128",
            "--envs",
            "2",
            "--config",
            utf8(&config),
            how,
            utf8(&checkpoint),
            "--out",
            utf8(out),
        ])
    };
    let (code, _, stderr) = train_in_real("--resume", &root.join("resumed"));
    assert_eq!(code, 2, "a resume across worlds is refused");
    assert!(stderr.contains("paper-real"), "{stderr}");
    let (code, _, stderr) = train_in_real("--fine-tune", &tuned);
    assert_eq!(code, 0, "{stderr}");
    let (code, _, stderr) = crm(&[
        "eval",
        "--world",
        utf8(&real),
        "--checkpoint",
        utf8(&tuned.join("crm-ppo.safetensors")),
        "--episodes",
        "1",
    ]);
    assert_eq!(code, 0, "{stderr}");

    // A bad number in the table: exit 2, the file, line and column, nothing written.
    let csv = second.join("crm_ppo/topo/pos_all.csv");
    let text = std::fs::read_to_string(&csv).expect("csv");
    std::fs::write(&csv, text.replacen("0.160000", "0.16x", 1)).expect("write");
    let bad = root.join("worlds/bad");
    let (code, _, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&second),
        "--out",
        utf8(&bad),
    ]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("pos_all.csv") && stderr.contains("line 3, column \"Trans\""),
        "{stderr}"
    );
    assert!(!bad.exists());
    // Not the repository: the first missing file is named.
    let (code, _, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&world),
        "--out",
        utf8(&bad),
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("crm_ppo/topo/pos_all.csv"), "{stderr}");
    std::fs::remove_dir_all(root).ok();
}

/// `--corrections FILE` applies a fit's grasp-location corrections to an import: the task
/// files stay the authors', the world is one of its own hash that lists what it corrects, and
/// a correction of a task the world lacks is refused with nothing written.
#[test]
fn an_import_takes_corrections_as_data() {
    let root = std::env::temp_dir().join(format!("crm-cli-import-fit-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let repo = standin(&root, "copy");
    let plain = root.join("worlds/plain");
    let (code, stdout, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&repo),
        "--out",
        utf8(&plain),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let plain_line: serde_json::Value = serde_json::from_str(stdout.trim()).expect("JSON");
    let benchmark: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(plain.join("benchmark.json")).expect("benchmark"),
    )
    .expect("JSON");
    let task = benchmark["tasks"][0]["id"]
        .as_str()
        .expect("a task")
        .to_string();
    let corrections = |id: &str| {
        serde_json::json!({
            "command": "crm world fit-grasps (written by the test)",
            "bounds": [0.06, 0.06, 0.06], "threshold": 0.8,
            "search_seeds": [0, 10], "check_seeds": [100, 10],
            "tasks": {id: {"offset": [0.0, 0.01, -0.02], "before": 0.0, "after": 0.9,
                           "before_check": 0.0, "after_check": 0.8, "evaluated": 40}},
        })
    };
    let file = root.join("corrections.json");
    std::fs::write(&file, corrections(&task).to_string()).expect("write");
    let fitted = root.join("worlds/fitted");
    let (code, stdout, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&repo),
        "--out",
        utf8(&fitted),
        "--corrections",
        utf8(&file),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let line: serde_json::Value = serde_json::from_str(stdout.trim()).expect("JSON");
    assert_ne!(line["hash"], plain_line["hash"]);
    assert_eq!(
        std::fs::read_to_string(fitted.join("benchmark.json")).expect("benchmark"),
        std::fs::read_to_string(plain.join("benchmark.json")).expect("benchmark"),
        "the task files stay the authors'"
    );
    let (code, stdout, stderr) = crm(&["world", "check", utf8(&fitted)]);
    assert_eq!(code, 0, "{stderr}");
    let check: serde_json::Value = serde_json::from_str(stdout.trim()).expect("JSON");
    assert_eq!(check["hash"], line["hash"]);
    assert_eq!(
        check["corrections"][&task],
        serde_json::json!([0.0, 0.01, -0.02])
    );

    std::fs::write(&file, corrections("no-such-task").to_string()).expect("write");
    let refused = root.join("worlds/refused");
    let (code, _, stderr) = crm(&[
        "world",
        "import-dexmobile",
        utf8(&repo),
        "--out",
        utf8(&refused),
        "--corrections",
        utf8(&file),
    ]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("corrections") && stderr.contains("no-such-task"),
        "{stderr}"
    );
    assert!(!refused.exists());
    std::fs::remove_dir_all(root).ok();
}
