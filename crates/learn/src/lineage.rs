//! How a checkpoint was made: its lineage, one stage per training run that led to it (a run
//! from fresh weights, then any resumes and fine-tunes), oldest first, carried from parent to
//! child in the checkpoint's header so that a model pulled onto a robot says where it came
//! from without its run folder.

use serde::{Deserialize, Serialize};

/// One training run in a checkpoint's making.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LineageStage {
    /// `train` (fresh weights), `resume`, `fine-tune`, or `unrecorded` (a parent written
    /// before checkpoints kept their lineage: what its own header said).
    pub kind: String,
    /// `crm-ppo`, `ippo`, `lppo`, `crm-sac` or `ppo`.
    pub algorithm: String,
    /// Environment steps this stage trained (a resume's total minus its parent's).
    pub steps: u64,
    /// Wall-clock seconds of this stage (0 where unrecorded).
    pub wall_s: f64,
    pub seed: u64,
    /// sha256 of the checkpoint file this stage started from; absent for fresh weights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent_sha256: Option<String>,
    /// The world it trained in and that world's hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_hash: Option<String>,
    /// The world's grasp-location corrections, where it has them (`crm world fit-grasps`):
    /// the command that found them and each corrected task's offset (m, object frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corrections: Option<serde_json::Value>,
    /// Behaviour cloning before the stage's reinforcement learning: the demonstrations'
    /// size and the settings it ran with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imitation: Option<serde_json::Value>,
    /// The command line that ran the stage (`crm train ...`), for runs from the CLI.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<Vec<String>>,
    /// The training job's whole specification (a `TrainSpec` as JSON).
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub job: serde_json::Value,
}

/// The lineage as text, one stage a paragraph (`crm checkpoint show`).
pub fn describe(lineage: &[LineageStage]) -> String {
    let mut out = String::new();
    for (k, stage) in lineage.iter().enumerate() {
        out.push_str(&format!(
            "{}. {} {}: {} steps, {:.1} min, seed {}",
            k + 1,
            stage.kind,
            stage.algorithm,
            stage.steps,
            stage.wall_s / 60.0,
            stage.seed
        ));
        if let Some(world) = &stage.world {
            let hash = stage.world_hash.as_deref().unwrap_or("?");
            out.push_str(&format!(", world {world} ({})", short(hash)));
        }
        out.push('\n');
        if let Some(corrections) = &stage.corrections {
            let command = corrections["command"].as_str().unwrap_or("?");
            out.push_str(&format!(
                "   the world's grasp corrections, found by: {command}\n   offsets: {}\n",
                corrections["offsets"]
            ));
        }
        if let Some(parent) = &stage.parent_sha256 {
            out.push_str(&format!("   from the checkpoint with sha256 {parent}\n"));
        }
        if let Some(imitation) = &stage.imitation {
            out.push_str(&format!("   behaviour cloning first: {imitation}\n"));
        }
        if let Some(command) = &stage.command {
            out.push_str(&format!("   command: {}\n", command.join(" ")));
        }
        if !stage.job.is_null() {
            out.push_str(&format!("   job: {}\n", stage.job));
        }
    }
    out
}

/// The first 12 characters of a hash.
fn short(hash: &str) -> &str {
    hash.get(..12).unwrap_or(hash)
}
