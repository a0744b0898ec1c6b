//! A checkpoint's deterministic policy for a robot: as an ONNX model (`crm_learn::onnx`)
//! with its contract in the model's metadata, and sample observations from real episodes with
//! the actions `crm` takes there, which the same model must reproduce on the robot's runtime.

use std::path::Path;

use crm_learn::Checkpoint;
use crm_learn::onnx::{self, Context as OnnxContext};
use serde::Serialize;

use crate::Env;
use crate::error::{Context, Result};
use crate::eval::{LoadedPolicy, PolicyNet};

/// The deterministic policy of the checkpoint at `path` as ONNX bytes.
pub fn onnx(path: &Path, env: &Env) -> Result<Vec<u8>> {
    let config = env.config_for(crm_api::ObjectiveMode::default(), None)?;
    let policy = LoadedPolicy::load(path, env, &config)?;
    let header = Checkpoint::read_header(path)?;
    let metadata = vec![
        ("crm.algorithm".to_string(), header.algorithm.clone()),
        ("crm.steps".to_string(), header.steps.to_string()),
        (
            "crm.world".to_string(),
            header.world.clone().unwrap_or_else(|| "crm".into()),
        ),
        (
            "crm.world_hash".to_string(),
            header.world_hash.clone().unwrap_or_default(),
        ),
        ("crm.spec_hash".to_string(), header.spec_hash.clone()),
        ("crm.env_version".to_string(), header.env_version.clone()),
        (
            "crm.lineage".to_string(),
            serde_json::to_string(&header.lineage).unwrap_or_default(),
        ),
    ];
    let ctx = OnnxContext {
        machine: &policy.machine,
        folded: &policy.folded,
        metadata,
    };
    Ok(match &policy.net {
        PolicyNet::Ppo(ppo) => onnx::export_ppo(&ppo.net, &ctx)?,
        PolicyNet::Sac(nets) => onnx::export_sac(nets, &ctx)?,
    })
}

/// Observations from real episodes and the deterministic actions `crm` takes at them.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Samples {
    /// Each the stage's abstract state, zero-padded to the network's width.
    pub observation: Vec<Vec<f32>>,
    pub stage: Vec<usize>,
    pub action: Vec<Vec<f32>>,
}

/// At least `count` steps of deterministic episodes of the checkpoint at `path` on the
/// world's tasks, episode `k` seeded by `seed` and `k`.
pub fn samples(path: &Path, env: &Env, count: usize, seed: u64) -> Result<Samples> {
    let config = env.config_for(crm_api::ObjectiveMode::default(), None)?;
    let mut policy = LoadedPolicy::load(path, env, &config)?;
    let benchmark = env.benchmark()?;
    let choice = crate::EnvChoice::of(&benchmark, &None, &[], &None)?;
    let grasp = env.grasp_env(config, &choice)?;
    let machine = policy.machine.clone();
    let width = machine.max_abstract_len();
    let recorded = crate::record::Recorded::new(grasp, machine.clone(), None);
    let mut crm_env = crm::CrmEnv::new(machine, recorded, crm::RewardMode::Crm);
    let mut out = Samples::default();
    let mut episode = 0u64;
    while out.stage.len() < count {
        let (mut stage, mut state) = crm_env
            .reset(seed.wrapping_mul(1_000_003).wrapping_add(episode))
            .context("reset")?;
        episode += 1;
        loop {
            let mask = crm_env.machine().action_mask(stage);
            let action = policy.act(&state, stage, &mask, None)?;
            let mut padded = state.clone();
            padded.resize(width, 0.0);
            out.observation.push(padded);
            out.stage.push(stage);
            out.action.push(action.clone());
            let step = crm_env.step(&action)?;
            if step.done || step.truncated || out.stage.len() >= count {
                break;
            }
            (stage, state) = (step.stage, step.abstract_state);
        }
    }
    Ok(out)
}
