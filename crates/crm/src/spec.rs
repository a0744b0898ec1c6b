//! The serialized form of a machine: what a spec file holds.
//!
//! Field names follow the paper: stages carry an action set `A_i` (`actions`), a state
//! abstraction `phi_i` (`abstraction`, a list of feature names of the global observation)
//! and a stage reward `r^(i)` (`reward`, a sum of terms); edges carry the transition reward
//! `R_T` (`reward`) and optional bonuses such as the friction-cone reward `R_cone` of the
//! success stage (paper, section IV-D-3).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::reward::RewardTerm;

/// A whole machine as written in a spec file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// A name for logs and checkpoints.
    pub name: String,
    /// Names of the global observation's features, in order (the layout of `u`).
    pub features: Vec<String>,
    /// Names of the union action space's dimensions, in order (the layout of `A`).
    pub action_dims: Vec<String>,
    /// The event alphabet `Sigma`, in priority order: when several events fire in one step,
    /// the first one with an edge out of the current stage is taken.
    pub events: Vec<String>,
    /// The stages `T`.
    pub stages: Vec<StageSpec>,
    /// The initial stage `u0` entered at reset, without a reward (paper, section IV-A).
    pub initial: String,
    /// The transition function `delta` and the transition rewards `R_T`.
    pub transitions: Vec<EdgeSpec>,
}

/// One stage `T_i = (A_i, r^(i), phi_i)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageSpec {
    pub name: String,
    /// A terminal stage ends the episode and has no actions or edges out of it.
    #[serde(default)]
    pub terminal: bool,
    /// The action set `A_i`: live dimensions of the union action space and their step scales.
    #[serde(default)]
    pub actions: Vec<ActionSpec>,
    /// The abstraction `phi_i`: the features of the global observation this stage sees.
    #[serde(default)]
    pub abstraction: Vec<String>,
    /// The intra-stage reward `r^(i)`: the sum of these terms on the next observation.
    #[serde(default)]
    pub reward: Vec<RewardTerm>,
}

/// A live action dimension of a stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionSpec {
    /// A name from [`Spec::action_dims`].
    pub dim: String,
    /// Multiplies the policy's output in `[-1, 1]` before it reaches the environment.
    pub scale: f32,
}

/// One edge of `delta`: `(from, event) -> to` with reward `R_T^{from->to}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EdgeSpec {
    pub from: String,
    pub event: String,
    pub to: String,
    pub reward: f32,
    /// Extra rewards added on this edge when a feature of the next observation is set.
    #[serde(default)]
    pub bonus: Vec<BonusSpec>,
}

/// `reward` is added when `feature > 0.5` in the observation that fired the edge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BonusSpec {
    pub feature: String,
    pub reward: f32,
}

impl Spec {
    /// Parses a spec from JSON text; `origin` names the source in errors.
    pub fn from_json(text: &str, origin: &str) -> Result<Self> {
        serde_json::from_str(text).map_err(|err| Error::Parse {
            path: origin.to_string(),
            line: err.line(),
            column: err.column(),
            message: err.to_string(),
        })
    }

    /// Reads and parses a spec file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|error| Error::Io {
            path: path.to_path_buf(),
            error,
        })?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// The canonical JSON text (for hashing into checkpoints).
    pub fn to_canonical_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }

    /// A short content hash (hex sha256 of the canonical JSON) identifying this machine.
    pub fn hash(&self) -> String {
        use sha2::Digest;
        let digest = sha2::Sha256::digest(self.to_canonical_json().as_bytes());
        digest.iter().take(8).map(|b| format!("{b:02x}")).collect()
    }
}
