//! Workers as Slurm jobs on a real Slurm: a one-node cluster of Debian's `slurm-wlm` that
//! `scripts/slurm-cluster` starts by hand (scripts/test does, and sets `SLURM_CONF`). A TLS
//! coordinator with a token and `--launcher slurm` runs a sweep of 8 training runs on the
//! workers it submits with `sbatch`; one worker is `scancel`ed mid-run and its job, given back,
//! is finished by another worker with the metrics of a run never interrupted; the workers leave
//! by themselves and the Slurm queue ends empty.

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};
use support::*;

const TOKEN: &str = "slurm-test-token";

fn slurm_conf() -> PathBuf {
    match std::env::var("SLURM_CONF") {
        Ok(conf) if Path::new(&conf).is_file() => PathBuf::from(conf),
        _ => panic!(
            "SLURM_CONF names no slurm.conf: this test needs a running Slurm; scripts/test starts \
             one with scripts/slurm-cluster (root, and Debian's slurm-wlm and munge)"
        ),
    }
}

/// The coordinator's REST API over TLS, checked against the test's CA.
struct Api {
    base: String,
    agent: ureq::Agent,
}

impl Api {
    fn new(addr: &str, ca: &Path) -> Self {
        let pem = std::fs::read(ca).expect("ca.pem");
        let certs: Vec<_> = ureq::tls::parse_pem(&pem)
            .filter_map(|item| match item {
                Ok(ureq::tls::PemItem::Certificate(cert)) => Some(cert),
                _ => None,
            })
            .collect();
        let tls = ureq::tls::TlsConfig::builder()
            .root_certs(ureq::tls::RootCerts::new_with_certs(&certs))
            .build();
        let config = ureq::Agent::config_builder()
            .tls_config(tls)
            .http_status_as_error(false)
            .build();
        Self {
            base: format!("https://{addr}"),
            agent: ureq::Agent::new_with_config(config),
        }
    }

    fn get(&self, path: &str) -> Value {
        let mut answer = self
            .agent
            .get(format!("{}{path}", self.base))
            .header("authorization", format!("Bearer {TOKEN}"))
            .call()
            .expect("GET");
        serde_json::from_str(&answer.body_mut().read_to_string().expect("body")).expect("JSON")
    }

    fn post(&self, path: &str, body: &Value) -> Value {
        let mut answer = self
            .agent
            .post(format!("{}{path}", self.base))
            .header("authorization", format!("Bearer {TOKEN}"))
            .content_type("application/json")
            .send(body.to_string().as_bytes())
            .expect("POST");
        assert_eq!(answer.status().as_u16(), 201, "POST {path}");
        serde_json::from_str(&answer.body_mut().read_to_string().expect("body")).expect("JSON")
    }

    fn job(&self, id: i64) -> Value {
        self.get(&format!("/api/v1/jobs/{id}"))
    }

    /// A run's metrics without their wall-clock fields.
    fn metrics(&self, id: i64) -> Vec<Value> {
        self.get(&format!("/api/v1/runs/{id}/metrics"))["metrics"]
            .as_array()
            .expect("metrics")
            .iter()
            .map(|m| without_wall_clock(&m["data"]))
            .collect()
    }
}

fn slurm(conf: &Path, tool: &str, args: &[&str]) -> String {
    let out = Command::new(tool)
        .args(args)
        .env("SLURM_CONF", conf)
        .output()
        .unwrap_or_else(|e| panic!("{tool}: {e}"));
    assert!(
        out.status.success(),
        "{tool} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn a_sweep_runs_on_slurm_workers_that_survive_scancel_and_leave_by_themselves() {
    let conf = slurm_conf();
    let dir = TempDir::new("slurm");
    let certs = dir.0.join("certs");
    let made = Command::new(crm())
        .args(["certs", "dev"])
        .arg(&certs)
        .output()
        .expect("crm certs dev");
    assert!(made.status.success());
    let path = |name: &str| certs.join(name).to_str().expect("utf-8").to_string();
    let server = start_server_with(
        &dir.0.join("data"),
        &[
            "--token",
            TOKEN,
            "--tls-cert",
            &path("server.pem"),
            "--tls-key",
            &path("server.key"),
            "--launcher",
            "slurm",
            "--max-workers",
            "2",
            "--slurm-cpus",
            "1",
            "--worker-idle-exit-s",
            "4",
            "--launch-every-s",
            "1",
            "--worker-ca",
            &path("ca.pem"),
            "--worker-command",
            crm().to_str().expect("utf-8"),
        ],
        &[("SLURM_CONF", &conf)],
    );
    let api = Api::new(&server.http, &certs.join("ca.pem"));
    let base = json!({
        "task": "mouse-press", "steps": 6144, "envs": 1,
        "config": {"rollout_steps": 512, "minibatch_size": 128, "early_stop_window": 1000000},
    });
    let seeds: Vec<u64> = (0..8).collect();
    let sweep = api.post(
        "/api/v1/sweeps",
        &json!({"name": "slurm", "base": base, "axes": {"algorithm": ["crm-ppo"], "seed": seeds}}),
    );
    let ids: Vec<i64> = sweep["jobs"]
        .as_array()
        .expect("jobs")
        .iter()
        .filter_map(|j| j["id"].as_i64())
        .collect();
    assert_eq!(ids.len(), 8);
    eprintln!("sweep of {} runs submitted: jobs {ids:?}", ids.len());

    // A job two iterations in, on a worker Slurm runs: scancel that worker.
    let (victim, batch) = wait_for(300, "a running job on a Slurm worker", || {
        let jobs = api.get("/api/v1/jobs?kind=train&state=running");
        let job = jobs["jobs"]
            .as_array()?
            .iter()
            .find(|j| j["steps"].as_i64().unwrap_or(0) >= 1024)?
            .clone();
        let worker = job["worker_id"].as_str()?.to_string();
        let workers = api.get("/api/v1/workers");
        let name = workers["workers"]
            .as_array()?
            .iter()
            .find(|w| w["id"].as_str() == Some(&worker))?["name"]
            .as_str()?
            .to_string();
        let batch = name.strip_prefix("slurm-")?.to_string();
        Some((job["id"].as_i64()?, batch))
    });
    eprintln!(
        "squeue before scancel:\n{}",
        slurm(&conf, "squeue", &["--format=%i %j %t %M"])
    );
    slurm(&conf, "scancel", &[&batch]);
    eprintln!("scancel {batch}: its worker held job {victim}");
    wait_for(40, "the job given back", || {
        (api.job(victim)["state"] == "queued" || api.job(victim)["attempts"] == 2).then_some(())
    });

    for id in &ids {
        wait_for(600, "every run to succeed", || {
            let job = api.job(*id);
            assert!(
                !["failed", "cancelled"].contains(&job["state"].as_str().unwrap_or("")),
                "{job}"
            );
            (job["state"] == "succeeded").then_some(())
        });
    }
    let resumed = api.job(victim);
    assert_eq!(resumed["attempts"], 2, "{resumed}");
    let from = resumed["result"]["resumed_from_steps"]
        .as_i64()
        .expect("resumed");
    assert!(from > 0, "{resumed}");
    eprintln!(
        "all {} runs succeeded; job {victim} resumed from {from} steps",
        ids.len()
    );

    // The same seed, never interrupted, on a worker the launcher starts for it.
    let mut spec = base.clone();
    spec["kind"] = json!("train");
    spec["algorithm"] = json!("crm-ppo");
    spec["seed"] = resumed["spec"]["seed"].clone();
    let reference = api.post("/api/v1/jobs", &spec)["id"].as_i64().expect("id");
    wait_for(300, "the uninterrupted run", || {
        (api.job(reference)["state"] == "succeeded").then_some(())
    });
    let (a, b) = (api.metrics(victim), api.metrics(reference));
    assert_eq!(a.len(), 12);
    assert_eq!(
        a, b,
        "the resumed run's metrics are the uninterrupted run's"
    );
    eprintln!(
        "job {victim} (scancelled, resumed) and job {reference} (uninterrupted): the same 12 iterations"
    );

    // Idle workers leave; the queue ends empty.
    wait_for(90, "the Slurm queue to empty", || {
        slurm(&conf, "squeue", &["--noheader", "--format=%i"])
            .trim()
            .is_empty()
            .then_some(())
    });
    let workers = api.get("/api/v1/workers");
    let names = worker_names(&workers);
    assert!(
        names.len() >= 3 && names.iter().all(|n| n.starts_with("slurm-")),
        "{names:?}"
    );
    eprintln!("the Slurm queue is empty; workers that ran: {names:?}");

    // The array script a user submits by hand: its workers register, named by array job and
    // task, find no job and leave.
    let token_file = dir.0.join("token");
    std::fs::write(&token_file, TOKEN).expect("token file");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/slurm/crm-worker.sbatch");
    let out = Command::new("sbatch")
        .args([
            "--parsable",
            "--array=1-2",
            "--cpus-per-task=1",
            "--time=00:10:00",
        ])
        .arg(format!("--output={}/array-%A_%a.out", dir.0.display()))
        .arg(&script)
        .env("SLURM_CONF", &conf)
        .env("CRM_COORDINATOR", format!("https://{}", server.grpc))
        .env("CRM_TOKEN_FILE", &token_file)
        .env("CRM_CA", certs.join("ca.pem"))
        .env("CRM_BIN", crm())
        .env("CRM_IDLE_EXIT_S", "2")
        .output()
        .expect("sbatch");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let array = String::from_utf8_lossy(&out.stdout).trim().to_string();
    wait_for(90, "the array's workers to register and leave", || {
        let workers = api.get("/api/v1/workers");
        let named = workers["workers"]
            .as_array()?
            .iter()
            .filter(|w| {
                w["name"]
                    .as_str()
                    .is_some_and(|n| n.starts_with(&format!("slurm-{array}_")))
            })
            .count();
        let empty = slurm(&conf, "squeue", &["--noheader", "--format=%i"])
            .trim()
            .is_empty();
        (named == 2 && empty).then_some(())
    });
    eprintln!("deploy/slurm/crm-worker.sbatch: array {array}'s two workers registered and left");
}
