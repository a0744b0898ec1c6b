//! Whether a task's grasp holds once the palm moves off the arrival point: the oracle
//! approaches; in the grasp stage the palm moves by `DX DY DZ` (m, world frame; 3 mm per
//! control step, the fingers still) and then every finger closes at a constant `CLOSE` (the
//! closing-only actions a policy sends) until the episode ends. One line: the successes over
//! seeds `0..SEEDS` and each episode's outcome. `PRESHAPE_SPEED` (rad/s) overrides the
//! default [`SimConfig::preshape_speed`] (0: the preshape at once).
//!
//! This is how the handle bottle of the paper's task 7 was found to be graspable once the
//! palm moves 4-8 cm along world x after arriving (docs/WORLDS.md, "The handle bottle of
//! `t07`"):
//!
//! ```sh
//! cargo run --release -p grasp-sim --example palm-offset -- \
//!     ~/worlds/dexmobile t07-handle_bottle-handle_grasp 0.07 -0.04 0 0.3 6
//! ```

use std::path::Path;

use anyhow::{Context, bail};
use grasp_sim::env::script::GRASP_SCALE;
use grasp_sim::oracle::Oracle;
use grasp_sim::{GraspEnv, SimConfig, TaskChoice, World};

fn number(text: &str, name: &str) -> anyhow::Result<f32> {
    text.parse()
        .with_context(|| format!("{name} {text:?} is not a number"))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (dir, id, dx, dy, dz, close, seeds, speed) = match args.as_slice() {
        [dir, id, dx, dy, dz, close, seeds] => (dir, id, dx, dy, dz, close, seeds, None),
        [dir, id, dx, dy, dz, close, seeds, speed] => {
            (dir, id, dx, dy, dz, close, seeds, Some(speed))
        }
        _ => bail!("usage: palm-offset WORLD_DIR TASK_ID DX DY DZ CLOSE SEEDS [PRESHAPE_SPEED]"),
    };
    let mut config = SimConfig::default();
    if let Some(speed) = speed {
        config.preshape_speed = number(speed, "PRESHAPE_SPEED")?;
        if config.preshape_speed.is_nan() || config.preshape_speed < 0.0 {
            bail!("PRESHAPE_SPEED {speed} is not a speed");
        }
    }
    let offset = [number(dx, "DX")?, number(dy, "DY")?, number(dz, "DZ")?];
    let close = number(close, "CLOSE")?;
    if !(0.0..=1.0).contains(&close) {
        bail!("CLOSE {close} is outside 0..=1");
    }
    let seeds: u64 = seeds
        .parse()
        .with_context(|| format!("SEEDS {seeds:?} is not a count"))?;
    let world = World::load(Path::new(dir)).with_context(|| format!("loading {dir}"))?;
    let benchmark = world.benchmark.clone();
    let task = benchmark
        .task_index(id)
        .with_context(|| format!("no task {id:?} in {dir}"))?;
    let mut outcomes = Vec::new();
    for seed in 0..seeds {
        let mut env = GraspEnv::new(benchmark.clone(), config.clone());
        env.set_task_choice(TaskChoice::Fixed(task))?;
        let mut crm_env = crm::CrmEnv::new(world.machine()?, env, crm::RewardMode::Crm);
        let (mut stage, _) = crm_env.reset(seed)?;
        let mut oracle = Oracle::new();
        let mut moved = [0.0f32; 3];
        loop {
            let name = crm_env.machine().stage_name(stage).to_string();
            let mut action = oracle.act(crm_env.env(), &name);
            if name == "grasp" {
                action.iter_mut().for_each(|a| *a = 0.0);
                let mut moving = false;
                for axis in 0..3 {
                    let left = offset[axis] - moved[axis];
                    if left.abs() > 1e-4 {
                        let step = left.clamp(-GRASP_SCALE, GRASP_SCALE);
                        action[axis] = step / GRASP_SCALE;
                        moved[axis] += step;
                        moving = true;
                    }
                }
                if !moving {
                    action[3..].iter_mut().for_each(|a| *a = close);
                }
            }
            let step = crm_env.step(&action)?;
            stage = step.stage;
            if step.done || step.truncated {
                let end = crm_env.machine().stage_name(stage).to_string();
                let label = if step.truncated { "truncated" } else { &end };
                outcomes.push(crm_env.env().outcome_label(label).to_string());
                break;
            }
        }
    }
    let successes = outcomes.iter().filter(|o| o.as_str() == "success").count();
    println!(
        "{} {} {} close {close}: {successes}/{seeds} {outcomes:?}",
        offset[0], offset[1], offset[2]
    );
    Ok(())
}
