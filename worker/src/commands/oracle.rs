//! `crm oracle`: the scripted controller over every task and several seeds.

use std::collections::BTreeMap;

use crm_api::jobs::failure_summary;
use grasp_sim::benchmark::Objective;
use grasp_sim::oracle::{Oracle, OracleEpisode, run_shifted_episode};
use grasp_sim::{GraspEnv, TaskChoice};
use rayon::prelude::*;
use serde::Serialize;

use std::fmt::Write;

use super::{EnvArgs, emit};

#[derive(clap::Args, Debug)]
pub struct OracleArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// Seeds per task (episodes = tasks x seeds).
    #[arg(long, default_value_t = 10)]
    pub seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Only these tasks (ids; repeat the flag).
    #[arg(long = "task")]
    pub tasks: Vec<String>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Print a per-step trace of the first episode of each task to stderr.
    #[arg(long)]
    pub trace: bool,
    /// Move the palm by DX,DY,DZ (m, world frame) from TASK's grasp location before closing
    /// (repeat the flag): a grasp that holds only off the arrival point (`palm-offset`).
    #[arg(long = "shift", value_name = "TASK=DX,DY,DZ", value_parser = crm_api::parse_shift)]
    pub shifts: Vec<(String, [f64; 3])>,
}

#[derive(Serialize)]
struct Group {
    success_rate: f64,
    episodes: usize,
    /// How the group's episodes ended (`success`, `failure (dropped)`, ...), as in the
    /// report's `outcomes`.
    outcomes: BTreeMap<String, usize>,
}

#[derive(Serialize)]
struct Report {
    tasks: usize,
    episodes: usize,
    success_rate: f64,
    per_objective: BTreeMap<String, Group>,
    per_task: BTreeMap<String, Group>,
    outcomes: BTreeMap<String, usize>,
    /// Control steps of the controller (the arm's scripted execution runs inside one).
    mean_episode_steps: f64,
    /// Simulated seconds, the scripted execution included.
    mean_episode_seconds: f64,
    /// `scripted` (the paper's protocol) or `learned`.
    objective: &'static str,
    randomization: bool,
}

fn group(episodes: &[&OracleEpisode]) -> Group {
    let wins = episodes.iter().filter(|e| e.success).count();
    let mut outcomes = BTreeMap::new();
    for e in episodes {
        *outcomes.entry(e.label.clone()).or_insert(0) += 1;
    }
    Group {
        success_rate: if episodes.is_empty() {
            0.0
        } else {
            wins as f64 / episodes.len() as f64
        },
        episodes: episodes.len(),
        outcomes,
    }
}

pub fn run(args: OracleArgs) -> anyhow::Result<()> {
    let benchmark = args.env.env().benchmark()?;
    let machine = args.env.env().machine()?;
    let config = args.env.env().config()?;
    let selected: Vec<usize> = if args.tasks.is_empty() {
        (0..benchmark.tasks.len()).collect()
    } else {
        args.tasks
            .iter()
            .map(|id| crm_run::choice::task_index(&benchmark, id))
            .collect::<crm_run::Result<_>>()?
    };
    let shifts = crm_run::demos::shifts_by_task(&benchmark, &args.shifts.iter().cloned().collect())
        .map_err(|e| anyhow::anyhow!("--shift: {e:#}"))?;
    if args.trace {
        for &task in &selected {
            trace(
                GraspEnv::new(benchmark.clone(), config.clone()),
                machine.clone(),
                task,
                args.seed,
                shifts[task],
            )?;
        }
    }
    let jobs: Vec<(usize, u64)> = selected
        .iter()
        .flat_map(|&task| (0..args.seeds).map(move |k| (task, args.seed + k)))
        .collect();
    let episodes = jobs
        .par_iter()
        .map(|&(task, seed)| {
            let env = GraspEnv::new(benchmark.clone(), config.clone());
            run_shifted_episode(env, machine.clone(), task, seed, shifts[task])
                .map(|(episode, _)| episode)
        })
        .collect::<Result<Vec<_>, _>>()?;

    let all: Vec<&OracleEpisode> = episodes.iter().collect();
    let mut per_objective = BTreeMap::new();
    for objective in Objective::ALL {
        let of: Vec<_> = all
            .iter()
            .copied()
            .filter(|e| benchmark.tasks[e.task].objective == objective)
            .collect();
        if !of.is_empty() {
            per_objective.insert(objective.name().to_string(), group(&of));
        }
    }
    let mut per_task = BTreeMap::new();
    for &task in &selected {
        let of: Vec<_> = all.iter().copied().filter(|e| e.task == task).collect();
        per_task.insert(benchmark.tasks[task].id.clone(), group(&of));
    }
    let overall = group(&all);
    let mean_steps =
        episodes.iter().map(|e| e.steps as f64).sum::<f64>() / episodes.len().max(1) as f64;
    let report = Report {
        tasks: selected.len(),
        episodes: episodes.len(),
        success_rate: overall.success_rate,
        per_objective,
        per_task,
        outcomes: overall.outcomes,
        mean_episode_steps: mean_steps,
        objective: args.env.protocol.name(),
        mean_episode_seconds: episodes
            .iter()
            .map(|e| f64::from(e.sim_seconds))
            .sum::<f64>()
            / episodes.len().max(1) as f64,
        randomization: config.randomization.enabled,
    };
    if args.json {
        return emit(&format!("{}\n", serde_json::to_string(&report)?));
    }
    let mut text = String::new();
    {
        writeln!(
            text,
            "oracle: {} tasks, {} episodes, success rate {:.3}, mean episode {:.1} steps ({:.2} s)",
            report.tasks,
            report.episodes,
            report.success_rate,
            report.mean_episode_steps,
            report.mean_episode_seconds
        )?;
        for (name, g) in &report.per_objective {
            writeln!(
                text,
                "  {name:<13} {:.3} over {}  failures: {}",
                g.success_rate,
                g.episodes,
                failure_summary(&g.outcomes)
            )?;
        }
        for (name, g) in &report.per_task {
            writeln!(
                text,
                "  task {name:<16} {:.3} over {}  failures: {}",
                g.success_rate,
                g.episodes,
                failure_summary(&g.outcomes)
            )?;
        }
        writeln!(text, "  outcomes: {:?}", report.outcomes)?;
    }
    emit(&text)
}

/// A per-step trace of one episode, for tuning tasks.
fn trace(
    env: GraspEnv,
    machine: crm::Machine,
    task: usize,
    seed: u64,
    shift: [f32; 3],
) -> anyhow::Result<()> {
    let mut env = env;
    env.set_task_choice(TaskChoice::Fixed(task))?;
    let mut crm_env = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
    let (mut stage, _) = crm_env.reset(seed)?;
    let mut oracle = Oracle::with_shift(shift);
    eprintln!("# task {}", crm_env.env().task().id);
    loop {
        let name = crm_env.machine().stage_name(stage).to_string();
        let action = oracle.act(crm_env.env(), &name);
        let step = crm_env.step(&action)?;
        let p = crm_env.env().observation_parts();
        eprintln!(
            "{:>4} {:<8} rel=({:+.3},{:+.3},{:+.3}) obj=({:+.3},{:+.3},{:+.3}) n_c={:>2} grip={:.2} F=({:+.1},{:+.1},{:+.1}) cmd={:?} cone={} prog={:.2} r=({:+.2},{:+.1}) ev={:?}",
            crm_env.env().steps(),
            name,
            p.relative[0],
            p.relative[1],
            p.relative[2],
            p.object[0],
            p.object[1],
            p.object[2],
            p.n_c,
            p.grip,
            p.force[0],
            p.force[1],
            p.force[2],
            p.commands
                .iter()
                .map(|c| (c * 100.0).round() / 100.0)
                .collect::<Vec<_>>(),
            u8::from(p.cone),
            p.progress,
            step.intra_reward,
            step.transition_reward,
            step.event
        );
        if let Some(scene) = crm_env.env().scene() {
            let palm = scene.hand.palm_pose(&scene.world);
            for point in &crm_env.env().hand_contacts().points {
                let link = point
                    .other_body
                    .and_then(|body| scene.hand.link_of(body))
                    .map_or_else(|| "palm".into(), |(f, k)| format!("f{f}l{k}"));
                let local = palm.inverse_transform_point(point.position);
                eprintln!(
                    "       {link} at hand ({:+.3},{:+.3},{:+.3}) Fn={:.1} Ft={:.1} F=({:+.1},{:+.1},{:+.1})",
                    local.x,
                    local.y,
                    local.z,
                    point.normal_force,
                    point.friction_force,
                    point.force.x,
                    point.force.y,
                    point.force.z
                );
            }
        }
        stage = step.stage;
        if step.done || step.truncated {
            eprintln!(
                "# end: {} (fail cause {:?})",
                crm_env.machine().stage_name(stage),
                crm_env.env().last_fail()
            );
            return Ok(());
        }
    }
}
