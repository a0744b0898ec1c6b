//! `crm results`: the paper's Table I as one sweep through a coordinator. It submits the
//! algorithms x seeds grid (`POST /api/v1/sweeps`, every final checkpoint evaluated on one
//! evaluation seed), waits with a progress bar, and writes `RESULTS.md` (Table I as mean ± std
//! over seeds beside the paper's numbers, row by row; budget, seeds, settings, wall-clock per
//! algorithm) and curves with ±1 std bands as PNG (`plot.rs`). With `--coordinator URL` the
//! study runs on that coordinator's workers (on other machines too); without, a coordinator
//! and local workers start in this process, as `crm up` does.

mod plot;
mod table;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use crm_api::{Algorithm, Iteration, PpoConfig, SacConfig};
use serde_json::{Value, json};

use super::read_json;
use super::remote::Rest;
use crate::service::{WorkerOptions, run_worker};

#[derive(clap::Args, Debug)]
pub struct ResultsArgs {
    /// Environment steps per run (the paper: 5,000,000).
    #[arg(long)]
    pub steps: u64,
    /// Training seeds per algorithm: SEED, SEED+1, ... (the paper: 5).
    #[arg(long, default_value_t = 5)]
    pub seeds: u64,
    /// The first training seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Tasks to train and evaluate on (repeat; default: the whole benchmark).
    #[arg(long)]
    pub task: Vec<String>,
    /// Evaluation episodes per checkpoint (the paper: 1,000).
    #[arg(long, default_value_t = 1000)]
    pub episodes: u64,
    /// The evaluation seed, the same for every checkpoint.
    #[arg(long, default_value_t = 1_000_000)]
    pub eval_seed: u64,
    /// Environments stepped in parallel per run.
    #[arg(long, default_value_t = 2)]
    pub envs: usize,
    /// Algorithms to compare (repeat; default: all five).
    #[arg(long, value_parser = crate::commands::algorithm())]
    pub algo: Vec<Algorithm>,
    /// PPO settings for crm-ppo, ippo, lppo and ppo (JSON; default: the paper's).
    #[arg(long, value_name = "FILE")]
    pub ppo_config: Option<PathBuf>,
    /// SAC settings for crm-sac (JSON).
    #[arg(long, value_name = "FILE")]
    pub sac_config: Option<PathBuf>,
    /// The coordinator's REST address (http://HOST:8080); without it, one starts here.
    #[arg(long, value_name = "URL")]
    pub coordinator: Option<String>,
    /// The coordinator's bearer token.
    #[arg(long, env = "CRM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// The CA certificate (PEM) of an `https://` coordinator with a private CA (`crm certs
    /// dev` writes `ca.pem`); without it the system's roots are used.
    #[arg(long, value_name = "FILE")]
    pub ca: Option<PathBuf>,
    /// Local workers of the coordinator started here (without `--coordinator`).
    #[arg(long, default_value_t = 1)]
    pub workers: usize,
    /// Data folder of the coordinator started here.
    #[arg(long, default_value = "runs/results-data")]
    pub data_dir: PathBuf,
    /// Folder for RESULTS.md; the plots go to its `results/` subfolder.
    #[arg(long, default_value = "docs")]
    pub out: PathBuf,
}

/// What the study needs to write its report.
pub struct Study {
    pub args_line: String,
    pub coordinator: String,
    pub sweep: Value,
    pub ppo: PpoConfig,
    pub sac: SacConfig,
    /// Per training run: its algorithm, seed and metric series.
    pub curves: Vec<(String, u64, Vec<Iteration>)>,
}

pub fn run(args: ResultsArgs) -> anyhow::Result<()> {
    if args.steps == 0 || args.episodes == 0 || args.envs == 0 || args.seeds == 0 {
        bail!("--steps, --seeds, --episodes and --envs must be positive");
    }
    let ppo: PpoConfig = read_json(&args.ppo_config)?;
    let sac: SacConfig = read_json(&args.sac_config)?;
    ppo.validate()?;
    sac.validate()?;
    match &args.coordinator {
        Some(url) => {
            let rest = Rest::new(url, args.token.clone(), args.ca.as_deref())?;
            study(&args, &rest, url, ppo, sac)
        }
        None => local(&args, ppo, sac),
    }
}

/// Starts a coordinator with `--workers` local workers, runs the study on it, stops it.
fn local(args: &ResultsArgs, ppo: PpoConfig, sac: SacConfig) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let config = crm_server::ServerConfig {
        http: "127.0.0.1:0".into(),
        grpc: "127.0.0.1:0".into(),
        data_dir: args.data_dir.clone(),
        token: args.token.clone(),
        ..crm_server::ServerConfig::default()
    };
    let running = runtime.block_on(crm_server::start(config))?;
    let stop = Arc::new(AtomicBool::new(false));
    for k in 0..args.workers.max(1) {
        let options = WorkerOptions {
            coordinator: format!("http://{}", running.grpc_addr),
            token: args.token.clone(),
            ca: None,
            name: format!("results-local{}", k + 1),
            checkpoint_every_s: 120,
            poll_s: 0.5,
            envs: None,
            worlds: None,
        };
        let stop = stop.clone();
        runtime.spawn(async move {
            if let Err(err) = run_worker(options, stop).await {
                eprintln!("local worker stopped: {err:#}");
            }
        });
    }
    let url = format!("http://{}", running.http_addr);
    eprintln!(
        "coordinator at {url} (dashboard: {url}/), data in {}",
        args.data_dir.display()
    );
    let rest = Rest::new(&url, args.token.clone(), None)?;
    let result = study(args, &rest, &url, ppo, sac);
    stop.store(true, Ordering::Relaxed);
    runtime.block_on(running.stop())?;
    runtime.shutdown_timeout(Duration::from_secs(2));
    result
}

/// Submits the sweep, waits for it, fetches the curves and writes the report.
fn study(
    args: &ResultsArgs,
    rest: &Rest,
    url: &str,
    ppo: PpoConfig,
    sac: SacConfig,
) -> anyhow::Result<()> {
    let algorithms = if args.algo.is_empty() {
        Algorithm::ALL.to_vec()
    } else {
        args.algo.clone()
    };
    let seeds: Vec<u64> = (args.seed..args.seed + args.seeds).collect();
    let request = json!({
        "name": "crm results: Table I",
        "base": {
            "steps": args.steps, "envs": args.envs, "tasks": args.task,
            "config": ppo, "sac": sac,
        },
        "axes": {
            "algorithm": algorithms.iter().map(|a| a.name()).collect::<Vec<_>>(),
            "seed": seeds,
        },
        "eval": {"episodes": args.episodes, "seed": args.eval_seed, "tasks": args.task},
    });
    let created = rest.post_json("/api/v1/sweeps", &request)?;
    let id = created["sweep"]["id"]
        .as_i64()
        .context("the coordinator's answer has no sweep id")?;
    eprintln!(
        "sweep {id}: {} runs; follow it at {url}/sweeps/{id}",
        algorithms.len() * seeds.len()
    );
    let bar = indicatif::ProgressBar::new(0);
    let sweep = loop {
        let sweep = rest.get(&format!("/api/v1/sweeps/{id}"))?;
        let progress = &sweep["progress"];
        bar.set_length(progress["jobs"].as_u64().unwrap_or(0));
        bar.set_position(progress["finished"].as_u64().unwrap_or(0));
        if progress["fraction"].as_f64().unwrap_or(0.0) >= 1.0 {
            break sweep;
        }
        std::thread::sleep(Duration::from_secs(2));
    };
    bar.finish_and_clear();
    let failed: Vec<String> = sweep["jobs"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|j| j["state"] == "failed")
        .map(|j| {
            format!(
                "job {}: {}",
                j["id"],
                j["error"].as_str().unwrap_or("no message")
            )
        })
        .collect();
    if !failed.is_empty() {
        eprintln!(
            "{} jobs failed (the table leaves them out):\n  {}",
            failed.len(),
            failed.join("\n  ")
        );
    }
    let mut curves = Vec::new();
    for run in sweep["jobs"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|j| j["kind"] == "train")
    {
        let id = run["id"].as_i64().context("a job without id")?;
        let metrics = rest.get(&format!("/api/v1/runs/{id}/metrics"))?;
        let series: Vec<Iteration> = metrics["metrics"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|m| serde_json::from_value(m["data"].clone()).ok())
            .collect();
        let algorithm = run["algorithm"].as_str().unwrap_or_default().to_string();
        curves.push((algorithm, run["spec"]["seed"].as_u64().unwrap_or(0), series));
    }
    let study = Study {
        args_line: std::env::args().skip(1).collect::<Vec<_>>().join(" "),
        coordinator: url.to_string(),
        sweep,
        ppo,
        sac,
        curves,
    };
    let plots = args.out.join("results");
    std::fs::create_dir_all(&plots).with_context(|| format!("creating {}", plots.display()))?;
    plot::bands(
        &study,
        &plots.join("success.png"),
        "success rate (last 100 episodes)",
        Some((0.0, 1.0)),
        |it| it.success_rate_last_100,
    )?;
    plot::bands(
        &study,
        &plots.join("episode_length.png"),
        "mean episode length (control steps)",
        Some((0.0, f64::INFINITY)),
        |it| it.mean_episode_length.unwrap_or(f64::NAN),
    )?;
    let path = args.out.join("RESULTS.md");
    std::fs::write(&path, table::markdown(args, &study))
        .with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
