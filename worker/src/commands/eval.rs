//! `crm eval`: a checkpoint's success rate and episode length per objective over random
//! tasks with a fixed seed, as the paper's Table I. With `--coordinator URL` the checkpoint
//! is uploaded to a coordinator and evaluated there by its workers; the output is the same.

use std::path::PathBuf;

use anyhow::{Context, bail};
use serde_json::Value;

use super::remote::Rest;
use super::{EnvArgs, FingerMode, emit};
use crm_api::{EvalReport, EvalSpec};
use crm_run::eval::evaluate;

#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// Episodes, each on a task drawn with the seed.
    #[arg(long, default_value_t = 1000)]
    pub episodes: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Evaluate on this task (id; repeat for several) instead of random tasks.
    #[arg(long)]
    pub task: Vec<String>,
    /// Grasp topology: `task` (each task's assigned one), `auto` (the selection network's
    /// pick) or a topology name forced on every task.
    #[arg(long)]
    pub topology: Option<String>,
    /// Act with the policy's deterministic action instead of sampling it (its mean, folded
    /// where the environment folds: docs/LEARNING.md; the default samples, seeded by
    /// `--seed`, as the paper's evaluation does).
    #[arg(long)]
    pub deterministic: bool,
    #[arg(long)]
    pub json: bool,
    /// Evaluate on a coordinator instead (its REST address, e.g. http://127.0.0.1:8080):
    /// the checkpoint is uploaded (or found, if the same bytes were uploaded before) and an
    /// evaluation job runs on its workers with the same settings.
    #[arg(long, value_name = "URL")]
    pub coordinator: Option<String>,
    /// The coordinator's bearer token, for `--coordinator`.
    #[arg(long, env = "CRM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// The CA certificate (PEM) of an `https://` coordinator with a private CA (`crm certs
    /// dev` writes `ca.pem`); without it the system's roots are used.
    #[arg(long, value_name = "FILE")]
    pub ca: Option<PathBuf>,
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    // The world by name, for a coordinator's workers (`--coordinator`).
    let world = match &args.env.world {
        Some(_) => Some(args.env.env().world()?.name.clone()),
        None => None,
    };
    let spec = EvalSpec {
        world,
        episodes: args.episodes,
        seed: args.seed,
        task: None,
        tasks: args.task.clone(),
        topology: args.topology.clone(),
        record: None,
        video: None,
        objective: args.env.protocol,
        deterministic: args.deterministic,
        hold_s: args.env.hold_s,
    };
    let (report, mut value) = match &args.coordinator {
        Some(url) => remote(url, &args, &spec)?,
        None => {
            let report = evaluate(&args.checkpoint, &spec, args.env.env(), None, |_, _, _| {
                true
            })?;
            let value = serde_json::to_value(&report)?;
            (report, value)
        }
    };
    if args.json {
        value["checkpoint"] = serde_json::Value::from(args.checkpoint.display().to_string());
        return emit(&format!("{value}\n"));
    }
    emit(&report.markdown())
}

/// Uploads the checkpoint, runs the evaluation job on the coordinator and returns its report
/// (with the job's extra fields, such as `checkpoint_id`).
fn remote(url: &str, args: &EvalArgs, spec: &EvalSpec) -> anyhow::Result<(EvalReport, Value)> {
    // Workers run the built-in benchmark and machine with randomization on.
    let local_only = [
        (args.env.benchmark.is_some(), "--benchmark"),
        (args.env.spec.is_some(), "--spec"),
        (args.env.no_randomization, "--no-randomization"),
        (
            args.env.finger_actions != FingerMode::Closing,
            "--finger-actions",
        ),
    ];
    if let Some((_, flag)) = local_only.iter().find(|(set, _)| *set) {
        bail!("{flag}: not available with --coordinator (workers run the built-in settings)");
    }
    let rest = Rest::new(url, args.token.clone(), args.ca.as_deref())?;
    let checkpoint_id = rest.upload_checkpoint(&args.checkpoint)?;
    let mut job = serde_json::to_value(spec)?;
    job["kind"] = Value::from("eval");
    job["checkpoint_id"] = Value::from(checkpoint_id);
    let id = rest.submit(&job)?;
    let bar = indicatif::ProgressBar::new(1000).with_message(format!("evaluation job {id}"));
    let done = rest.wait(id, |p| bar.set_position((p * 1000.0) as u64))?;
    bar.finish_and_clear();
    let value = done["result"].clone();
    let report: EvalReport =
        serde_json::from_value(value.clone()).context("the evaluation job's result")?;
    Ok((report, value))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    #[test]
    fn the_coordinator_checks_the_environment_version_the_workers_run() {
        assert_eq!(crm_api::checkpoint::ENV_VERSION, grasp_sim::ENV_VERSION);
        // The shipped model passes the coordinator's upload check.
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/crm-ppo.safetensors");
        let bytes = std::fs::read(model).expect("the shipped model");
        let info = crm_api::checkpoint::inspect(&bytes, bytes.len() as u64).expect("a checkpoint");
        assert_eq!(info.algorithm, crm_api::Algorithm::CrmPpo);
        assert_eq!(info.env_version, grasp_sim::ENV_VERSION);
    }
}
