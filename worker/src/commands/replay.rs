//! `crm replay`: one seeded episode of the grasping machine driven by a file of actions, each
//! step printed as a JSON line (the global observation, both reward parts, the stage) with
//! the floats' bits, so another front end of the same world (the Python package) can be
//! checked against it bit for bit.

use std::path::PathBuf;

use anyhow::{Context, bail};
use grasp_sim::GraspEnv;
use grasp_sim::observation::ACTIONS;
use serde_json::json;

use super::{EnvArgs, emit};

/// Which reward parts the learner sees (the Python package's `reward_mode`).
#[derive(Clone, Copy, Debug, Default, clap::ValueEnum)]
pub enum RewardModeArg {
    #[default]
    Crm,
    Dense,
    Sparse,
}

#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// The task (an id of `crm tasks`).
    #[arg(long)]
    pub task: String,
    /// The episode's seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A JSON file with the actions: a list of lists of 8 numbers (union space, [-1, 1]).
    #[arg(long, value_name = "FILE")]
    pub actions: PathBuf,
    #[arg(long, value_enum, default_value_t = RewardModeArg::Crm)]
    pub reward_mode: RewardModeArg,
}

/// An observation's values and their bits.
fn floats(values: &[f32]) -> (Vec<f32>, Vec<u32>) {
    (
        values.to_vec(),
        values.iter().map(|v| v.to_bits()).collect(),
    )
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.actions)
        .with_context(|| format!("reading {}", args.actions.display()))?;
    let actions: Vec<Vec<f32>> = serde_json::from_str(&text).with_context(|| {
        format!(
            "{}: a list of lists of {} numbers is needed",
            args.actions.display(),
            ACTIONS.len()
        )
    })?;
    if let Some(k) = actions.iter().position(|a| a.len() != ACTIONS.len()) {
        bail!(
            "{}: action {k} has {} values, not {}",
            args.actions.display(),
            actions[k].len(),
            ACTIONS.len()
        );
    }
    let benchmark = args.env.env().benchmark()?;
    let task = crm_run::choice::task_index(&benchmark, &args.task)?;
    let machine = args.env.env().machine()?;
    let mut grasp = GraspEnv::new(benchmark, args.env.env().config()?);
    grasp.set_task_choice(grasp_sim::TaskChoice::Fixed(task))?;
    let mode = match args.reward_mode {
        RewardModeArg::Crm => crm::RewardMode::Crm,
        RewardModeArg::Dense => crm::RewardMode::Dense,
        RewardModeArg::Sparse => crm::RewardMode::Sparse,
    };
    let mut env = crm::CrmEnv::new(machine, grasp, mode);
    let (stage, _) = env.reset(args.seed)?;
    let mut out = String::new();
    let (obs, bits) = floats(&env.env().observation_parts().to_vec());
    let line =
        json!({"step": 0, "stage": env.machine().stage_name(stage), "obs": obs, "obs_bits": bits});
    out.push_str(&format!("{line}\n"));
    for (k, action) in actions.iter().enumerate() {
        let step = env.step(action)?;
        let (obs, bits) = floats(&env.env().observation_parts().to_vec());
        let line = json!({
            "step": k + 1,
            "stage": env.machine().stage_name(step.stage),
            "obs": obs,
            "obs_bits": bits,
            "intra_reward": step.intra_reward,
            "intra_bits": step.intra_reward.to_bits(),
            "transition_reward": step.transition_reward,
            "transition_bits": step.transition_reward.to_bits(),
            "terminated": step.done,
            "truncated": step.truncated,
        });
        out.push_str(&format!("{line}\n"));
        if step.done || step.truncated {
            break;
        }
    }
    emit(&out)
}
