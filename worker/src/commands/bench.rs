//! `crm bench`: figures from the real environment (speed targets live here, not in tests).

use std::time::Instant;

use grasp_sim::observation::ACTIONS;
use grasp_sim::{GraspEnv, SimConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use super::{EnvArgs, emit};

#[derive(clap::Subcommand, Debug)]
pub enum BenchCommand {
    /// Control steps per second of the grasping environment with random actions.
    Env(EnvBenchArgs),
    /// PPO rollout steps per second (policy in the loop) and update samples per second.
    Learn(LearnBenchArgs),
    /// Training's hold shortcut (`settle_s`) against the full hold on the same episodes.
    Hold(super::bench_hold::HoldBenchArgs),
}

#[derive(clap::Args, Debug)]
pub struct LearnBenchArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// PPO settings (JSON, any `PpoConfig` field): the batch geometry to time. The KL guard
    /// is off while timing, so every epoch runs.
    #[arg(long, value_name = "FILE")]
    pub config: Option<std::path::PathBuf>,
    /// Rollout steps per iteration (over all environments); default: the config's.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Iterations (rollout then update) timed end to end.
    #[arg(long, default_value_t = 2)]
    pub iterations: usize,
    /// Start from this CRM-PPO checkpoint's policy (a trained policy grasps, so its episodes
    /// include the arm's scripted executions, as late in training); default: untrained.
    #[arg(long, value_name = "FILE")]
    pub checkpoint: Option<std::path::PathBuf>,
    /// Environments stepped in parallel (default: one per core).
    #[arg(long)]
    pub envs: Option<usize>,
    #[arg(long)]
    pub json: bool,
    /// CRM-SAC gradient steps to time (batch 256).
    #[arg(long, default_value_t = 20)]
    pub sac_steps: usize,
    /// Split matrix products over threads, as candle's `gemm` does by default (`crm` runs
    /// each on one thread: see `crm_learn::kernels`), to compare the two.
    #[arg(long)]
    pub split_products: bool,
    /// How the PPO update computes gradients: `fused` (what training runs) or `candle`
    /// (autograd, the reference the fused path is tested against).
    #[arg(long, value_enum, default_value_t = Engine::Fused)]
    pub engine: Engine,
    /// Training's hold shortcut (`crm train --settle-s`), as a training run with it steps.
    #[arg(long, value_name = "SECONDS")]
    pub settle_s: Option<f64>,
}

/// `crm_learn::UpdateEngine` on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    Fused,
    Candle,
}

impl From<Engine> for crm_learn::UpdateEngine {
    fn from(engine: Engine) -> Self {
        match engine {
            Engine::Fused => Self::Fused,
            Engine::Candle => Self::Candle,
        }
    }
}

#[derive(Serialize)]
struct LearnReport {
    envs: usize,
    rollout_steps: usize,
    iterations: usize,
    rollout_steps_per_sec: f64,
    update_samples_per_sec: f64,
    /// Environment steps per second of whole training iterations (rollout and update).
    end_to_end_steps_per_sec: f64,
    /// Share of the iterations' wall time spent in the update.
    update_share: f64,
    /// Shares of the update's wall time: preparation (values, GAE, encoding), permutation
    /// gathers, forward and backward passes, the fused optimizer, reading statistics back.
    update_breakdown: std::collections::BTreeMap<&'static str, f64>,
    update_epochs: usize,
    minibatch_size: usize,
    hidden: Vec<usize>,
    /// CRM-SAC gradient steps per second (default `SacConfig`: batch 256, the same widths)
    /// over the rollout above stored in its replay buffer.
    sac_gradient_steps_per_sec: f64,
    sac_batch_size: usize,
    /// Whether matrix products were split over threads (`--split-products`).
    split_products: bool,
    /// The PPO update's engine (`--engine`).
    engine: Engine,
    /// Training's hold shortcut (`--settle-s`), if on.
    settle_s: Option<f64>,
}

#[derive(clap::Args, Debug)]
pub struct EnvBenchArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// Control steps to time on one core.
    #[arg(long, default_value_t = 6000)]
    pub steps: usize,
    /// Environments whose memory is measured together.
    #[arg(long, default_value_t = 64)]
    pub memory_envs: usize,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct EnvReport {
    control_steps_per_sec_one_core: f64,
    control_steps_per_sec_all_cores: f64,
    cores: usize,
    physics_steps_per_control_step: usize,
    physics_dt: f32,
    real_time_factor_one_core: f64,
    real_time_factor_all_cores: f64,
    peak_rss_bytes_per_env: f64,
    steps_timed_one_core: usize,
    episodes_one_core: usize,
}

pub fn run(command: BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Env(args) => env(args),
        BenchCommand::Learn(args) => learn(args),
        BenchCommand::Hold(args) => super::bench_hold::hold(args),
    }
}

/// A random action in the union space, in environment units (metres, radians): the grasping
/// spec's scales, so the hand moves as a policy would move it.
fn random_action(rng: &mut ChaCha8Rng) -> Vec<f32> {
    let mut action: Vec<f32> = (0..ACTIONS.len())
        .map(|_| rng.random_range(-1.0f32..=1.0))
        .collect();
    for value in &mut action[..3] {
        *value *= 0.01;
    }
    for value in &mut action[3..] {
        *value = 0.1 * (*value + 0.3);
    }
    action
}

/// Steps one environment through `steps` control steps of random actions over random tasks,
/// resetting when an episode ends (episodes end at the time limit or when the object leaves).
fn drive(env: &mut GraspEnv, steps: usize, seed: u64) -> anyhow::Result<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut episodes = 1;
    env.reset_seeded(seed)?;
    let horizon = 150;
    for k in 0..steps {
        let step = env.step_action(&random_action(&mut rng))?;
        if step.truncated || env.steps() >= horizon {
            env.reset_seeded(seed.wrapping_add(k as u64 + 1))?;
            episodes += 1;
        }
    }
    Ok(episodes)
}

fn rss_bytes() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

fn env(args: EnvBenchArgs) -> anyhow::Result<()> {
    let benchmark = args.env.env().benchmark()?;
    let config: SimConfig = args.env.env().config()?;

    let mut one = GraspEnv::new(benchmark.clone(), config.clone());
    drive(&mut one, 200, 99)?; // warm up caches and allocations
    let start = Instant::now();
    let episodes = drive(&mut one, args.steps, 1)?;
    let one_core = args.steps as f64 / start.elapsed().as_secs_f64();

    let cores = rayon::current_num_threads();
    let per_env = (args.steps / cores.max(1)).max(200);
    let start = Instant::now();
    (0..cores)
        .into_par_iter()
        .map(|k| {
            let mut env = GraspEnv::new(benchmark.clone(), config.clone());
            drive(&mut env, per_env, 1000 + k as u64)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let all_cores = (per_env * cores) as f64 / start.elapsed().as_secs_f64();

    let before = rss_bytes().unwrap_or(0.0);
    let mut envs = Vec::with_capacity(args.memory_envs);
    for k in 0..args.memory_envs {
        let mut env = GraspEnv::new(benchmark.clone(), config.clone());
        drive(&mut env, 30, 5000 + k as u64)?;
        envs.push(env);
    }
    let after = rss_bytes().unwrap_or(0.0);
    let per_env_bytes = (after - before).max(0.0) / args.memory_envs.max(1) as f64;
    drop(envs);

    let control_dt = f64::from(config.control_dt());
    let report = EnvReport {
        control_steps_per_sec_one_core: one_core,
        control_steps_per_sec_all_cores: all_cores,
        cores,
        physics_steps_per_control_step: config.substeps,
        physics_dt: config.physics_dt,
        real_time_factor_one_core: one_core * control_dt,
        real_time_factor_all_cores: all_cores * control_dt,
        peak_rss_bytes_per_env: per_env_bytes,
        steps_timed_one_core: args.steps,
        episodes_one_core: episodes,
    };
    if args.json {
        emit(&format!("{}\n", serde_json::to_string(&report)?))
    } else {
        emit(&format!("{}\n", serde_json::to_string_pretty(&report)?))
    }
}

fn learn(args: LearnBenchArgs) -> anyhow::Result<()> {
    if args.split_products {
        crm_learn::kernels::split_products();
    }
    let benchmark = args.env.env().benchmark()?;
    let machine = args.env.env().machine()?;
    let mut config: crm_learn::PpoConfig = super::read_json(&args.config)?;
    config.target_kl = 0.0;
    if let Some(steps) = args.steps {
        config.rollout_steps = steps;
    }
    config.validate()?;
    crm_api::jobs::check_settle_s(args.settle_s)
        .map_err(|message| anyhow::anyhow!("--settle-s {message}"))?;
    let sim = SimConfig {
        settle_s: args.settle_s.unwrap_or(0.0) as f32,
        ..args.env.env().config()?
    };
    let env_count = args.envs.unwrap_or_else(rayon::current_num_threads).max(1);
    let envs = (0..env_count)
        .map(|_| {
            crm::CrmEnv::new(
                machine.clone(),
                GraspEnv::new(benchmark.clone(), sim.clone()),
                crm::RewardMode::Crm,
            )
        })
        .collect();
    let mut envs = crm_learn::VecEnv::new(envs, 1)?;
    let mut ppo = crm_learn::Ppo::new(crm_learn::Layout::of(&machine), config.clone(), 1)?;
    ppo.set_engine(args.engine.into());
    if let Some(path) = &args.checkpoint {
        let (net, _) =
            crm_learn::Checkpoint::load(path, &machine.spec().hash(), grasp_sim::ENV_VERSION)?;
        ppo.load_weights(&net)?;
    }
    let per_env = config.rollout_steps.div_ceil(env_count).max(1);
    let (mut rollout_secs, mut update_secs, mut steps, mut samples) = (0.0, 0.0, 0, 0);
    let mut timing = crm_learn::UpdateTiming::default();
    let mut rollout = crm_learn::Rollout::default();
    for _ in 0..args.iterations.max(1) {
        let start = Instant::now();
        rollout = envs.collect(&mut ppo, per_env)?;
        rollout_secs += start.elapsed().as_secs_f64();
        let start = Instant::now();
        let stats = ppo.update(&rollout, 0.0)?;
        update_secs += start.elapsed().as_secs_f64();
        timing.prepare += stats.timing.prepare;
        timing.shuffle += stats.timing.shuffle;
        timing.forward_backward += stats.timing.forward_backward;
        timing.optimizer += stats.timing.optimizer;
        timing.bookkeeping += stats.timing.bookkeeping;
        steps += rollout.len();
        // Every minibatch but an epoch's last is full.
        samples += rollout.len() * stats.minibatches
            / rollout.len().div_ceil(config.minibatch_size).max(1);
    }
    let sac_config = crm_api::SacConfig {
        learning_starts: 0,
        ..crm_api::SacConfig::default()
    };
    let masks = (0..machine.stage_count())
        .map(|s| machine.action_mask(s))
        .collect();
    let mut sac = crm_learn::Sac::new(
        crm_learn::Layout::of(&machine),
        sac_config.clone(),
        masks,
        1,
    )?;
    sac.store(&rollout);
    let sac_steps = args.sac_steps.max(1);
    let start = Instant::now();
    sac.update(sac_steps)?;
    let sac_secs = start.elapsed().as_secs_f64();
    let report = LearnReport {
        envs: env_count,
        rollout_steps: rollout.len(),
        iterations: args.iterations.max(1),
        rollout_steps_per_sec: steps as f64 / rollout_secs,
        update_samples_per_sec: samples as f64 / update_secs,
        end_to_end_steps_per_sec: steps as f64 / (rollout_secs + update_secs),
        update_share: update_secs / (rollout_secs + update_secs),
        update_breakdown: [
            ("prepare", timing.prepare),
            ("shuffle", timing.shuffle),
            ("forward_backward", timing.forward_backward),
            ("optimizer", timing.optimizer),
            ("bookkeeping", timing.bookkeeping),
        ]
        .into_iter()
        .map(|(name, secs)| (name, secs / update_secs))
        .collect(),
        update_epochs: config.update_epochs,
        minibatch_size: config.minibatch_size,
        hidden: config.hidden,
        sac_gradient_steps_per_sec: sac_steps as f64 / sac_secs,
        sac_batch_size: sac_config.batch_size,
        split_products: crm_learn::kernels::products_split(),
        engine: args.engine,
        settle_s: args.settle_s,
    };
    if args.json {
        emit(&format!("{}\n", serde_json::to_string(&report)?))
    } else {
        emit(&format!("{}\n", serde_json::to_string_pretty(&report)?))
    }
}
