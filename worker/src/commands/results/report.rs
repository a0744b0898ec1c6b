//! `RESULTS.md`, written entirely from the studies on disk ([`super::record`]): per study,
//! the command, budget and settings; Table I as the paper prints it (mean ± std over seeds
//! beside the paper's numbers); the interval estimates of [`super::stats`]; every run's early
//! stop or budget and wall-clock; the last fifth of the curves; and a reading derived from
//! those numbers (ordering, overlapping intervals, early stops), never typed by hand.

use std::fmt::Write as _;

use super::paper::paper;
use super::record::{Run, Study};
use super::stats::{self, Estimate, Scores};

/// Mean and population standard deviation.
fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// The tasks every finished run of the study evaluated, by id.
pub fn common_tasks(study: &Study) -> Vec<String> {
    let mut tasks: Option<Vec<String>> = None;
    for run in &study.runs {
        for report in [&run.eval, &run.deterministic] {
            let ids: Vec<String> = report.per_task.keys().cloned().collect();
            tasks = Some(match tasks {
                None => ids,
                Some(t) => t.into_iter().filter(|id| ids.contains(id)).collect(),
            });
        }
    }
    tasks.unwrap_or_default()
}

/// The runs x tasks matrix of success rates of `runs` (sampled or deterministic).
pub fn scores(runs: &[&Run], tasks: &[String], deterministic: bool) -> Option<Scores> {
    let rows: Vec<Vec<f64>> = runs
        .iter()
        .map(|run| {
            let report = if deterministic {
                &run.deterministic
            } else {
                &run.eval
            };
            tasks
                .iter()
                .map(|t| report.per_task.get(t).map_or(f64::NAN, |r| r.success_rate))
                .collect()
        })
        .collect();
    Scores::new(&rows)
}

fn interval(e: &Estimate) -> String {
    format!("{:.3} [{:.3}, {:.3}]", e.point, e.low, e.high)
}

/// The algorithms of the study with at least one finished run, in the study's order.
fn present(study: &Study) -> Vec<&str> {
    study
        .file
        .algorithms
        .iter()
        .map(String::as_str)
        .filter(|a| study.runs_of(a).next().is_some())
        .collect()
}

/// `RESULTS.md`: a short head, then one section per study.
pub fn markdown(studies: &[(Study, String)], reps: usize) -> String {
    let mut text = String::from(
        "# Results: Table I\n\n\
         Written by `crm results` from the studies under `docs/results/` (`crm results \
         --report-only` rebuilds this file and every plot from them without training). Each \
         section gives the command that runs, continues or extends its study. Success is the \
         share of evaluation episodes the judge passes (the paper's protocol; 5 s steady hold); \
         the paper's numbers are its Table I.\n",
    );
    for (study, link) in studies {
        section(&mut text, study, link, reps);
    }
    text
}

fn section(text: &mut String, study: &Study, link: &str, reps: usize) {
    let f = &study.file;
    let algorithms = present(study);
    let total = f.algorithms.len() * f.seeds.len();
    let tasks = if f.tasks.is_empty() {
        format!(
            "the world's whole benchmark ({} tasks), drawn at random",
            f.task_objectives.len()
        )
    } else {
        f.tasks.join(", ")
    };
    // The settings of the learners the study has: PPO's for the PPO family, SAC's for CRM-SAC.
    let (ppo, sac): (Vec<&str>, Vec<&str>) = f
        .algorithms
        .iter()
        .map(String::as_str)
        .partition(|a| super::record::settings_field(a) == "ppo");
    let mut settings = String::new();
    if !ppo.is_empty() {
        let _ = writeln!(
            settings,
            "- PPO settings ({}): `{}`",
            ppo.join(", "),
            serde_json::to_string(&f.ppo).unwrap_or_default()
        );
    }
    if !sac.is_empty() {
        let _ = writeln!(
            settings,
            "- SAC settings ({}): `{}`",
            sac.join(", "),
            serde_json::to_string(&f.sac).unwrap_or_default()
        );
    }
    let _ = write!(
        text,
        "\n## {} (world `{}`)\n\n```\ncrm {}\n```\n\n\
         - runs finished: {} of {total} ({} algorithms x seeds {})\n\
         - budget: {} environment steps per run, or the early stop at {:.0}% success over the last {} training episodes (the paper's rule); {} environments{}\n\
         - tasks: {tasks}; randomization on; the paper's grasp protocol\n\
         - evaluation: {} episodes per final checkpoint on evaluation seed {}, sampled actions (the authors' `evaluate.py`) and the deterministic action\n\
         {settings}",
        f.name,
        f.world,
        f.command,
        study.runs.len(),
        f.algorithms.len(),
        f.seeds
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(", "),
        f.steps,
        f.ppo.early_stop_success * 100.0,
        f.ppo.early_stop_window,
        f.envs,
        f.settle_s.map_or(String::new(), |s| format!(
            "; training's hold shortcut {s} s"
        )),
        f.episodes,
        f.eval_seed,
    );
    if let Some(note) = &f.budget_note {
        let _ = writeln!(text, "- why this budget: {note}");
    }
    if algorithms.is_empty() {
        text.push_str("\nNo run has finished yet.\n");
        return;
    }
    table_one(text, study, &algorithms);
    let tasks = common_tasks(study);
    let matrices: Vec<(&str, Scores, Scores)> = algorithms
        .iter()
        .filter_map(|a| {
            let runs: Vec<&Run> = study.runs_of(a).collect();
            Some((
                *a,
                scores(&runs, &tasks, false)?,
                scores(&runs, &tasks, true)?,
            ))
        })
        .collect();
    let estimates = intervals(text, study, &matrices, &tasks, reps);
    improvement(text, &matrices, reps);
    runs_table(text, study, &algorithms);
    curves(text, study, &algorithms, link);
    super::reading::reading(text, study, &algorithms, &estimates);
}

/// One cell of Table I: (success mean, std), (length mean, std) over seeds.
type Cell = ((f64, f64), (f64, f64));

/// Table I as the paper prints it: mean ± std over seeds per objective, beside the paper.
fn table_one(text: &mut String, study: &Study, algorithms: &[&str]) {
    let mut objectives = study.file.objectives();
    objectives.push("overall".into());
    text.push_str(
        "\n### Table I\n\nSuccess rate and mean episode length (control steps) of the sampled \
         evaluation, mean ± std over seeds (population std, as the paper), beside the paper's; \
         the best mean success per objective in bold.\n\n| objective |",
    );
    for a in algorithms {
        let _ = write!(text, " {a} | paper |");
    }
    text.push_str("\n| --- |");
    text.push_str(&" --- | --- |".repeat(algorithms.len()));
    text.push('\n');
    for objective in &objectives {
        let cells: Vec<Option<Cell>> = algorithms
            .iter()
            .map(|a| {
                let rows: Vec<(f64, f64)> = study
                    .runs_of(a)
                    .filter_map(|r| {
                        if objective == "overall" {
                            Some((r.eval.success_rate, r.eval.mean_episode_length))
                        } else {
                            r.eval
                                .per_objective
                                .get(objective)
                                .map(|row| (row.success_rate, row.mean_episode_length))
                        }
                    })
                    .collect();
                (!rows.is_empty()).then(|| {
                    let s: Vec<f64> = rows.iter().map(|r| r.0).collect();
                    let l: Vec<f64> = rows.iter().map(|r| r.1).collect();
                    (mean_std(&s), mean_std(&l))
                })
            })
            .collect();
        let best = cells
            .iter()
            .flatten()
            .map(|c| c.0.0)
            .fold(f64::NEG_INFINITY, f64::max);
        let _ = write!(text, "| {objective} |");
        for (cell, a) in cells.iter().zip(algorithms) {
            let ours = match cell {
                Some(((sm, ss), (lm, ls))) => {
                    let body = format!("{sm:.2} ± {ss:.2} ({lm:.0} ± {ls:.0})");
                    if *sm == best && best > 0.0 {
                        format!("**{body}**")
                    } else {
                        body
                    }
                }
                None => "–".into(),
            };
            let theirs =
                paper(a, objective).map_or("–".to_string(), |(s, l)| format!("{s:.2} ({l:.0})"));
            let _ = write!(text, " {ours} | {theirs} |");
        }
        text.push('\n');
    }
}

/// The aggregates with their intervals, overall (sampled and deterministic) and the IQM per
/// objective; returns the sampled overall IQM per algorithm.
fn intervals(
    text: &mut String,
    study: &Study,
    matrices: &[(&str, Scores, Scores)],
    tasks: &[String],
    reps: usize,
) -> Vec<(String, Estimate)> {
    let _ = write!(
        text,
        "\n### Interval estimates\n\nOver runs x tasks ({} tasks, each run's success rate per \
         task): point estimate [95% stratified-bootstrap interval], {reps} bootstrap samples, as \
         `rliable` computes them (Agarwal et al. 2021). The optimality gap is the mean shortfall \
         from a success rate of 1 (lower is better).\n\n\
         | algorithm | actions | runs | IQM | mean | median | optimality gap |\n\
         | --- | --- | --- | --- | --- | --- | --- |\n",
        tasks.len()
    );
    let mut iqms = Vec::new();
    for (a, sampled, deterministic) in matrices {
        for (label, m) in [("sampled", sampled), ("deterministic", deterministic)] {
            let e = stats::aggregates(m, reps, 0);
            if label == "sampled" {
                iqms.push((a.to_string(), e[0].1));
            }
            let _ = writeln!(
                text,
                "| {a} | {label} | {} | {} | {} | {} | {} |",
                m.runs,
                interval(&e[0].1),
                interval(&e[1].1),
                interval(&e[2].1),
                interval(&e[3].1)
            );
        }
    }
    let objectives = study.file.objectives();
    text.push_str("\nIQM of the sampled evaluation per objective, over runs x that objective's tasks:\n\n| objective |");
    for (a, _, _) in matrices {
        let _ = write!(text, " {a} |");
    }
    text.push_str("\n| --- |");
    text.push_str(&" --- |".repeat(matrices.len()));
    text.push('\n');
    for objective in &objectives {
        let columns: Vec<usize> = tasks
            .iter()
            .enumerate()
            .filter(|(_, t)| study.file.task_objectives.get(*t) == Some(objective))
            .map(|(k, _)| k)
            .collect();
        if columns.is_empty() {
            continue;
        }
        let _ = write!(text, "| {objective} |");
        for (_, m, _) in matrices {
            let rows: Vec<Vec<f64>> = (0..m.runs)
                .map(|r| columns.iter().map(|&c| m.data[r * m.tasks + c]).collect())
                .collect();
            let cell = Scores::new(&rows)
                .map(|s| interval(&stats::aggregates(&s, reps, 0)[0].1))
                .unwrap_or_else(|| "–".into());
            let _ = write!(text, " {cell} |");
        }
        text.push('\n');
    }
    iqms
}

/// The probability that CRM-PPO improves on each other algorithm.
fn improvement(text: &mut String, matrices: &[(&str, Scores, Scores)], reps: usize) {
    let Some((_, reference, _)) = matrices.iter().find(|(a, _, _)| *a == "crm-ppo") else {
        return;
    };
    if matrices.len() < 2 {
        return;
    }
    text.push_str(
        "\nProbability of improvement of CRM-PPO over each algorithm, `P(CRM-PPO > X)` per task \
         averaged over tasks (sampled evaluation; 0.5 is a tie) [95% interval]:\n\n\
         | X | P(CRM-PPO > X) |\n| --- | --- |\n",
    );
    for (a, m, _) in matrices.iter().filter(|(a, _, _)| *a != "crm-ppo") {
        let e = stats::improvement(reference, m, reps, 0);
        let _ = writeln!(text, "| {a} | {} |", interval(&e));
    }
}

fn minutes(seconds: f64) -> String {
    if seconds.is_finite() {
        format!("{:.1} min", seconds / 60.0)
    } else {
        "–".into()
    }
}

/// Every run: its steps (early stop or budget), leases, wall-clock and overall success.
fn runs_table(text: &mut String, study: &Study, algorithms: &[&str]) {
    text.push_str(
        "\n### Runs\n\nTraining is the time workers trained each run (its leases' wall-clock summed from the curve: a run given back and resumed waited between leases, which is left out, and redid the steps after its last checkpoint, which are in).\n\n\
         | algorithm | seed | steps | ended by | leases | training | evaluations | success, sampled | success, deterministic |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for a in algorithms {
        for run in study.runs_of(a) {
            let r = &run.file;
            let _ = writeln!(
                text,
                "| {a} | {} | {} | {} | {} | {} | {} | {:.3} | {:.3} |",
                r.seed,
                r.steps,
                if r.stopped_early {
                    "early stop"
                } else {
                    "budget"
                },
                r.leases,
                minutes(run.training_s()),
                minutes(r.eval_wall_s + r.eval_deterministic_wall_s),
                run.eval.success_rate,
                run.deterministic.success_rate,
            );
        }
    }
    text.push_str("\n| algorithm | runs | early stops | training wall-clock, mean per run | steps per second, mean |\n| --- | --- | --- | --- | --- |\n");
    for a in algorithms {
        let runs: Vec<&Run> = study.runs_of(a).collect();
        let stops = runs.iter().filter(|r| r.file.stopped_early).count();
        let wall: Vec<f64> = runs.iter().map(|r| r.training_s()).collect();
        let rate: Vec<f64> = runs
            .iter()
            .map(|r| r.file.steps as f64 / r.training_s())
            .collect();
        let _ = writeln!(
            text,
            "| {a} | {} | {stops} | {} | {:.0} |",
            runs.len(),
            minutes(mean_std(&wall).0),
            mean_std(&rate).0
        );
    }
}

/// A run's training success at the start and end of the last fifth of its steps.
pub fn last_fifth(run: &Run) -> Option<(f64, f64)> {
    let end = run.curve.last()?;
    let from = end.steps as f64 * 0.8;
    let start = run.curve.iter().find(|p| p.steps as f64 >= from)?;
    Some((start.success_rate_last_100, end.success_rate_last_100))
}

/// The plots and the last fifth of every curve.
fn curves(text: &mut String, study: &Study, algorithms: &[&str], link: &str) {
    let _ = write!(
        text,
        "\n### Curves\n\nTraining success over the last 100 episodes at 80% of each run's steps \
         and at its end (the last fifth of the curve; mean over seeds, and the largest change \
         of one seed):\n\n| algorithm | at 80% | at the end | largest change |\n| --- | --- | --- | --- |\n"
    );
    for a in algorithms {
        let fifths: Vec<(f64, f64)> = study.runs_of(a).filter_map(last_fifth).collect();
        if fifths.is_empty() {
            continue;
        }
        let at80: Vec<f64> = fifths.iter().map(|f| f.0).collect();
        let end: Vec<f64> = fifths.iter().map(|f| f.1).collect();
        let largest = fifths
            .iter()
            .map(|f| f.1 - f.0)
            .fold(0.0f64, |m, d| if d.abs() > m.abs() { d } else { m });
        let _ = writeln!(
            text,
            "| {a} | {:.2} | {:.2} | {largest:+.2} |",
            mean_std(&at80).0,
            mean_std(&end).0
        );
    }
    let _ = write!(
        text,
        "\n![training success]({link}/success.png)\n\n![episode length]({link}/episode_length.png)\n\n\
         ![performance profile]({link}/profile.png)\n"
    );
}
