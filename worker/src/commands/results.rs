//! `crm results`: the paper's Table I at one training budget. Trains each algorithm with the
//! same seed, tasks and step budget, evaluates each checkpoint on the same episodes, and writes
//! `RESULTS.md` (the table with the best success in bold, seeds, budget, wall-clock times)
//! and learning curves as PNG (plotters) beside it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use crm_api::{Algorithm, EvalReport, EvalSpec, Iteration, PpoConfig, SacConfig, TrainSpec};
use plotters::prelude::*;

use super::{EnvArgs, read_json};
use crate::jobs::eval::evaluate;
use crate::jobs::train::Trainer;

#[derive(clap::Args, Debug)]
pub struct ResultsArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// Environment steps per algorithm.
    #[arg(long)]
    pub steps: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Tasks to train and evaluate on (repeat; default: the whole benchmark).
    #[arg(long)]
    pub task: Vec<String>,
    /// Evaluation episodes per algorithm (the paper: 1,000).
    #[arg(long, default_value_t = 1000)]
    pub episodes: u64,
    /// Environments stepped in parallel per run.
    #[arg(long, default_value_t = 2)]
    pub envs: usize,
    /// Algorithms to compare (repeat; default: all five).
    #[arg(long, value_enum)]
    pub algo: Vec<Algorithm>,
    /// PPO settings for crm-ppo, ippo, lppo and ppo (JSON; default: the paper's).
    #[arg(long, value_name = "FILE")]
    pub ppo_config: Option<PathBuf>,
    /// SAC settings for crm-sac (JSON).
    #[arg(long, value_name = "FILE")]
    pub sac_config: Option<PathBuf>,
    /// Folder for RESULTS.md; the plots go to its `results/` subfolder.
    #[arg(long, default_value = "docs")]
    pub out: PathBuf,
    /// Folder for the trained checkpoints.
    #[arg(long, default_value = "runs/results")]
    pub checkpoints: PathBuf,
}

/// One algorithm's run.
struct Outcome {
    algorithm: Algorithm,
    curve: Vec<Iteration>,
    report: EvalReport,
    train_s: f64,
    eval_s: f64,
}

pub fn run(args: ResultsArgs) -> anyhow::Result<()> {
    if args.steps == 0 || args.episodes == 0 || args.envs == 0 {
        anyhow::bail!("--steps, --episodes and --envs must be positive");
    }
    let ppo: PpoConfig = read_json(&args.ppo_config)?;
    let sac: SacConfig = read_json(&args.sac_config)?;
    ppo.validate()?;
    sac.validate()?;
    let algorithms = if args.algo.is_empty() {
        Algorithm::ALL.to_vec()
    } else {
        args.algo.clone()
    };
    let plots = args.out.join("results");
    for dir in [&plots, &args.checkpoints] {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut outcomes = Vec::new();
    for algorithm in algorithms {
        let spec = TrainSpec {
            algorithm,
            steps: args.steps,
            seed: args.seed,
            task: None,
            tasks: args.task.clone(),
            topology: None,
            envs: Some(args.envs),
            config: ppo.clone(),
            sac: sac.clone(),
            record: None,
            imitation: None,
            objective: args.env.protocol,
            curriculum: false,
        };
        let started = Instant::now();
        let mut trainer = Trainer::new(spec, &args.env, None, None)?;
        let mut curve = Vec::new();
        while !trainer.finished() {
            let it = trainer.iterate()?;
            eprintln!(
                "{}: {}/{} steps, success(last 100) {:.2}",
                algorithm.name(),
                it.steps,
                args.steps,
                it.success_rate_last_100
            );
            curve.push(it);
        }
        let train_s = started.elapsed().as_secs_f64();
        let checkpoint = args
            .checkpoints
            .join(format!("{}.safetensors", algorithm.name()));
        trainer.save(&checkpoint)?;
        let started = Instant::now();
        let eval = EvalSpec {
            episodes: args.episodes,
            seed: args.seed + 1,
            task: None,
            tasks: args.task.clone(),
            topology: None,
            record: None,
            objective: args.env.protocol,
            deterministic: false,
        };
        let report = evaluate(&checkpoint, &eval, &args.env, None, |_, _, _| true)?;
        outcomes.push(Outcome {
            algorithm,
            curve,
            report,
            train_s,
            eval_s: started.elapsed().as_secs_f64(),
        });
    }
    plot(
        &outcomes,
        &plots.join("success.png"),
        "success rate (last 100 episodes)",
        |it| it.success_rate_last_100,
    )?;
    plot(
        &outcomes,
        &plots.join("return.png"),
        "mean episode return",
        |it| it.mean_return,
    )?;
    let markdown = table(&args, &ppo, &sac, &outcomes);
    let path = args.out.join("RESULTS.md");
    std::fs::write(&path, markdown).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

fn table(args: &ResultsArgs, ppo: &PpoConfig, sac: &SacConfig, outcomes: &[Outcome]) -> String {
    let command: Vec<String> = std::env::args().skip(1).collect();
    let tasks = if args.task.is_empty() {
        "all 26 tasks, drawn at random".to_string()
    } else {
        args.task.join(", ")
    };
    let mut text = format!(
        "# Results: Table I at one training budget\n\nMade by `crm {}`.\n\n- budget: {} environment steps per algorithm, {} environments, training seed {}\n- tasks: {tasks}\n- evaluation: {} episodes per algorithm, seed {}, deterministic actions, randomization {}\n- PPO settings: `{}`\n- SAC settings: `{}`\n\n",
        command.join(" "),
        args.steps,
        args.envs,
        args.seed,
        args.episodes,
        args.seed + 1,
        if args.env.no_randomization {
            "off"
        } else {
            "on"
        },
        serde_json::to_string(ppo).unwrap_or_default(),
        serde_json::to_string(sac).unwrap_or_default(),
    );
    let mut rows: BTreeMap<String, Vec<Option<(f64, f64)>>> = BTreeMap::new();
    for (k, outcome) in outcomes.iter().enumerate() {
        let mut add = |name: &str, success: f64, length: f64| {
            rows.entry(name.to_string())
                .or_insert_with(|| vec![None; outcomes.len()])[k] = Some((success, length));
        };
        for (name, row) in &outcome.report.per_objective {
            add(name, row.success_rate, row.mean_episode_length);
        }
        add(
            "~overall",
            outcome.report.success_rate,
            outcome.report.mean_episode_length,
        );
    }
    text.push_str("Success rate and mean episode length (control steps) per objective; the best success per row in bold.\n\n| objective |");
    for outcome in outcomes {
        text.push_str(&format!(" {} |", outcome.algorithm.name()));
    }
    text.push_str("\n| --- |");
    text.push_str(&" --- |".repeat(outcomes.len()));
    text.push('\n');
    for (name, cells) in &rows {
        let best = cells
            .iter()
            .flatten()
            .map(|c| c.0)
            .fold(f64::NEG_INFINITY, f64::max);
        text.push_str(&format!("| {} |", name.trim_start_matches('~')));
        for cell in cells {
            match cell {
                Some((success, length)) if *success == best && best > 0.0 => {
                    text.push_str(&format!(" **{success:.2}** ({length:.0}) |"))
                }
                Some((success, length)) => text.push_str(&format!(" {success:.2} ({length:.0}) |")),
                None => text.push_str(" - |"),
            }
        }
        text.push('\n');
    }
    text.push_str("\n| algorithm | training wall-clock | evaluation wall-clock | steps trained |\n| --- | --- | --- | --- |\n");
    for outcome in outcomes {
        text.push_str(&format!(
            "| {} | {:.0} s | {:.0} s | {} |\n",
            outcome.algorithm.name(),
            outcome.train_s,
            outcome.eval_s,
            outcome.report.trained_steps
        ));
    }
    text.push_str(&format!("\nLearning curves (training episodes):\n\n![success rate](results/success.png)\n\n![return](results/return.png)\n\nThe curves show the iterations in which episodes ended; the checkpoints are in `{}`.\n", args.checkpoints.display()));
    text
}

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

fn plot(
    outcomes: &[Outcome],
    path: &Path,
    title: &str,
    value: impl Fn(&Iteration) -> f64,
) -> anyhow::Result<()> {
    // Registering twice is harmless; plotters keeps the first.
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow::anyhow!("the bundled font is not a font"))?;
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (900, 540)).into_drawing_area();
        root.fill(&WHITE)?;
        let x_max = outcomes
            .iter()
            .flat_map(|o| o.curve.iter().map(|it| it.steps as f64))
            .fold(1.0, f64::max);
        let values: Vec<f64> = outcomes
            .iter()
            .flat_map(|o| o.curve.iter().filter(|it| it.episodes > 0).map(&value))
            .filter(|v| v.is_finite())
            .collect();
        let lo = values
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
            .min(0.0);
        let hi = values
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
            .max(lo + 1e-6);
        let hi = if hi <= 1.0 && lo >= 0.0 { 1.0 } else { hi };
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x_max, lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("environment steps")
            .label_style(("sans-serif", 14))
            .draw()?;
        for (k, outcome) in outcomes.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            chart
                .draw_series(LineSeries::new(
                    outcome
                        .curve
                        .iter()
                        .filter(|it| it.episodes > 0)
                        .map(|it| (it.steps as f64, value(it)))
                        .filter(|p| p.1.is_finite()),
                    color.stroke_width(2),
                ))?
                .label(outcome.algorithm.name())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))
}
