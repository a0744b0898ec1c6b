//! `crm train`: PPO on the grasping environment inside the grasping CRM, with the reward mode
//! of the chosen algorithm; writes checkpoints and a metrics log.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use crm_learn::checkpoint::FORMAT;
use crm_learn::{Checkpoint, CheckpointHeader, EarlyStop, Layout, Ppo, PpoConfig, VecEnv};
use grasp_sim::{GraspEnv, TaskChoice};

use super::EnvArgs;

/// The learners by name. `crm-sac` comes with the rest of the learners issue.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Algorithm {
    /// PPO with intra-stage and transition rewards (the paper's method).
    CrmPpo,
    /// PPO with the stage-wise sparse transition rewards only.
    Ippo,
    /// PPO with the hierarchical dense intra-stage rewards only.
    Lppo,
    /// SAC inside the CRM (not available yet).
    CrmSac,
    /// PPO on the flat, unstaged machine (`crates/sim/specs/flat.json`): the ablation.
    Ppo,
}

impl Algorithm {
    pub fn name(self) -> &'static str {
        match self {
            Algorithm::CrmPpo => "crm-ppo",
            Algorithm::Ippo => "ippo",
            Algorithm::Lppo => "lppo",
            Algorithm::CrmSac => "crm-sac",
            Algorithm::Ppo => "ppo",
        }
    }

    pub fn reward_mode(self) -> crm::RewardMode {
        match self {
            Algorithm::Ippo => crm::RewardMode::Sparse,
            Algorithm::Lppo => crm::RewardMode::Dense,
            _ => crm::RewardMode::Crm,
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    #[arg(long, value_enum, default_value = "crm-ppo")]
    pub algo: Algorithm,
    /// Environment steps to train for.
    #[arg(long)]
    pub steps: i64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Directory for the checkpoint and metrics (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Train on one task (id) instead of random tasks.
    #[arg(long)]
    pub task: Option<String>,
    /// Environments stepped in parallel (default: one per core). Results depend on this
    /// number and the seed, not on the thread count.
    #[arg(long)]
    pub envs: Option<usize>,
    /// A JSON file with PPO settings (see `crm_learn::PpoConfig`); defaults cite the paper.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    if args.steps <= 0 {
        bail!("--steps must be positive, got {}", args.steps);
    }
    if args.algo == Algorithm::CrmSac {
        bail!("--algo crm-sac is not available yet; use crm-ppo, ippo, lppo or ppo");
    }
    let config: PpoConfig = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?
        }
        None => PpoConfig::default(),
    };
    config.validate()?;
    let benchmark = args.env.benchmark()?;
    let machine = match args.algo {
        Algorithm::Ppo => args.env.machine_or(grasp_sim::spec::flat_spec())?,
        _ => args.env.machine()?,
    };
    let choice = match &args.task {
        Some(id) => TaskChoice::Fixed(super::task_index(&benchmark, id)?),
        None => TaskChoice::Random,
    };
    let env_count = args.envs.unwrap_or_else(rayon::current_num_threads);
    if env_count == 0 {
        bail!("--envs must be at least 1");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let spec_hash = machine.spec().hash();
    let layout = Layout::of(&machine);
    let envs = (0..env_count)
        .map(|_| {
            let mut env = GraspEnv::new(benchmark.clone(), args.env.config());
            env.set_task_choice(choice)?;
            Ok(crm::CrmEnv::new(
                machine.clone(),
                env,
                args.algo.reward_mode(),
            ))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut envs = VecEnv::new(envs, args.seed)?;
    let mut ppo = Ppo::new(layout, config.clone(), args.seed)?;
    let mut early_stop = EarlyStop::new(config.early_stop_window, config.early_stop_success);
    let total = args.steps as u64;
    let mut done = 0u64;
    let metrics_path = args.out.join("metrics.jsonl");
    let mut metrics = std::fs::File::create(&metrics_path)
        .with_context(|| format!("creating {}", metrics_path.display()))?;
    let started = Instant::now();
    let mut stopped_early = false;
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} steps {per_sec} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let stage_names: Vec<String> = (0..layout.stages)
        .map(|s| machine.stage_name(s).to_string())
        .collect();
    while done < total {
        let steps = config.rollout_steps.min((total - done) as usize);
        let rollout = envs.collect(&mut ppo, steps.div_ceil(env_count))?;
        done += rollout.len() as u64;
        let stats = ppo.update(&rollout, done as f64 / total as f64)?;
        for &(success, _, _) in &rollout.episodes {
            stopped_early |= early_stop.record(success);
        }
        let episodes = rollout.episodes.len().max(1) as f64;
        let mean_return = rollout.episodes.iter().map(|e| f64::from(e.2)).sum::<f64>() / episodes;
        let mean_length = rollout.episodes.iter().map(|e| e.1 as f64).sum::<f64>() / episodes;
        let elapsed = started.elapsed().as_secs_f64();
        let line = serde_json::json!({
            "steps": done,
            "wall_s": elapsed,
            "steps_per_s": done as f64 / elapsed.max(1e-9),
            "episodes": rollout.episodes.len(),
            "success_rate_last_100": early_stop.success_rate(),
            "mean_return": mean_return,
            "mean_episode_length": mean_length,
            "losses/policy": stats.policy_loss,
            "losses/value": stats.value_loss,
            "losses/entropy": stats.entropy,
            "losses/approx_kl": stats.approx_kl,
            "losses/clipfrac": stats.clipfrac,
            "learning_rate": stats.learning_rate,
        });
        writeln!(metrics, "{line}")?;
        // Stage mix: the share of the rollout's steps taken in each stage.
        let mut mix = vec![0usize; layout.stages];
        for &stage in &rollout.stages {
            mix[stage] += 1;
        }
        let mix: Vec<String> = mix
            .iter()
            .zip(&stage_names)
            .filter(|(count, _)| **count > 0)
            .map(|(count, name)| {
                format!(
                    "{name} {:.0}%",
                    100.0 * *count as f64 / rollout.len().max(1) as f64
                )
            })
            .collect();
        let message = format!(
            "success(last 100) {:.2}  return {:.1}  length {:.1}  [{}]",
            early_stop.success_rate(),
            mean_return,
            mean_length,
            mix.join(", ")
        );
        if bar.is_hidden() {
            // Not a terminal (a log file, CI): one line per update instead of a bar.
            eprintln!(
                "{done}/{total} steps  {:.0} steps/s  {message}",
                done as f64 / elapsed.max(1e-9)
            );
        }
        bar.set_position(done.min(total));
        bar.set_message(message);
        if stopped_early {
            bar.println(format!(
                "early stop: the last {} episodes reached the success threshold",
                config.early_stop_window
            ));
            break;
        }
    }
    bar.finish();
    let header = CheckpointHeader {
        format: FORMAT.to_string(),
        algorithm: args.algo.name().to_string(),
        spec_hash,
        env_version: grasp_sim::ENV_VERSION.to_string(),
        seed: args.seed,
        steps: done,
        layout,
        hidden: config.hidden.clone(),
        config: serde_json::to_value(&config)?,
    };
    let path = args.out.join(format!("{}.safetensors", args.algo.name()));
    Checkpoint::save(&ppo.net, &header, &path)?;
    eprintln!("wrote {} and {}", path.display(), metrics_path.display());
    Ok(())
}
