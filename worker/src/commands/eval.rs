//! `crm eval`: a checkpoint's success rate and episode length per objective over random
//! tasks with a fixed seed, as the paper's Table I.

use std::path::PathBuf;

use super::{EnvArgs, emit};
use crate::jobs::eval::evaluate;
use crm_api::EvalSpec;

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
    /// Act with the policy's mean action instead of sampling it (the default samples, seeded
    /// by `--seed`, as the paper's evaluation does).
    #[arg(long)]
    pub deterministic: bool,
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let spec = EvalSpec {
        episodes: args.episodes,
        seed: args.seed,
        task: None,
        tasks: args.task.clone(),
        topology: args.topology.clone(),
        record: None,
        objective: args.env.protocol,
        deterministic: args.deterministic,
    };
    let report = evaluate(&args.checkpoint, &spec, &args.env, None, |_, _, _| true)?;
    if args.json {
        let mut value = serde_json::to_value(&report)?;
        value["checkpoint"] = serde_json::Value::from(args.checkpoint.display().to_string());
        return emit(&format!("{value}\n"));
    }
    emit(&report.markdown())
}
