//! `crm bench hold`: training's shortcut through the hold (`settle_s`) against the paper's
//! full hold, on the same episodes of one checkpoint: how often the outcome (success, or the
//! failure and its kind) agrees, and what each costs in simulated and wall seconds.

use std::path::PathBuf;
use std::time::Instant;

use crm_api::EvalSpec;
use serde::Serialize;

use super::{EnvArgs, emit};
use crm_run::eval::{EpisodeRecord, evaluate_in};

#[derive(clap::Args, Debug)]
pub struct HoldBenchArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// The policy that grasps (its sampled actions, as the paper's evaluation).
    #[arg(long, value_name = "FILE")]
    pub checkpoint: PathBuf,
    #[arg(long, default_value_t = 1000)]
    pub episodes: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The shortcut's rest in the palm (s).
    #[arg(long, default_value_t = 0.5)]
    pub settle_s: f64,
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Disagreement {
    episode: u64,
    task: String,
    full_hold: String,
    shortcut: String,
}

#[derive(Serialize)]
struct HoldReport {
    episodes: u64,
    seed: u64,
    settle_s: f64,
    /// Episodes whose outcome label is the same both ways.
    agree: u64,
    agreement: f64,
    success_full_hold: f64,
    success_shortcut: f64,
    mean_sim_seconds_full_hold: f64,
    mean_sim_seconds_shortcut: f64,
    wall_s_full_hold: f64,
    wall_s_shortcut: f64,
    /// Per task: episodes and mean simulated seconds, full hold then shortcut.
    per_task: std::collections::BTreeMap<String, (u64, f64, f64)>,
    disagreements: Vec<Disagreement>,
}

pub fn hold(args: HoldBenchArgs) -> anyhow::Result<()> {
    crm_api::jobs::check_settle_s(Some(args.settle_s))
        .map_err(|message| anyhow::anyhow!("--settle-s {message}"))?;
    let report = compare(
        &args.checkpoint,
        &args.env,
        args.episodes,
        args.seed,
        args.settle_s,
    )?;
    if args.json {
        emit(&format!("{}\n", serde_json::to_string(&report)?))
    } else {
        emit(&format!("{}\n", serde_json::to_string_pretty(&report)?))
    }
}

/// Runs the same `episodes` of `checkpoint` (sampled actions, evaluation seed `seed`) with
/// the full hold and with the shortcut at `settle_s`, and compares their outcomes.
fn compare(
    checkpoint: &std::path::Path,
    env: &EnvArgs,
    episodes: u64,
    seed: u64,
    settle_s: f64,
) -> anyhow::Result<HoldReport> {
    let spec = EvalSpec {
        world: None,
        episodes,
        seed,
        task: None,
        tasks: Vec::new(),
        topology: None,
        record: None,
        video: None,
        objective: env.protocol,
        deterministic: false,
        hold_s: env.hold_s,
    };
    let full = env.env().config_for(spec.objective, spec.hold_s)?;
    let shortcut = grasp_sim::SimConfig {
        settle_s: settle_s as f32,
        ..full.clone()
    };
    let mut runs = Vec::new();
    for config in [full, shortcut] {
        let started = Instant::now();
        let mut episodes = Vec::new();
        evaluate_in(
            checkpoint,
            &spec,
            env.env(),
            config,
            None,
            |_, _, record| {
                episodes.push(record.clone());
                true
            },
        )?;
        runs.push((episodes, started.elapsed().as_secs_f64()));
    }
    let [(full, full_wall), (short, short_wall)] =
        <[_; 2]>::try_from(runs).map_err(|_| anyhow::anyhow!("two evaluations expected"))?;
    let n = full.len().max(1) as f64;
    let rate = |v: &[EpisodeRecord]| v.iter().filter(|e| e.success).count() as f64 / n;
    let seconds = |v: &[EpisodeRecord]| v.iter().map(|e| e.sim_seconds).sum::<f64>() / n;
    let disagreements: Vec<Disagreement> = full
        .iter()
        .zip(&short)
        .enumerate()
        .filter(|(_, (a, b))| a.outcome != b.outcome || a.task != b.task)
        .map(|(k, (a, b))| Disagreement {
            episode: k as u64,
            task: a.task.clone(),
            full_hold: a.outcome.clone(),
            shortcut: b.outcome.clone(),
        })
        .collect();
    let agree = full.len() as u64 - disagreements.len() as u64;
    let mut per_task = std::collections::BTreeMap::<String, (u64, f64, f64)>::new();
    for (a, b) in full.iter().zip(&short) {
        let row = per_task.entry(a.task.clone()).or_default();
        row.0 += 1;
        row.1 += a.sim_seconds;
        row.2 += b.sim_seconds;
    }
    for row in per_task.values_mut() {
        row.1 /= row.0 as f64;
        row.2 /= row.0 as f64;
    }
    Ok(HoldReport {
        episodes: full.len() as u64,
        seed,
        settle_s,
        agree,
        agreement: agree as f64 / n,
        success_full_hold: rate(&full),
        success_shortcut: rate(&short),
        mean_sim_seconds_full_hold: seconds(&full),
        mean_sim_seconds_shortcut: seconds(&short),
        wall_s_full_hold: full_wall,
        wall_s_shortcut: short_wall,
        per_task,
        disagreements,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped model's episodes end the same way with the shortcut as with the full hold,
    /// in less simulated time (a small sample; `crm bench hold` measures 1,000).
    #[test]
    fn the_hold_shortcut_keeps_the_shipped_models_outcomes() {
        let model =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/crm-ppo.safetensors");
        let report = compare(&model, &EnvArgs::default(), 30, 7, 0.5).expect("compare");
        let shown = serde_json::to_string(&report.disagreements).expect("json");
        assert_eq!(report.agree, 30, "{shown}");
        assert!(
            report.success_full_hold > 0.8,
            "{}",
            report.success_full_hold
        );
        assert!(
            report.mean_sim_seconds_shortcut < 0.8 * report.mean_sim_seconds_full_hold,
            "{} against {}",
            report.mean_sim_seconds_shortcut,
            report.mean_sim_seconds_full_hold
        );
    }
}
