//! `crm eval`: a checkpoint's success rate and episode length per objective over random
//! tasks with a fixed seed, as the paper's Table I.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use crm_learn::{Checkpoint, Layout, Ppo, PpoConfig};
use grasp_sim::GraspEnv;
use grasp_sim::benchmark::Objective;
use serde::Serialize;

use super::{EnvArgs, emit};

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
    /// Evaluate on one task (id) instead of random tasks.
    #[arg(long)]
    pub task: Option<String>,
    #[arg(long)]
    pub json: bool,
}

#[derive(Default, Serialize)]
struct Row {
    success_rate: f64,
    mean_episode_length: f64,
    episodes: u64,
}

#[derive(Serialize)]
struct Report {
    checkpoint: String,
    algorithm: String,
    trained_steps: u64,
    episodes: u64,
    success_rate: f64,
    mean_episode_length: f64,
    per_objective: BTreeMap<String, Row>,
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let benchmark = args.env.benchmark()?;
    // The flat ablation ("ppo") runs in its own machine.
    let algorithm = Checkpoint::read_header(&args.checkpoint)?.algorithm;
    let machine = if algorithm == "ppo" {
        args.env.machine_or(grasp_sim::spec::flat_spec())?
    } else {
        args.env.machine()?
    };
    let (net, header) = Checkpoint::load(
        &args.checkpoint,
        &machine.spec().hash(),
        grasp_sim::ENV_VERSION,
    )?;
    if net.layout() != Layout::of(&machine) {
        anyhow::bail!(
            "checkpoint {}: network layout {:?} does not fit the machine",
            args.checkpoint.display(),
            net.layout()
        );
    }
    let config = PpoConfig {
        hidden: header.hidden.clone(),
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(net.layout(), config, 0)?;
    ppo.net = net;
    let mut env = GraspEnv::new(benchmark.clone(), args.env.config());
    if let Some(id) = &args.task {
        let index = super::task_index(&benchmark, id)?;
        env.set_task_choice(grasp_sim::TaskChoice::Fixed(index))?;
    }
    let mut crm_env = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
    let mut sums: BTreeMap<Objective, (u64, u64, u64)> = BTreeMap::new();
    for k in 0..args.episodes {
        let seed = args.seed.wrapping_mul(1_000_003).wrapping_add(k);
        let (mut stage, mut state) = crm_env.reset(seed).context("reset")?;
        let objective = crm_env.env().objective();
        let (success, length) = loop {
            let mask = crm_env.machine().action_mask(stage);
            let (action, _) = ppo.act(&state, stage, &mask, true)?;
            let step = crm_env.step(&action)?;
            if step.done || step.truncated {
                let success = step.done && crm_env.machine().stage_name(step.stage) == "success";
                break (success, crm_env.episode().steps());
            }
            (stage, state) = (step.stage, step.abstract_state);
        };
        let entry = sums.entry(objective).or_default();
        entry.0 += 1;
        entry.1 += u64::from(success);
        entry.2 += length as u64;
    }
    let row = |(n, wins, length): (u64, u64, u64)| Row {
        success_rate: wins as f64 / n.max(1) as f64,
        mean_episode_length: length as f64 / n.max(1) as f64,
        episodes: n,
    };
    let total = sums
        .values()
        .fold((0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
    let overall = row(total);
    let report = Report {
        checkpoint: args.checkpoint.display().to_string(),
        algorithm: header.algorithm.clone(),
        trained_steps: header.steps,
        episodes: args.episodes,
        success_rate: overall.success_rate,
        mean_episode_length: overall.mean_episode_length,
        per_objective: sums
            .into_iter()
            .map(|(o, s)| (o.name().to_string(), row(s)))
            .collect(),
    };
    if args.json {
        return emit(&format!("{}\n", serde_json::to_string(&report)?));
    }
    let mut text = format!(
        "{} ({} steps): success {:.3}, mean length {:.1} over {} episodes\n\n| objective | success | episode length |\n| --- | --- | --- |\n",
        report.algorithm,
        report.trained_steps,
        report.success_rate,
        report.mean_episode_length,
        report.episodes
    );
    for (name, r) in &report.per_objective {
        text.push_str(&format!(
            "| {name} | {:.2} | {:.1} |\n",
            r.success_rate, r.mean_episode_length
        ));
    }
    text.push_str(&format!(
        "| overall | {:.2} | {:.1} |\n",
        report.success_rate, report.mean_episode_length
    ));
    emit(&text)
}
