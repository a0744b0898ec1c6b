//! The learners a job can run, by the names the API, checkpoints and the command line use.

use serde::{Deserialize, Serialize};

/// The learners by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Algorithm {
    /// PPO with intra-stage and transition rewards (the paper's method).
    CrmPpo,
    /// PPO with the stage-wise sparse transition rewards only.
    Ippo,
    /// PPO with the hierarchical dense intra-stage rewards only.
    Lppo,
    /// SAC inside the CRM with the CRM's reward (the paper's CRM-SAC baseline).
    CrmSac,
    /// PPO on the flat, unstaged machine (`crates/sim/specs/flat.json`): the ablation.
    Ppo,
}

impl Algorithm {
    pub const ALL: [Algorithm; 5] = [
        Algorithm::CrmPpo,
        Algorithm::Ippo,
        Algorithm::Lppo,
        Algorithm::CrmSac,
        Algorithm::Ppo,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Algorithm::CrmPpo => "crm-ppo",
            Algorithm::Ippo => "ippo",
            Algorithm::Lppo => "lppo",
            Algorithm::CrmSac => "crm-sac",
            Algorithm::Ppo => "ppo",
        }
    }

    /// The algorithm named `name`, as in checkpoints and the API.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|a| a.name() == name)
    }

    /// Whether this is a PPO learner of the grasping machine (crm-ppo, ippo, lppo): one
    /// Gaussian policy over the machine's stages, what behaviour cloning
    /// ([`crate::ImitationSpec::supports`]) acts on.
    pub fn is_machine_ppo(self) -> bool {
        matches!(self, Algorithm::CrmPpo | Algorithm::Ippo | Algorithm::Lppo)
    }
}
