//! The hand profile (JSON): what the paper's method needs to know about a hand that its
//! description does not say. Which link is the palm and where its grasp point is, which joint
//! each of the paper's five finger actions commands and how the others follow it, the finger
//! groups of the ready test and the topologies, the motors, and the preshape per topology.
//! [`super::HandModel::new`] checks it against the description, naming the field.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::taxonomy::Topology;

/// A hand profile as written in `hand.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// The description file (URDF or MJCF), relative to the profile or found in `CRM_ASSETS`.
    pub description: String,
    /// The link the wrist holds; links above it (an arm) are not part of the hand.
    pub palm: String,
    /// Other links whose contacts count as the palm's (default: none).
    #[serde(default)]
    pub palm_links: Vec<String>,
    /// The point that goes to a task's grasp location, in the palm frame (m).
    pub grasp_point: [f32; 3],
    /// The direction the palm approaches along, in the palm frame: it points down at the
    /// object (world -z).
    pub approach_axis: [f32; 3],
    /// The direction the fingers point, in the palm frame: world +x at a task's zero yaw.
    pub finger_axis: [f32; 3],
    /// The frame a task's `grasp.orientation` places, as a unit quaternion `[x, y, z, w]` in
    /// the palm frame (default: the palm frame itself). An imported world puts here the frame
    /// its source's tasks were written for (DexMobile: their end-effector link's, turned by
    /// their `convert_hand`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasp_frame: Option<[f32; 4]>,
    /// Friction coefficient of every hand collider.
    pub friction: f32,
    pub wrist: Wrist,
    pub motor: Motor,
    pub fingers: Fingers,
    /// The shape of every topology (all six).
    pub topologies: BTreeMap<Topology, TopologyShape>,
    /// Finger commands held through the approach, by finger name (default: none, so the hand
    /// approaches in its topology's preshape). Where given, the hand takes the preshape when
    /// the grasp stage begins, as the authors' hand does (their `relax` pose, then the
    /// topology's grasp pose), at `SimConfig::preshape_speed`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub relaxed: BTreeMap<String, f32>,
    /// Joints the paper's action does not move (spread, thumb opposition), held at these
    /// angles in every topology unless the topology says otherwise; any other joint of the
    /// hand that no finger commands is held at 0.
    #[serde(default)]
    pub held: BTreeMap<String, f32>,
    /// Joints whose coupling in the description (URDF `<mimic>`, MJCF equalities, tendons)
    /// this profile replaces on purpose: `crm world check` refuses a profile that couples,
    /// commands or holds such a joint otherwise unless it is named here. It changes nothing
    /// the hand does, so it is not in the world's hash.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub description_overrides: Vec<String>,
}

/// The compliant joint between the arm's mount and the palm (a bounded linear spring; the
/// orientation is locked).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wrist {
    /// N/m.
    pub stiffness: f32,
    /// N s/m.
    pub damping: f32,
    /// N, per axis.
    pub max_force: f32,
}

impl Wrist {
    /// The built-in hand's wrist (`worlds/crm/hand.json`), the default of drafted and imported
    /// hands.
    pub const BUILTIN: Wrist = Wrist {
        stiffness: 2500.0,
        damping: 80.0,
        max_force: 50.0,
    };
}

/// Position motors on every hand joint.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Motor {
    /// N m/rad.
    pub stiffness: f32,
    /// N m s/rad.
    pub damping: f32,
    /// N m: the torque limit of a joint that names none.
    pub torque: f32,
    /// kg m²: rotor inertia added to each moving link (default: the description's
    /// `armature` per joint, MuJoCo's way of keeping light links stable; 0 where none).
    #[serde(default)]
    pub armature: Option<f32>,
}

impl Motor {
    /// The built-in hand's motors (`worlds/crm/hand.json`), the default of drafted hands.
    pub const BUILTIN: Motor = Motor {
        stiffness: 3.0,
        damping: 0.06,
        torque: 0.2,
        armature: None,
    };
}

/// The paper's five finger actions, thumb first. A four-finger hand (Allegro, LEAP) leaves
/// one of `middle`, `ring` and `little` out: its action dimension stays in the paper's
/// 8-dimensional action space, masked in every stage ([`crate::World::machine`]), and no
/// topology may use it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fingers {
    pub thumb: Finger,
    pub index: Finger,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub middle: Option<Finger>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ring: Option<Finger>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub little: Option<Finger>,
}

impl Fingers {
    /// Each finger the hand has, thumb first; `None` where the profile leaves it out.
    pub fn all(&self) -> [Option<&Finger>; 5] {
        [
            Some(&self.thumb),
            Some(&self.index),
            self.middle.as_ref(),
            self.ring.as_ref(),
            self.little.as_ref(),
        ]
    }
}

/// One finger: the joint its action commands (PIP; the thumb's TMCP), the command range and
/// the joints that follow the command.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Finger {
    pub command: String,
    /// Radians, `[open, closed]`.
    pub range: [f32; 2],
    /// The finger's joints, proximal first, the commanded one among them.
    pub joints: Vec<Coupled>,
    /// The links whose contacts count as this finger's (default: the joints' child links).
    #[serde(default)]
    pub links: Vec<String>,
}

/// A joint that follows its finger's command: `angle = ratio * command + offset`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Coupled {
    pub joint: String,
    /// A number, a paper coupling (`"pip"`, `"tmcp"`: 1; `"mcp"`: alpha_MCP; `"dip"`: the
    /// finger's alpha_DIP; `"ip"`: alpha_TMCP, section IV-B), or `"description"`: the
    /// description's own mimic/equality ratio. Default: the description's, where it has one.
    #[serde(default)]
    pub ratio: Option<Ratio>,
    /// Radians (default: the description's mimic offset, else 0).
    #[serde(default)]
    pub offset: Option<f32>,
    /// The motor's torque limit, N m (default: `motor.torque`).
    #[serde(default)]
    pub torque: Option<f32>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Ratio {
    Value(f32),
    Named(String),
}

/// A topology's hand shape: which fingers it uses, their commands before closing (preshape),
/// how far the scripted oracle closes them, held joints and a grasp point of its own.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopologyShape {
    /// Finger names (`thumb`, `index`, `middle`, `ring`, `little`).
    #[serde(default)]
    pub active: Vec<String>,
    /// Commands at reset, by finger name (default 0).
    #[serde(default)]
    pub preshape: BTreeMap<String, f32>,
    /// Commands the oracle closes to, by finger name (default 0).
    #[serde(default)]
    pub closed: BTreeMap<String, f32>,
    /// Held joint angles in this topology (over the profile's `held`).
    #[serde(default)]
    pub held: BTreeMap<String, f32>,
    /// The point (palm frame, m) this topology brings to the task's grasp location, where it
    /// is not the profile's `grasp_point`: a palm press wants the palm's face where a pinch
    /// wants the fingertips' meeting point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasp_point: Option<[f32; 3]>,
}
