//! End-to-end tests of checkpoints made elsewhere, against the real `crm-server` and
//! `crm worker` on loopback with a temporary data folder: the shipped models are registered
//! on a new data folder; `POST /api/v1/checkpoints` stores a checkpoint once by content and
//! refuses, storing nothing, a body that is not one, one of another environment version, one
//! over the size limit or one without the token; `crm eval --coordinator` uploads a file and
//! prints what a local `crm eval` prints.

mod support;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use support::*;

/// Upload limit of the coordinator under test (the shipped model is about 630 KB).
const LIMIT: usize = 1_000_000;

fn models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

fn upload(addr: &str, path: &str, body: &[u8], token: Option<&str>) -> Reply {
    let auth = token.map(|t| format!("Bearer {t}"));
    let headers: Vec<(&str, &str)> = auth.iter().map(|a| ("Authorization", a.as_str())).collect();
    try_http_bytes(
        addr,
        "POST",
        path,
        body,
        "application/octet-stream",
        &headers,
    )
    .expect("HTTP request")
}

fn files(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .expect("checkpoint folder")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().to_string())
        .collect()
}

/// `bytes` with the first occurrence of `from` replaced by `to` (of the same length).
fn patched(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    assert_eq!(from.len(), to.len());
    let at = bytes
        .windows(from.len())
        .position(|w| w == from.as_bytes())
        .unwrap_or_else(|| panic!("{from:?} not in the file"));
    let mut out = bytes.to_vec();
    out[at..at + to.len()].copy_from_slice(to.as_bytes());
    out
}

fn eval_json(args: &[&str]) -> Value {
    let out = Command::new(crm())
        .arg("eval")
        .args(args)
        .output()
        .expect("run crm eval");
    assert!(
        out.status.success(),
        "crm eval {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

/// An upload the coordinator refuses: path, body, token, status, the field the error names.
type Refusal = (
    &'static str,
    Vec<u8>,
    Option<&'static str>,
    u16,
    &'static str,
);

#[test]
fn checkpoints_made_elsewhere_are_stored_once_checked_and_evaluated_remotely() {
    let data = TempDir::new("upload");
    let limit = LIMIT.to_string();
    let models = models();
    let server = start_server(
        &data.0,
        &[
            "--token",
            TOKEN,
            "--max-checkpoint-bytes",
            &limit,
            "--models",
            models.to_str().expect("utf-8 path"),
        ],
    );
    let addr = server.http.clone();
    let dir = data.0.join("checkpoints");

    // The shipped policy is registered on the new data folder (the topology network, which
    // is no policy checkpoint, is not).
    let listed = get(&addr, "/api/v1/checkpoints?uploaded=true");
    let listed = listed["checkpoints"].as_array().expect("list");
    assert_eq!(listed.len(), 1, "{listed:?}");
    let shipped = &listed[0];
    assert_eq!(shipped["name"], "crm-ppo");
    assert_eq!(shipped["algorithm"], "crm-ppo");
    assert_eq!(shipped["job_id"], Value::Null);
    let shipped_id = shipped["id"].as_i64().expect("id");
    let model = std::fs::read(models.join("crm-ppo.safetensors")).expect("model");
    assert_eq!(shipped["size"], model.len());
    let before = files(&dir);
    assert_eq!(before.len(), 1);

    // Refused bodies store nothing and say why.
    let refusals: [Refusal; 7] = [
        (
            "/api/v1/checkpoints",
            model.clone(),
            None,
            401,
            "authorization",
        ),
        (
            "/api/v1/checkpoints",
            b"hello".to_vec(),
            Some(TOKEN),
            400,
            "body",
        ),
        (
            "/api/v1/checkpoints",
            patched(&model, "obs38/v4", "obs38/v9"),
            Some(TOKEN),
            422,
            "body",
        ),
        (
            "/api/v1/checkpoints",
            vec![0; LIMIT + 1],
            Some(TOKEN),
            413,
            "body",
        ),
        (
            "/api/v1/checkpoints?name=",
            model.clone(),
            Some(TOKEN),
            400,
            "name",
        ),
        (
            // A right-to-left override would make the name read otherwise than it is.
            "/api/v1/checkpoints?name=policy%E2%80%AEtxt.exe",
            model.clone(),
            Some(TOKEN),
            400,
            "name",
        ),
        (
            "/api/v1/checkpoints?label=x",
            model.clone(),
            Some(TOKEN),
            400,
            "label",
        ),
    ];
    for (path, body, token, status, field) in refusals {
        let reply = upload(&addr, path, &body, token);
        assert_eq!(
            reply.status,
            status,
            "{path}: {}",
            String::from_utf8_lossy(&reply.body)
        );
        assert_eq!(reply.json()["error"]["field"], field, "{path}");
    }
    let mismatch = upload(
        &addr,
        "/api/v1/checkpoints",
        &patched(&model, "obs38/v4", "obs38/v9"),
        Some(TOKEN),
    );
    let message = mismatch.json()["error"]["message"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(message.contains("obs38/v9"), "{message}");
    assert_eq!(files(&dir), before);
    assert_eq!(
        get(&addr, "/api/v1/checkpoints")["checkpoints"]
            .as_array()
            .map(Vec::len),
        Some(1)
    );

    // The same bytes again: the existing checkpoint, 200. New bytes: a new one, 201, whose
    // download is the uploaded file.
    let again = upload(&addr, "/api/v1/checkpoints?name=again", &model, Some(TOKEN));
    assert_eq!(again.status, 200);
    assert_eq!(again.json()["id"], shipped_id);
    // New bytes: the shipped model with another step count in its header (read from the
    // listing, so the test follows whichever model is shipped). Flipping the lowest bit keeps
    // the number of digits, so the header keeps its length.
    let steps = shipped["steps"].as_u64().expect("steps");
    let other_steps = steps ^ 1;
    let other = patched(
        &model,
        &format!("\\\"steps\\\":{steps}"),
        &format!("\\\"steps\\\":{other_steps}"),
    );
    let created = upload(
        &addr,
        "/api/v1/checkpoints?name=my%20policy",
        &other,
        Some(TOKEN),
    );
    assert_eq!(
        created.status,
        201,
        "{}",
        String::from_utf8_lossy(&created.body)
    );
    let created = created.json();
    assert_eq!(created["name"], "my policy");
    assert_eq!(created["steps"], other_steps);
    let id = created["id"].as_i64().expect("id");
    assert_ne!(id, shipped_id);
    let download = http(
        &addr,
        "GET",
        &format!("/api/v1/checkpoints/{id}/download"),
        None,
        Some(TOKEN),
    );
    assert_eq!(download.status, 200);
    assert!(
        download.body == other,
        "the download is not the uploaded file"
    );
    assert_eq!(files(&dir).len(), 2);

    // `crm eval --coordinator` uploads (finding the shipped model's row), runs the evaluation
    // on a worker and prints what a local evaluation prints, number for number.
    let _worker = start_worker(&format!("http://{}", server.grpc), &["--token", TOKEN]);
    let checkpoint = models.join("crm-ppo.safetensors");
    let checkpoint = checkpoint.to_str().expect("utf-8 path");
    let common = [
        "--checkpoint",
        checkpoint,
        "--episodes",
        "4",
        "--seed",
        "3",
        "--json",
    ];
    let url = format!("http://{addr}");
    let mut remote_args = vec!["--coordinator", url.as_str(), "--token", TOKEN];
    remote_args.extend(common);
    let mut remote = eval_json(&remote_args);
    let local = eval_json(&common);
    assert_eq!(remote["checkpoint_id"], shipped_id);
    remote
        .as_object_mut()
        .expect("object")
        .remove("checkpoint_id");
    assert_eq!(remote, local);
    let evaluations = get(&addr, "/api/v1/evaluations");
    assert_eq!(evaluations["evaluations"][0]["checkpoint_id"], shipped_id);
    assert_eq!(files(&dir).len(), 2);

    // An unreachable coordinator: exit 2, naming the address.
    let out = Command::new(crm())
        .args([
            "eval",
            "--coordinator",
            "http://127.0.0.1:9",
            "--checkpoint",
            checkpoint,
        ])
        .output()
        .expect("run crm eval");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("http://127.0.0.1:9"), "{stderr}");
}

#[test]
fn models_are_registered_only_on_a_new_data_folder() {
    let data = TempDir::new("register");
    let models = models();
    let models = models.to_str().expect("utf-8 path");
    let server = start_server(&data.0, &["--models", models]);
    let count = |addr: &str| {
        get(addr, "/api/v1/checkpoints")["checkpoints"]
            .as_array()
            .map(Vec::len)
    };
    assert_eq!(count(&server.http), Some(1));
    drop(server);
    // An emptied folder of models on a restart: what was registered stays, nothing is added.
    let empty = TempDir::new("no-models");
    let server = start_server(&data.0, &["--models", empty.0.to_str().expect("utf-8")]);
    assert_eq!(count(&server.http), Some(1));
    drop(server);
    // A data folder that already has a store is not new: the models are not registered.
    let other = TempDir::new("register-later");
    let server = start_server(&other.0, &["--models", empty.0.to_str().expect("utf-8")]);
    assert_eq!(count(&server.http), Some(0));
    drop(server);
    let server = start_server(&other.0, &["--models", models]);
    assert_eq!(count(&server.http), Some(0));
}
