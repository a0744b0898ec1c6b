//! One seeded episode of a task, step by step from the grasp stage on, as JSON lines: the
//! action, the finger commands, the grip, each finger's normal force, the touching parts,
//! whether the ready test passes, the event and whether the arm has taken over. The oracle
//! approaches; in the grasp stage it acts too, or every finger closes at a constant `CLOSE`
//! (the closing-only actions a policy sends; a value outside 0..=1 leaves the oracle acting).
//! The last line says how the episode ended.
//!
//! This is how a world's hand-over is checked: whether a topology's grasp can pass the ready
//! test before the grip crushes the object (docs/WORLDS.md, "The ready test of a topology that
//! moves only the thumb").
//!
//! ```sh
//! cargo run --release -p grasp-sim --example trace-grasp -- WORLD_DIR TASK_ID [CLOSE] [SEED]
//! ```

use std::path::Path;

use anyhow::{Context, bail};
use grasp_sim::oracle::Oracle;
use grasp_sim::ready::touch;
use grasp_sim::{GraspEnv, SimConfig, TaskChoice, World};
use serde_json::json;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (dir, id) = match args.as_slice() {
        [dir, id, ..] if args.len() <= 4 => (dir, id),
        _ => bail!("usage: trace-grasp WORLD_DIR TASK_ID [CLOSE in 0..=1, else the oracle] [SEED]"),
    };
    let close: Option<f32> = match args.get(2) {
        Some(text) => {
            let value: f32 = text.parse().with_context(|| format!("CLOSE {text:?}"))?;
            (0.0..=1.0).contains(&value).then_some(value)
        }
        None => None,
    };
    let seed: u64 = match args.get(3) {
        Some(text) => text.parse().with_context(|| format!("SEED {text:?}"))?,
        None => 0,
    };
    let world = World::load(Path::new(dir)).with_context(|| format!("loading {dir}"))?;
    let benchmark = world.benchmark.clone();
    let task = benchmark
        .task_index(id)
        .with_context(|| format!("no task {id:?} in {dir}"))?;
    let machine = world.machine()?;
    let mut env = GraspEnv::new(benchmark, SimConfig::default());
    env.set_task_choice(TaskChoice::Fixed(task))?;
    let mut crm_env = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
    let (mut stage, _) = crm_env.reset(seed)?;
    let mut oracle = Oracle::new();
    loop {
        let name = crm_env.machine().stage_name(stage).to_string();
        let mut action = oracle.act(crm_env.env(), &name);
        if let (Some(close), "grasp") = (close, name.as_str()) {
            action.iter_mut().for_each(|a| *a = 0.0);
            action[3..].iter_mut().for_each(|a| *a = close);
        }
        let step = crm_env.step(&action)?;
        let env = crm_env.env();
        if name != "approach" {
            let scene = env.scene().context("no scene")?;
            let touched = touch(
                env.hand_contacts(),
                &scene.hand,
                env.config().ready_finger_force,
            );
            println!(
                "{}",
                json!({
                    "step": env.steps(),
                    "stage": name,
                    "action": action,
                    "commands": env.observation_parts().commands,
                    "grip": touched.grip,
                    "fingers": touched.fingers,
                    "parts": touched.parts,
                    "ready": env.ready_test().is_ready(&touched),
                    "event": step.event,
                    "executed": env.executed(),
                })
            );
        }
        stage = step.stage;
        if step.done || step.truncated {
            let end = crm_env.machine().stage_name(stage).to_string();
            println!(
                "{}",
                json!({ "end": crm_env.env().outcome_label(if step.truncated { "truncated" } else { &end }) })
            );
            return Ok(());
        }
    }
}
