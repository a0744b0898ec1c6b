//! The benchmark's vocabularies: the 7 task objectives, the 6 grasp topologies of the
//! paper's Fig. 2 (section II-B) and the fragility classes with their grasp-force limits.
//! Hands and benchmarks both speak it; neither imports the other for it.

use serde::{Deserialize, Serialize};

/// The five fingers in action order (paper, section IV-B: thumb, index, middle, ring, little).
pub const FINGERS: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];

/// A task objective (paper, section V-A).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Objective {
    Lift,
    Pull,
    Press,
    Twist,
    Lever,
    WrapGrasp,
    HandleGrasp,
}

impl Objective {
    pub const ALL: [Objective; 7] = [
        Objective::Lift,
        Objective::Pull,
        Objective::Press,
        Objective::Twist,
        Objective::Lever,
        Objective::WrapGrasp,
        Objective::HandleGrasp,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Objective::Lift => "lift",
            Objective::Pull => "pull",
            Objective::Press => "press",
            Objective::Twist => "twist",
            Objective::Lever => "lever",
            Objective::WrapGrasp => "wrap_grasp",
            Objective::HandleGrasp => "handle_grasp",
        }
    }

    pub fn index(self) -> usize {
        Self::ALL.iter().position(|&o| o == self).unwrap_or(0)
    }

    /// Objectives whose success is "picked up and held steadily for 5 s" (paper, V-B-2).
    pub fn is_hold(self) -> bool {
        !matches!(self, Objective::Press | Objective::Twist)
    }
}

/// Per-finger role of a topology: whether the policy moves it, its starting PIP angle and
/// the closed shape it aims for (radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FingerShape {
    pub active: bool,
    pub preshape: f32,
    pub closed: f32,
}

/// A grasp topology: a target hand shape (paper, section II-B).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Topology {
    /// Flat hand for holding, pushing or pressing.
    #[serde(rename = "platform")]
    Platform,
    /// Power grasp, palm opposition, fingers 2-5.
    #[serde(rename = "poPmAb25")]
    PoPmAb25,
    /// Precision pad opposition, thumb and index.
    #[serde(rename = "pPdAb2")]
    PPdAb2,
    /// Precision pad opposition, thumb, index and middle.
    #[serde(rename = "pPdAb23")]
    PPdAb23,
    /// Precision pad opposition, thumb and fingers 2-5.
    #[serde(rename = "pPdAb25")]
    PPdAb25,
    /// Intermediate side opposition (thumb against the curled index), for levering and twisting.
    #[serde(rename = "InSiAd2")]
    InSiAd2,
}

impl Topology {
    pub const ALL: [Topology; 6] = [
        Topology::Platform,
        Topology::PoPmAb25,
        Topology::PPdAb2,
        Topology::PPdAb23,
        Topology::PPdAb25,
        Topology::InSiAd2,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Topology::Platform => "platform",
            Topology::PoPmAb25 => "poPmAb25",
            Topology::PPdAb2 => "pPdAb2",
            Topology::PPdAb23 => "pPdAb23",
            Topology::PPdAb25 => "pPdAb25",
            Topology::InSiAd2 => "InSiAd2",
        }
    }

    pub fn index(self) -> usize {
        Self::ALL.iter().position(|&t| t == self).unwrap_or(0)
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }
}

/// How much squeezing an object takes before it is damaged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fragility {
    Fragile,
    Normal,
    Sturdy,
}

impl Fragility {
    /// The largest summed normal force (N) the hand may apply; above it for a few control
    /// steps the grasp fails (the object is crushed).
    pub fn grasp_force_limit(self) -> f32 {
        match self {
            Fragility::Fragile => 15.0,
            Fragility::Normal => 40.0,
            Fragility::Sturdy => 80.0,
        }
    }

    /// A number for the topology network's features: 1 fragile, 0.5 normal, 0 sturdy.
    pub fn level(self) -> f32 {
        match self {
            Fragility::Fragile => 1.0,
            Fragility::Normal => 0.5,
            Fragility::Sturdy => 0.0,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Fragility::Fragile => "fragile",
            Fragility::Normal => "normal",
            Fragility::Sturdy => "sturdy",
        }
    }
}
