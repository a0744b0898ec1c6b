//! `crm results`: the paper's Table I as a study of algorithms x seeds through a coordinator,
//! one that survives interruption and can be read without rerunning it. The runs go to the
//! coordinator as sweeps (every final checkpoint evaluated sampled and deterministic,
//! `study.rs`); each finished run is written under `OUT/results/NAME/` (`record.rs`) and
//! `OUT/RESULTS.md` is rebuilt from every study there (`report.rs`: Table I beside the
//! paper's, interval estimates of `stats.rs`, every run's early stop and wall-clock, the
//! curves and performance profile of `plot.rs`). The same command again continues the study:
//! finished runs are kept, interrupted ones resume from their last checkpoint, new seeds or
//! algorithms extend it. `--report-only` rebuilds the report from the files alone. With
//! `--coordinator URL` the study runs on that coordinator's workers; without, a coordinator
//! and local workers start in this process on `--data-dir`, as `crm up` does.

mod extend;
mod paper;
mod plot;
mod reading;
pub mod record;
mod redo;
mod report;
pub mod stats;
mod study;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use crm_api::{Algorithm, PpoConfig, SacConfig};

use super::read_json;
use super::remote::Rest;
use crate::service::{WorkerOptions, run_worker};

#[derive(clap::Args, Debug)]
pub struct ResultsArgs {
    /// Environment steps per run (the paper: 5,000,000); runs stop sooner by the early-stop
    /// rule of the PPO and SAC settings.
    #[arg(long, required_unless_present_any = ["report_only", "stats_of"])]
    pub steps: Option<u64>,
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
    /// Train these algorithms' runs again (repeat), after a fix to them: their runs are
    /// removed from the study's folder and their training jobs on the coordinator set aside
    /// (open ones cancelled), then trained anew. Not part of the command the study records.
    #[arg(
        long,
        value_parser = crate::commands::algorithm(),
        conflicts_with_all = ["report_only", "stats_of"]
    )]
    pub redo: Vec<Algorithm>,
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
    /// Folder for RESULTS.md; each study's runs and plots go to `OUT/results/NAME/`.
    #[arg(long, default_value = "docs")]
    pub out: PathBuf,
    /// The study's name, its folder under `OUT/results/` (default: `builtin` for the built-in
    /// world, else the world's name).
    #[arg(long)]
    pub name: Option<String>,
    /// The world the runs train and evaluate in, by the coordinator's name for it (default:
    /// the built-in world).
    #[arg(long)]
    pub world: Option<String>,
    /// A folder of world folders for the coordinator and workers started here (`crm up
    /// --worlds`).
    #[arg(long, value_name = "DIR")]
    pub worlds: Option<PathBuf>,
    /// Training's hold shortcut (s; `crm train --settle-s`); evaluations run the full hold.
    #[arg(long)]
    pub settle_s: Option<f64>,
    /// Why the budget is what it is, printed in the report.
    #[arg(long)]
    pub budget_note: Option<String>,
    /// Rebuild RESULTS.md and every plot from the studies under `OUT/results/`, without
    /// training or a coordinator.
    #[arg(long)]
    pub report_only: bool,
    /// Print the interval estimates of a score file as JSON and exit (`{"scores": {ALGO:
    /// [[run's task scores], ...]}, "reference": ALGO, "reps": N, "seed": S}`).
    #[arg(long, value_name = "FILE", conflicts_with = "report_only")]
    pub stats_of: Option<PathBuf>,
    /// Bootstrap samples per interval (rliable's default: 50,000).
    #[arg(long, default_value_t = stats::REPS)]
    pub reps: usize,
}

pub fn run(args: ResultsArgs) -> anyhow::Result<()> {
    if args.reps == 0 {
        bail!("--reps must be positive");
    }
    if let Some(path) = &args.stats_of {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let request: stats::StatsRequest =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        let answer = stats::answer(&request).with_context(|| path.display().to_string())?;
        println!("{}", serde_json::to_string(&answer)?);
        return Ok(());
    }
    if args.report_only {
        return write_report(&args.out, args.reps);
    }
    let steps = args.steps.unwrap_or_default();
    if steps == 0 || args.episodes == 0 || args.envs == 0 || args.seeds == 0 {
        bail!("--steps, --seeds, --episodes and --envs must be positive");
    }
    if let Some(settle) = args.settle_s {
        crm_api::jobs::check_settle_s(Some(settle))
            .map_err(|e| anyhow::anyhow!("--settle-s: {e}"))?;
    }
    let ppo: PpoConfig = read_json(&args.ppo_config)?;
    let sac: SacConfig = read_json(&args.sac_config)?;
    ppo.validate()?;
    sac.validate()?;
    match &args.coordinator {
        Some(url) => {
            let rest = Rest::new(url, args.token.clone(), args.ca.as_deref())?;
            // The coordinator's workers go on without this client: a signal ends it at once.
            study(&args, &rest, ppo, sac, &AtomicBool::new(false))
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
        worlds: args.worlds.clone(),
        ..crm_server::ServerConfig::default()
    };
    let running = runtime.block_on(crm_server::start(config))?;
    // SIGTERM or SIGINT: each local worker ends its job where it can resume (a training job
    // at the iteration's end with a checkpoint), gives it back and stops; then the study
    // stops, and the same command continues it.
    let stop = crate::service::stop_on_signals()?;
    let mut workers = Vec::new();
    for k in 0..args.workers.max(1) {
        let options = WorkerOptions {
            coordinator: format!("http://{}", running.grpc_addr),
            token: args.token.clone(),
            ca: None,
            name: format!("results-local{}", k + 1),
            checkpoint_every_s: 120,
            poll_s: 0.5,
            envs: None,
            worlds: args.worlds.clone(),
            max_jobs: None,
            idle_exit_s: None,
        };
        let stop = stop.clone();
        workers.push(runtime.spawn(async move {
            if let Err(err) = run_worker(options, stop).await {
                eprintln!("local worker stopped: {err:#}");
            }
        }));
    }
    let url = format!("http://{}", running.http_addr);
    eprintln!(
        "coordinator at {url} (dashboard: {url}/), data in {}",
        args.data_dir.display()
    );
    let rest = Rest::new(&url, args.token.clone(), None)?;
    let result = study(args, &rest, ppo, sac, &stop);
    stop.store(true, Ordering::Relaxed);
    // The workers give their jobs back (with a checkpoint) before the coordinator stops;
    // within `crm worker`'s default grace period.
    let all = async {
        for worker in workers {
            worker.await.ok();
        }
    };
    if runtime
        .block_on(async { tokio::time::timeout(Duration::from_secs(25), all).await })
        .is_err()
    {
        eprintln!(
            "a local worker did not stop within 25 s; its job is queued again when its lease expires"
        );
    }
    runtime.block_on(running.stop())?;
    runtime.shutdown_timeout(Duration::from_secs(2));
    result
}

/// Runs (or continues, or extends) the study of `args` on the coordinator at `rest`,
/// rebuilding the report after every run that lands and at the end.
fn study(
    args: &ResultsArgs,
    rest: &Rest,
    ppo: PpoConfig,
    sac: SacConfig,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let world = args.world.clone().unwrap_or_else(|| "crm".into());
    let name = args.name.clone().unwrap_or_else(|| {
        if world == "crm" {
            "builtin".into()
        } else {
            world.clone()
        }
    });
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        || name.starts_with('.')
    {
        bail!("--name: {name:?} must be letters, digits, '-', '_' and '.' (a folder name)");
    }
    let catalog = if world == "crm" {
        rest.get("/api/v1/tasks")?
    } else {
        rest.get(&format!("/api/v1/tasks?world={world}"))?
    };
    let task_objectives = catalog["tasks"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|t| args.task.is_empty() || args.task.iter().any(|id| t["id"].as_str() == Some(id)))
        .filter_map(|t| {
            Some((
                t["id"].as_str()?.to_string(),
                t["objective"].as_str()?.to_string(),
            ))
        })
        .collect();
    let algorithms = if args.algo.is_empty() {
        Algorithm::ALL.to_vec()
    } else {
        args.algo.clone()
    };
    let mut file = record::StudyFile {
        name: name.clone(),
        command: redo::recorded_command(std::env::args().skip(1)),
        world,
        steps: args.steps.unwrap_or_default(),
        envs: args.envs,
        tasks: args.task.clone(),
        episodes: args.episodes,
        eval_seed: args.eval_seed,
        seeds: (args.seed..args.seed + args.seeds).collect(),
        algorithms: algorithms.iter().map(|a| a.name().to_string()).collect(),
        ppo,
        sac,
        task_objectives,
        settle_s: args.settle_s,
        budget_note: args.budget_note.clone(),
        superseded: Default::default(),
    };
    let dir = args.out.join("results").join(&name);
    let path = dir.join("study.json");
    if path.exists() {
        let before = record::Study::read(&dir)?.file;
        file = extend::extend(&before, file, &path)?;
    }
    if !args.redo.is_empty() {
        redo::set_aside(rest, &dir, &mut file, &args.redo)?;
    }
    record::write_json(&path, &file)?;
    eprintln!(
        "study {name}: {} algorithms x {} seeds in {}",
        file.algorithms.len(),
        file.seeds.len(),
        dir.display()
    );
    study::run(rest, &dir, &file, stop, |_, _| {
        write_report(&args.out, args.reps)
    })?;
    write_report(&args.out, args.reps)
}

/// Rebuilds `OUT/RESULTS.md` and every study's plots from the studies under `OUT/results/`.
pub fn write_report(out: &std::path::Path, reps: usize) -> anyhow::Result<()> {
    let root = out.join("results");
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&root)
        .with_context(|| format!("reading {} (no study there yet?)", root.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("study.json").is_file())
        .collect();
    dirs.sort();
    if dirs.is_empty() {
        bail!(
            "{}: no study (a folder with a study.json) in it",
            root.display()
        );
    }
    let mut studies = Vec::new();
    for dir in dirs {
        let study = record::Study::read(&dir)?;
        if !study.runs.is_empty() {
            plots(&study)?;
        }
        let link = format!("results/{}", study.file.name);
        studies.push((study, link));
    }
    let path = out.join("RESULTS.md");
    std::fs::write(&path, report::markdown(&studies, reps))
        .with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// A study's curves and performance profile, in its folder.
fn plots(study: &record::Study) -> anyhow::Result<()> {
    plot::bands(
        study,
        &study.dir.join("success.png"),
        "training success rate (last 100 episodes)",
        Some((0.0, 1.0)),
        |it| it.success_rate_last_100,
    )?;
    plot::bands(
        study,
        &study.dir.join("episode_length.png"),
        "mean episode length (control steps)",
        Some((0.0, f64::INFINITY)),
        |it| it.mean_episode_length,
    )?;
    let tasks = report::common_tasks(study);
    let thresholds: Vec<f64> = (0..=100).map(|k| f64::from(k) / 100.0).collect();
    let profiles: Vec<(String, Vec<(f64, f64)>)> = study
        .file
        .algorithms
        .iter()
        .filter_map(|a| {
            let runs: Vec<&record::Run> = study.runs_of(a).collect();
            let scores = report::scores(&runs, &tasks, false)?;
            let shares = stats::profile(&scores, &thresholds);
            Some((a.clone(), thresholds.iter().copied().zip(shares).collect()))
        })
        .collect();
    plot::profile(&study.dir.join("profile.png"), &profiles)
}
