//! `crm checkpoint export --onnx`: the deterministic policy as ONNX, run with ONNX Runtime (the
//! `onnxruntime` package from PyPI, in the venv scripts/test makes; `scripts/onnx-parity.py`)
//! on observations from real episodes: every action within 1e-5 of `crm`'s own, for a PPO
//! policy with folded dimensions (the shipped model), CRM-SAC and flat PPO, with the contract
//! in the model's metadata.

mod support;

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use support::*;

fn python() -> String {
    std::env::var("CRM_ONNX_PYTHON").unwrap_or_else(|_| {
        panic!(
            "CRM_ONNX_PYTHON is not set: scripts/test installs onnxruntime into a venv under \
             ~/.cache and sets it; run the suite with scripts/test"
        )
    })
}

fn succeeded(command: &mut Command, what: &str) -> std::process::Output {
    let out = command.output().expect(what);
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Exports `checkpoint` with 1,200 sample steps and runs the parity script on it.
fn parity(dir: &Path, checkpoint: &Path, name: &str) -> Value {
    let model = dir.join(format!("{name}.onnx"));
    let samples = dir.join(format!("{name}.json"));
    succeeded(
        Command::new(crm())
            .args(["checkpoint", "export"])
            .arg(checkpoint)
            .arg("--onnx")
            .arg(&model)
            .args(["--samples", "1200", "--seed", "3", "--samples-out"])
            .arg(&samples),
        "crm checkpoint export",
    );
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/onnx-parity.py");
    let out = succeeded(
        Command::new(python()).arg(script).arg(&model).arg(&samples),
        "onnx-parity.py",
    );
    let report: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(report["samples"], 1200, "{name}");
    let diff = report["max_abs_diff"].as_f64().expect("diff");
    assert!(
        diff < 1e-5,
        "{name}: ONNX Runtime differs from crm by {diff}"
    );
    assert_eq!(report["clipped_ok"], true, "{name}");
    let header = crm_learn::Checkpoint::read_header(checkpoint).expect("header");
    let meta = &report["metadata"];
    assert_eq!(meta["crm.algorithm"], header.algorithm, "{name}");
    assert_eq!(
        meta["crm.world_hash"],
        header.world_hash.clone().unwrap_or_default()
    );
    let lineage: Value =
        serde_json::from_str(meta["crm.lineage"].as_str().expect("lineage")).expect("json");
    assert_eq!(lineage.as_array().map(Vec::len), Some(header.lineage.len()));
    let stages: Vec<String> =
        serde_json::from_str(meta["crm.stages"].as_str().expect("stages")).expect("json");
    assert_eq!(stages.len(), header.layout.stages);
    assert_eq!(
        meta["crm.observation_width"],
        header.layout.state_width.to_string()
    );
    report
}

#[test]
fn exported_policies_act_as_crm_does_in_onnx_runtime() {
    let dir = TempDir::new("onnx");
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/crm-ppo.safetensors");
    let report = parity(&dir.0, &shipped, "shipped");
    let folded: Vec<bool> =
        serde_json::from_str(report["metadata"]["crm.folded"].as_str().expect("folded"))
            .expect("json");
    assert!(
        folded.contains(&true),
        "the shipped world folds the fingers"
    );
    for algorithm in ["crm-sac", "ppo"] {
        let out = dir.0.join(algorithm);
        succeeded(
            Command::new(crm())
                .args([
                    "train", "--algo", algorithm, "--steps", "1024", "--envs", "1",
                ])
                .args(["--task", "mouse-press", "--out"])
                .arg(&out),
            "crm train",
        );
        parity(
            &dir.0,
            &out.join(format!("{algorithm}.safetensors")),
            algorithm,
        );
    }
    // A file that is no checkpoint is refused, naming it.
    let bad = dir.0.join("bad.safetensors");
    std::fs::write(&bad, b"not a checkpoint").expect("write");
    let refused = Command::new(crm())
        .args(["checkpoint", "export"])
        .arg(&bad)
        .arg("--onnx")
        .arg(dir.0.join("bad.onnx"))
        .output()
        .expect("crm checkpoint export");
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("bad.safetensors"), "{stderr}");
    assert!(!dir.0.join("bad.onnx").exists());
}
