//! `crm train`: PPO on the grasping environment inside the grasping CRM, with the reward mode
//! of the chosen algorithm; writes a checkpoint and a metrics log (one JSON line per
//! iteration).

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};
use crm_learn::PpoConfig;

use super::{EnvArgs, read_json};
use crm_api::{Algorithm, ImitationSpec, SacConfig, TrainSpec};
use crm_run::Trainer;
use crm_run::imitation;

#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// A training job's document as `POST /api/v1/jobs` takes it (`kind` may be left out;
    /// the experiment document `{"env", "algorithm", "run"}` or the flat form), instead of the
    /// flags that set its fields; --steps, --seed and --envs override it. Its
    /// `world`, `fine_tune` and `record` name a coordinator's things: give --world DIR and
    /// --fine-tune FILE here.
    #[arg(long, value_name = "FILE", conflicts_with_all = [
        "algo", "config", "task", "topology", "init_log_std", "bc_episodes", "bc_epochs",
        "bc_noise", "bc_learning_rate", "bc_tasks", "bc_shifts", "bc_stages",
        "bc_anchor_episodes", "curriculum", "settle_s", "protocol", "hold_s",
    ])]
    pub job: Option<PathBuf>,
    #[arg(long, value_parser = super::algorithm(), default_value = "crm-ppo")]
    pub algo: Algorithm,
    /// Environment steps to train for (in total, counting a resumed checkpoint's).
    #[arg(long, required_unless_present = "job")]
    pub steps: Option<i64>,
    /// The run's seed (default 0, or the --job document's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Directory for the checkpoint and metrics (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Train on this task (id; repeat for several) instead of random tasks.
    #[arg(long)]
    pub task: Vec<String>,
    /// Grasp topology: `task` (each task's assigned one), `auto` (the selection network's
    /// pick) or a topology name forced on every task.
    #[arg(long)]
    pub topology: Option<String>,
    /// Environments stepped in parallel (default: one per core). Results depend on this
    /// number and the seed, not on the thread count.
    #[arg(long)]
    pub envs: Option<usize>,
    /// A JSON file with the learner's settings (`crm_api::PpoConfig`, or `crm_api::SacConfig`
    /// for crm-sac); defaults cite the paper.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Resume from this checkpoint (same algorithm and machine).
    #[arg(long, value_name = "FILE")]
    pub resume: Option<PathBuf>,
    /// Start from this checkpoint's weights, trained in another world with the same machine
    /// and observation layout (the same hand with fewer sensors); steps count from 0.
    #[arg(long, value_name = "FILE", conflicts_with = "resume")]
    pub fine_tune: Option<PathBuf>,
    /// Every log standard deviation of the policy at the start, over the --config file's
    /// `init_log_std` (absent from both: 0 on fresh weights, the --fine-tune checkpoint's own);
    /// a --resume keeps the checkpoint's. `--start-log-std` is its older name.
    #[arg(
        long,
        value_name = "LOG_STD",
        allow_negative_numbers = true,
        alias = "start-log-std"
    )]
    pub init_log_std: Option<f64>,
    /// Also write a checkpoint every this many iterations (0: only at the end).
    #[arg(long, default_value_t = 0)]
    pub checkpoint_every: u64,
    /// Keep each periodic checkpoint as `ALGO-STEPS.safetensors` beside the latest (to find
    /// afterwards when a run first met a bar).
    #[arg(long)]
    pub keep_checkpoints: bool,
    /// Before PPO, clone the scripted oracle's successful episodes out of this many (0: off).
    #[arg(long, default_value_t = 0)]
    pub bc_episodes: u64,
    /// Passes over the oracle's demonstrations.
    #[arg(long, default_value_t = 20)]
    pub bc_epochs: usize,
    /// Noise (standard deviation, in action units) on the oracle's executed actions while
    /// it demonstrates; the labels stay clean (DART).
    #[arg(long, default_value_t = 0.0)]
    pub bc_noise: f64,
    /// Learning rate of behaviour cloning.
    #[arg(long, default_value_t = 1e-3)]
    pub bc_learning_rate: f64,
    /// Only these tasks are demonstrated (ids; repeat the flag); none: the training tasks.
    #[arg(long = "bc-task", value_name = "TASK")]
    pub bc_tasks: Vec<String>,
    /// The oracle moves the palm by DX,DY,DZ (m, world frame) from TASK's grasp location
    /// before it closes, as `crm oracle --shift` does (repeat the flag).
    #[arg(long = "bc-shift", value_name = "TASK=DX,DY,DZ", value_parser = crm_api::parse_shift)]
    pub bc_shifts: Vec<(String, [f64; 3])>,
    /// Only these stages' steps are cloned (names, e.g. `grasp`; repeat the flag); none: all.
    #[arg(long = "bc-stage", value_name = "STAGE")]
    pub bc_stages: Vec<String>,
    /// Episodes of the starting policy on the training tasks not in --bc-task (all of them
    /// without it) whose states keep its own actions in behaviour cloning (0: none).
    #[arg(long, default_value_t = 0)]
    pub bc_anchor_episodes: u64,
    /// Draw tasks more often where the policy fails (a job's `curriculum`); off: uniform, as
    /// in the paper.
    #[arg(long)]
    pub curriculum: bool,
    /// Training's shortcut through the hold (a job's `settle_s`): a hold grasp whose object
    /// has rested in the palm for this many seconds passes then; off without it.
    #[arg(long, value_name = "SECONDS", value_parser = parse_settle_s)]
    pub settle_s: Option<f64>,
    /// Also log the run to this MLflow tracking server (`http://HOST:PORT`): parameters,
    /// every metric by step, tags, the final checkpoint. A server that is down or refuses is
    /// reported and retried; it never stops the training.
    #[arg(long, value_name = "URI", env = "MLFLOW_TRACKING_URI")]
    pub mlflow_uri: Option<String>,
    /// The MLflow experiment (made when missing).
    #[arg(
        long,
        value_name = "NAME",
        env = "MLFLOW_EXPERIMENT_NAME",
        default_value = "crm-grasp"
    )]
    pub mlflow_experiment: String,
    /// The MLflow run's name (default: the --out folder's name).
    #[arg(long, value_name = "NAME")]
    pub mlflow_run_name: Option<String>,
    /// Seconds a finished run waits for its last MLflow records to reach the server.
    #[arg(long, value_name = "SECONDS", default_value_t = 30)]
    pub mlflow_wait_s: u64,
}

/// `--settle-s`: seconds within [`crm_api::jobs::SETTLE_S_RANGE`].
fn parse_settle_s(text: &str) -> Result<f64, String> {
    let settle: f64 = text
        .parse()
        .map_err(|_| format!("{text:?} is not a number of seconds"))?;
    crm_api::jobs::check_settle_s(Some(settle))?;
    Ok(settle)
}

pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    if let Some(steps) = args.steps
        && steps <= 0
    {
        bail!("--steps must be positive, got {steps}");
    }
    let spec = match &args.job {
        Some(path) => job_spec(&args, path)?,
        None => flag_spec(&args)?,
    };
    let init = match (&args.resume, &args.fine_tune) {
        (Some(path), _) => Some(crm_run::Init::Resume(path)),
        (None, Some(path)) => Some(crm_run::Init::FineTune(path)),
        (None, None) => None,
    };
    let mut trainer = Trainer::new(spec.clone(), args.env.env(), init, None)?;
    trainer.set_command(std::env::args().collect());
    let bar = indicatif::ProgressBar::new(0);
    imitation::imitate(
        &spec,
        args.env.env(),
        &mut trainer,
        |line| {
            eprintln!("{line}");
            true
        },
        |name, done, total| {
            bar.set_length(total);
            bar.set_position(done);
            bar.set_message(name.to_string());
            true
        },
    )?;
    bar.finish_and_clear();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let metrics_path = args.out.join("metrics.jsonl");
    if let Some(made_on) = trainer.resumed_state_from() {
        // The same run goes on: the log keeps what it wrote up to the checkpoint.
        keep_metrics_until(&metrics_path, trainer.steps())?;
        let here = crm_learn::state::this_machine();
        if made_on != here {
            eprintln!(
                "note: the checkpoint's state was made on {made_on}, this is {here}: the run \
                 goes on, but floating-point results differ between CPU types"
            );
        }
    }
    let mut metrics = std::fs::OpenOptions::new()
        .create(true)
        .append(args.resume.is_some())
        .write(true)
        .truncate(args.resume.is_none())
        .open(&metrics_path)
        .with_context(|| format!("creating {}", metrics_path.display()))?;
    let mut events = tensorboard_events(&args.out, &metrics_path, &spec)?;
    let mlflow = match &args.mlflow_uri {
        Some(uri) => {
            let target = crate::mlflow::Target {
                uri: uri.clone(),
                experiment: args.mlflow_experiment.clone(),
                run_name: args.mlflow_run_name.clone().unwrap_or_else(|| {
                    args.out
                        .file_name()
                        .map_or("crm-train".into(), |n| n.to_string_lossy().to_string())
                }),
            };
            // A resumed run goes on in the MLflow run of its --out folder (the newest there).
            let out = std::fs::canonicalize(&args.out)
                .unwrap_or_else(|_| args.out.clone())
                .display()
                .to_string();
            let find = if args.resume.is_some() {
                crate::mlflow::Find::OrCreate("crm.out".into(), out)
            } else {
                crate::mlflow::Find::Tagged("crm.out".into(), out)
            };
            Some(crate::mlflow::Logger::training(
                &target,
                &spec,
                trainer.world(),
                find,
            )?)
        }
        None => None,
    };
    let checkpoint = args
        .out
        .join(format!("{}.safetensors", spec.algorithm.name()));
    let total = spec.steps;
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} steps {per_sec} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.set_position(trainer.steps().min(total));
    // SIGTERM or SIGINT: stop at the end of the iteration with a checkpoint to resume from.
    let stop = crate::service::stop_on_signals()?;
    while !trainer.finished() {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            trainer.save(&checkpoint)?;
            bar.abandon();
            eprintln!(
                "stopped at {} steps: resume with --resume {}",
                trainer.steps(),
                checkpoint.display()
            );
            if let Some(mlflow) = mlflow {
                mlflow.finish(Some("KILLED"), Duration::from_secs(args.mlflow_wait_s));
            }
            return Ok(());
        }
        let it = trainer.iterate()?;
        writeln!(metrics, "{}", serde_json::to_string(&it)?)?;
        events.iteration(&it)?;
        if let Some(mlflow) = &mlflow {
            mlflow.metrics(it.steps, &crm_api::tensorboard::scalars(&it));
        }
        let mix: Vec<String> = it
            .stage_mix
            .iter()
            .map(|(name, share)| format!("{name} {:.0}%", 100.0 * share))
            .collect();
        let message = format!(
            "success(last 100) {:.2}  return {}  length {}  [{}]{}",
            it.success_rate_last_100,
            it.mean_return.map_or("-".into(), |v| format!("{v:.1}")),
            it.mean_episode_length
                .map_or("-".into(), |v| format!("{v:.1}")),
            mix.join(", "),
            weakest(&it.task_success, 3)
        );
        if bar.is_hidden() {
            // Not a terminal (a log file, CI): one line per iteration instead of a bar.
            eprintln!(
                "{}/{total} steps  {:.0} steps/s  {message}",
                it.steps, it.steps_per_s
            );
        }
        bar.set_position(it.steps.min(total));
        bar.set_message(message);
        if args.checkpoint_every > 0 && it.iteration % args.checkpoint_every == 0 {
            trainer.save(&checkpoint)?;
            if args.keep_checkpoints {
                let kept = args.out.join(format!(
                    "{}-{}.safetensors",
                    spec.algorithm.name(),
                    it.steps
                ));
                std::fs::copy(&checkpoint, &kept)
                    .with_context(|| format!("keeping {}", kept.display()))?;
            }
        }
    }
    if trainer.stopped_early() {
        let line = format!(
            "early stop at {} steps: the last {} episodes reached the success threshold",
            trainer.steps(),
            trainer.early_stop_window()
        );
        // A hidden bar (a log file) prints nothing of its own.
        if bar.is_hidden() {
            eprintln!("{line}");
        } else {
            bar.println(line);
        }
    }
    bar.finish();
    trainer.save(&checkpoint)?;
    eprintln!(
        "wrote {} and {}",
        checkpoint.display(),
        metrics_path.display()
    );
    if let Some(mlflow) = mlflow {
        mlflow.checkpoint(&checkpoint)?;
        if let Some(id) = mlflow.finish(Some("FINISHED"), Duration::from_secs(args.mlflow_wait_s)) {
            eprintln!("logged to MLflow as run {id}");
        }
    }
    Ok(())
}

/// The run's TensorBoard event file, `OUT/events.out.tfevents.crm-train`, written anew from
/// the metrics log so far (a resumed run's earlier iterations included), for the run's
/// iterations to be appended as they come (`crm_api::tensorboard`).
fn tensorboard_events(
    out: &std::path::Path,
    metrics: &std::path::Path,
    spec: &TrainSpec,
) -> anyhow::Result<crm_api::tensorboard::Writer<std::io::BufWriter<std::fs::File>>> {
    let earlier: Vec<crm_api::Iteration> = std::fs::read_to_string(metrics)
        .unwrap_or_default()
        .lines()
        .filter_map(|line| serde_json::from_str(line).ok())
        .collect();
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    let path = out.join("events.out.tfevents.crm-train");
    let file =
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
    let mut writer = crm_api::tensorboard::Writer::new(
        std::io::BufWriter::new(file),
        &serde_json::to_value(spec)?,
        now,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    for it in &earlier {
        writer.iteration(it)?;
    }
    Ok(writer)
}

/// Drops the lines of a metrics log past `steps` (what a killed run wrote after its last
/// checkpoint), so a resumed run's log reads as if it had never stopped.
fn keep_metrics_until(path: &std::path::Path, steps: u64) -> anyhow::Result<()> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(());
    };
    let kept: String = text
        .lines()
        .filter(|line| {
            serde_json::from_str::<serde_json::Value>(line)
                .ok()
                .and_then(|v| v["steps"].as_u64())
                .is_some_and(|s| s <= steps)
        })
        .map(|line| format!("{line}\n"))
        .collect();
    std::fs::write(path, kept).with_context(|| format!("rewriting {}", path.display()))
}

/// The training spec the flags make.
fn flag_spec(args: &TrainArgs) -> anyhow::Result<TrainSpec> {
    let imitation = (args.bc_episodes > 0).then_some(ImitationSpec {
        episodes: args.bc_episodes,
        epochs: args.bc_epochs,
        learning_rate: args.bc_learning_rate,
        noise: args.bc_noise,
        tasks: args.bc_tasks.clone(),
        shifts: args.bc_shifts.iter().cloned().collect(),
        stages: args.bc_stages.clone(),
        anchor_episodes: args.bc_anchor_episodes,
    });
    if imitation.is_none()
        && !(args.bc_tasks.is_empty()
            && args.bc_shifts.is_empty()
            && args.bc_stages.is_empty()
            && args.bc_anchor_episodes == 0)
    {
        bail!(
            "--bc-task, --bc-shift, --bc-stage and --bc-anchor-episodes shape behaviour cloning: give --bc-episodes too"
        );
    }
    if let Some(imitation) = &imitation {
        imitation.validate().map_err(|e| {
            let flag = match e.field {
                "tasks" => "task".to_string(),
                "shifts" => "shift".to_string(),
                "stages" => "stage".to_string(),
                field => field.replace('_', "-"),
            };
            anyhow::anyhow!("--bc-{flag}: {}", e.message)
        })?;
        if !ImitationSpec::supports(args.algo) {
            bail!(
                "--bc-episodes: behaviour cloning is for the PPO learners of the grasping machine (crm-ppo, ippo, lppo)"
            );
        }
    }
    // The flag's checks are those of the job field it stands for.
    crm_api::jobs::check_start_log_std(args.algo, args.init_log_std, None)
        .map_err(|message| anyhow::anyhow!("--init-log-std: {message}"))?;
    let (mut config, sac) = if args.algo == Algorithm::CrmSac {
        (PpoConfig::default(), read_json::<SacConfig>(&args.config)?)
    } else {
        (read_json::<PpoConfig>(&args.config)?, SacConfig::default())
    };
    if args.init_log_std.is_some() {
        config.init_log_std = args.init_log_std;
    }
    Ok(TrainSpec {
        algorithm: args.algo,
        world: None,
        steps: args.steps.unwrap_or_default() as u64,
        seed: args.seed.unwrap_or_default(),
        task: None,
        tasks: args.task.clone(),
        topology: args.topology.clone(),
        envs: args.envs,
        config,
        sac,
        record: None,
        imitation,
        // The command line names a file (`--fine-tune`), not a stored checkpoint.
        fine_tune: None,
        start_log_std: None,
        objective: args.env.protocol,
        curriculum: args.curriculum,
        hold_s: args.env.hold_s,
        settle_s: args.settle_s,
    })
}

/// The training spec of a `--job` document, with --steps, --seed and --envs over it.
fn job_spec(args: &TrainArgs, path: &std::path::Path) -> anyhow::Result<TrainSpec> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut document: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    if let Some(fields) = document.as_object_mut() {
        match fields.remove("kind") {
            None => {}
            Some(serde_json::Value::String(kind)) if kind == "train" => {}
            Some(other) => bail!(
                "{}: kind: a training job's is \"train\", not {other}",
                path.display()
            ),
        }
    }
    // The experiment document (`env`, `algorithm`, `run`) or the flat form.
    let nested = document
        .as_object()
        .is_some_and(crm_api::document::is_document);
    let name = |field: &str| match nested {
        true => crm_api::document::document_path(field),
        false => field.to_string(),
    };
    let parsed = match nested {
        true => serde_json::from_value::<crm_api::TrainDocument>(document).map(TrainSpec::from),
        false => serde_json::from_value(document),
    };
    let mut spec: TrainSpec =
        parsed.with_context(|| format!("parsing {} as a training job", path.display()))?;
    for (field, set, instead) in [
        ("world", spec.world.is_some(), "give --world DIR"),
        (
            "fine_tune",
            spec.fine_tune.is_some(),
            "give --fine-tune FILE",
        ),
        ("record", spec.record.is_some(), "record with `crm record`"),
    ] {
        if set {
            bail!(
                "{}: {} names the coordinator's things, which `crm train` does not have: {instead}",
                path.display(),
                name(field)
            );
        }
    }
    if let Some(steps) = args.steps {
        spec.steps = steps as u64;
    }
    if let Some(seed) = args.seed {
        spec.seed = seed;
    }
    if args.envs.is_some() {
        spec.envs = args.envs;
    }
    spec.validate().map_err(|err| {
        let err = crm_api::SpecError {
            field: name(&err.field),
            ..err
        };
        anyhow::anyhow!("{}: {err}", path.display())
    })?;
    Ok(spec)
}

/// The `count` tasks with the lowest training success (`  weakest: bowl-lift 0.12, ...`), or
/// nothing for a run on fewer tasks than that.
fn weakest(task_success: &std::collections::BTreeMap<String, f64>, count: usize) -> String {
    if task_success.len() <= count {
        return String::new();
    }
    let listed: Vec<String> = crm_api::jobs::weakest_tasks(task_success, count)
        .iter()
        .map(|(task, success)| format!("{task} {success:.2}"))
        .collect();
    format!("  weakest: {}", listed.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_weakest_tasks_are_listed_lowest_first() {
        let tasks: std::collections::BTreeMap<String, f64> = [
            ("a-lift", 0.9),
            ("b-pull", 0.1),
            ("c-press", 1.0),
            ("d-twist", 0.1),
        ]
        .into_iter()
        .map(|(t, s)| (t.to_string(), s))
        .collect();
        assert_eq!(weakest(&tasks, 2), "  weakest: b-pull 0.10, d-twist 0.10");
        assert_eq!(weakest(&tasks, 4), "");
    }
}
