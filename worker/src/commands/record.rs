//! `crm record`: replay one evaluation episode of a checkpoint into a rerun recording file or
//! a live viewer; `crm record --inspect FILE` says what a recording holds.

use std::path::PathBuf;

use anyhow::{Context, bail};
use crm_api::{EvalSpec, RecordSpec};

use super::{EnvArgs, emit};
use crate::record::{Recorder, Target, inspect, lock, reachable};
use crm_run::eval::evaluate;

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// The checkpoint whose policy acts (deterministically).
    #[arg(long, required_unless_present = "inspect")]
    pub checkpoint: Option<PathBuf>,
    /// The task (id); a random one from the seed when absent.
    #[arg(long)]
    pub task: Option<String>,
    /// Seed of the episode (task draw, randomization), as `crm eval --seed`.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Grasp topology: `task`, `auto` or a topology name.
    #[arg(long)]
    pub topology: Option<String>,
    /// Write the recording here (`.rrd`; open with `rerun FILE`).
    #[arg(long, conflicts_with = "connect", required_unless_present_any = ["connect", "inspect"])]
    pub out: Option<PathBuf>,
    /// Stream to a running viewer instead (`rerun+http://127.0.0.1:9876/proxy`).
    #[arg(long)]
    pub connect: Option<String>,
    /// Print what a recording file holds (JSON) instead of recording.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["checkpoint", "out", "connect"])]
    pub inspect: Option<PathBuf>,
}

pub fn run(args: RecordArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.inspect {
        let summary = inspect::summarize(path)?;
        return emit(&format!("{}\n", serde_json::to_string_pretty(&summary)?));
    }
    let checkpoint = args
        .checkpoint
        .clone()
        .context("--checkpoint is required")?;
    if let Some(url) = &args.connect {
        reachable(url).map_err(|why| anyhow::anyhow!("--connect: {why}"))?;
    }
    if let Some(out) = &args.out
        && out.is_dir()
    {
        bail!("--out: {} is a folder; give a file name", out.display());
    }
    let record = RecordSpec {
        every: 1,
        max_episodes: 1,
        connect: args.connect.clone(),
    };
    let name = checkpoint
        .file_name()
        .map_or("checkpoint".into(), |n| n.to_string_lossy().to_string());
    let recorder = Recorder::new(&record, name).shared();
    if *lock(&recorder).target() == Target::Off {
        bail!("--connect: the viewer stopped answering");
    }
    let spec = EvalSpec {
        world: None,
        episodes: 1,
        seed: args.seed,
        task: args.task.clone(),
        tasks: Vec::new(),
        topology: args.topology.clone(),
        record: Some(record),
        objective: args.env.protocol,
        deterministic: false,
        hold_s: args.env.hold_s,
    };
    let mut episode = None;
    evaluate(
        &checkpoint,
        &spec,
        args.env.env(),
        Some(recorder.clone() as crm_run::SharedRecorder),
        |_, _, e| {
            episode = Some(e.clone());
            true
        },
    )?;
    let episode = episode.context("no episode ran")?;
    let bytes = lock(&recorder).take_pending();
    let written = match (&args.out, bytes) {
        (Some(out), Some((bytes, _))) => {
            let partial = out.with_extension("rrd.partial");
            std::fs::write(&partial, &bytes)
                .with_context(|| format!("writing {}", partial.display()))?;
            std::fs::rename(&partial, out).with_context(|| format!("writing {}", out.display()))?;
            bytes.len()
        }
        _ => 0,
    };
    let report = serde_json::json!({
        "task": episode.task,
        "success": episode.success,
        "length": episode.length,
        "transitions": episode.transitions.iter().map(|(step, from, to, event, reward)| {
            serde_json::json!({"step": step, "from": from, "to": to, "event": event, "reward": reward})
        }).collect::<Vec<_>>(),
        "out": args.out.as_ref().map(|p| p.display().to_string()),
        "connect": args.connect,
        "bytes": written,
    });
    emit(&format!("{report}\n"))
}
