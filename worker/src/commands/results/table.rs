//! `RESULTS.md`: Table I from the sweep's aggregation (the coordinator's numbers, as
//! `GET /api/v1/sweeps/{id}` gives them), each algorithm beside the paper's, then the budget,
//! seeds, settings, wall-clock per algorithm and the early stops.

use serde_json::Value;

use super::{ResultsArgs, Study};

/// The paper's Table I: (objective, [(IPPO), (LPPO), (CRM-SAC), (CRM-PPO)]) as
/// (success rate, episode length).
const PAPER: [(&str, [(f64, f64); 4]); 8] = [
    (
        "lift",
        [
            (0.85, 412.63),
            (0.88, 456.33),
            (0.63, 534.68),
            (0.88, 342.43),
        ],
    ),
    (
        "pull",
        [(0.86, 433.60), (0.76, 315.82), (1.0, 276.22), (1.0, 217.34)],
    ),
    (
        "press",
        [
            (0.76, 415.82),
            (0.29, 793.22),
            (0.33, 787.64),
            (0.96, 167.30),
        ],
    ),
    (
        "twist",
        [
            (0.74, 436.20),
            (0.67, 531.34),
            (0.49, 599.17),
            (0.91, 335.52),
        ],
    ),
    (
        "lever",
        [
            (0.70, 466.80),
            (0.90, 367.67),
            (0.95, 307.24),
            (0.93, 246.15),
        ],
    ),
    (
        "wrap_grasp",
        [
            (0.89, 348.88),
            (0.67, 372.49),
            (0.60, 377.41),
            (1.0, 252.17),
        ],
    ),
    (
        "handle_grasp",
        [
            (0.98, 303.70),
            (0.97, 369.71),
            (0.75, 338.43),
            (0.97, 281.09),
        ],
    ),
    (
        "overall",
        [
            (0.84, 390.86),
            (0.71, 461.75),
            (0.61, 479.36),
            (0.95, 273.07),
        ],
    ),
];

/// The paper's numbers for `algorithm` on `objective`.
fn paper(algorithm: &str, objective: &str) -> Option<(f64, f64)> {
    let column = ["ippo", "lppo", "crm-sac", "crm-ppo"]
        .iter()
        .position(|a| *a == algorithm)?;
    PAPER
        .iter()
        .find(|(o, _)| *o == objective)
        .map(|(_, cells)| cells[column])
}

/// A table cell: `success ± std (length ± std)`, as the test reads it back.
pub fn cell(stats: &Value) -> String {
    let (s, l) = (&stats["success"], &stats["length"]);
    match (s["mean"].as_f64(), l["mean"].as_f64()) {
        (Some(sm), Some(lm)) => format!(
            "{sm:.2} ± {:.2} ({lm:.0} ± {:.0})",
            s["std"].as_f64().unwrap_or(0.0),
            l["std"].as_f64().unwrap_or(0.0)
        ),
        _ => "–".to_string(),
    }
}

pub fn markdown(args: &ResultsArgs, study: &Study) -> String {
    let sweep = &study.sweep;
    let id = sweep["sweep"]["id"].as_i64().unwrap_or(0);
    let rows = sweep["table"]["rows"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let mut objectives: Vec<String> = sweep["table"]["objectives"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|o| o.as_str().map(String::from))
        .collect();
    objectives.push("overall".into());
    let tasks = if args.task.is_empty() {
        "all 26 tasks, drawn at random".to_string()
    } else {
        args.task.join(", ")
    };
    let seeds: Vec<String> = (args.seed..args.seed + args.seeds)
        .map(|s| s.to_string())
        .collect();
    let mut text = format!(
        "# Results: Table I, {} algorithms x {} seeds\n\nMade by `crm {}` (sweep {id} on {}).\n\n\
         - budget: {} environment steps per run, {} environments; training seeds {}\n\
         - tasks: {tasks}; randomization on; the paper's grasp protocol (the arm executes the objective once the grasp is ready)\n\
         - evaluation: {} episodes per final checkpoint on evaluation seed {}, sampled actions (as the authors' `evaluate.py`)\n\
         - PPO settings: `{}`\n- SAC settings: `{}`\n\n",
        rows.len(),
        args.seeds,
        study.args_line,
        study.coordinator,
        args.steps,
        args.envs,
        seeds.join(", "),
        args.episodes,
        args.eval_seed,
        serde_json::to_string(&study.ppo).unwrap_or_default(),
        serde_json::to_string(&study.sac).unwrap_or_default(),
    );
    text.push_str(
        "Success rate and mean episode length (control steps), mean ± std over seeds \
         (population std), each algorithm beside the paper's number; the best mean success per \
         objective in bold.\n\n| objective |",
    );
    let algorithms: Vec<String> = rows
        .iter()
        .map(|r| {
            r["config"]["algorithm"]
                .as_str()
                .unwrap_or("all")
                .to_string()
        })
        .collect();
    for algorithm in &algorithms {
        text.push_str(&format!(" {algorithm} | paper |"));
    }
    text.push_str("\n| --- |");
    text.push_str(&" --- | --- |".repeat(rows.len()));
    text.push('\n');
    for objective in &objectives {
        let stats: Vec<Value> = rows
            .iter()
            .map(|r| {
                if objective == "overall" {
                    r["overall"].clone()
                } else {
                    r["per_objective"][objective].clone()
                }
            })
            .collect();
        let best = stats
            .iter()
            .filter_map(|s| s["success"]["mean"].as_f64())
            .fold(f64::NEG_INFINITY, f64::max);
        text.push_str(&format!("| {objective} |"));
        for (stats, algorithm) in stats.iter().zip(&algorithms) {
            let ours = cell(stats);
            let bold = stats["success"]["mean"].as_f64() == Some(best) && best > 0.0;
            let theirs = paper(algorithm, objective)
                .map_or("–".to_string(), |(s, l)| format!("{s:.2} ({l:.0})"));
            if bold {
                text.push_str(&format!(" **{ours}** | {theirs} |"));
            } else {
                text.push_str(&format!(" {ours} | {theirs} |"));
            }
        }
        text.push('\n');
    }
    text.push_str("\n| algorithm | runs evaluated | early stop (runs, at steps) | training wall-clock, mean per run | evaluation wall-clock, mean per run |\n| --- | --- | --- | --- | --- |\n");
    let jobs = sweep["jobs"].as_array().cloned().unwrap_or_default();
    for (row, algorithm) in rows.iter().zip(&algorithms) {
        let seconds = |kind: &str| {
            let times: Vec<f64> = jobs
                .iter()
                .filter(|j| j["kind"] == kind && j["algorithm"] == algorithm.as_str())
                .filter_map(|j| {
                    Some((j["finished_at"].as_f64()? - j["started_at"].as_f64()?) / 1000.0)
                })
                .collect();
            if times.is_empty() {
                "–".to_string()
            } else {
                format!("{:.0} s", times.iter().sum::<f64>() / times.len() as f64)
            }
        };
        let steps: Vec<String> = row["early_stop"]["steps"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|s| s.to_string())
            .collect();
        let stops = if steps.is_empty() {
            "0".to_string()
        } else {
            format!("{} (at {})", steps.len(), steps.join(", "))
        };
        text.push_str(&format!(
            "| {algorithm} | {} of {} | {stops} | {} | {} |\n",
            row["evaluated"],
            row["runs"].as_array().map_or(0, Vec::len),
            seconds("train"),
            seconds("eval"),
        ));
    }
    text.push_str(
        "\nTraining curves (training episodes; mean over seeds, ±1 std band):\n\n\
         ![success rate](results/success.png)\n\n![episode length](results/episode_length.png)\n",
    );
    text
}
