//! The global observation `u` (paper, section IV-C) and the union action space.
//!
//! The paper's vector `[n_c, o_dist, o_object, o_cone, o_relative, o_force, o_torque]` comes
//! first; the rest is what a multi-task policy needs to act on it (the paper's single network
//! was trained on one scene family): the finger commands in force, the grip as a fraction of
//! the object's force limit, the objective's progress, and the task's objective and topology.

use crate::benchmark::{Objective, Topology};

/// Names of the global observation's features, in order.
pub const FEATURES: [&str; 38] = [
    // n_c: number of hand-object contact points.
    "n_c",
    // o_dist: distance from the hand's grasp point to the grasp location (m).
    "dist",
    // o_object: object displacement from its start (m, world).
    "object_x",
    "object_y",
    "object_z",
    // o_cone: 1 when every contact sticks inside its friction cone (with a margin).
    "cone",
    // o_relative: grasp location minus grasp point (m, world) ...
    "rel_x",
    "rel_y",
    "rel_z",
    // ... and the object's centre of mass relative to the grasp point (m, world).
    "in_hand_x",
    "in_hand_y",
    "in_hand_z",
    // o_force, o_torque: summed contact forces (N) and torques about the object's centre of
    // mass (N m) from the hand, world axes.
    "force_x",
    "force_y",
    "force_z",
    "torque_x",
    "torque_y",
    "torque_z",
    // PIP (thumb: TMCP) commands in force (rad).
    "cmd_thumb",
    "cmd_index",
    "cmd_middle",
    "cmd_ring",
    "cmd_little",
    // Summed normal force over the object's fragility limit.
    "grip",
    // Progress of the objective's success test in [0, 1].
    "progress",
    "objective_lift",
    "objective_pull",
    "objective_press",
    "objective_twist",
    "objective_lever",
    "objective_wrap_grasp",
    "objective_handle_grasp",
    "topology_platform",
    "topology_poPmAb25",
    "topology_pPdAb2",
    "topology_pPdAb23",
    "topology_pPdAb25",
    "topology_InSiAd2",
];

/// Names of the union action space's dimensions (paper, section IV-B): palm increments (m)
/// and PIP command increments (rad) of thumb, index, middle, ring and little finger.
pub const ACTIONS: [&str; 8] = [
    "dx", "dy", "dz", "thumb", "index", "middle", "ring", "little",
];

/// Largest palm step (m) and finger step (rad) the hand accepts per control step; larger
/// values are clipped and counted.
pub const MAX_PALM_STEP: f32 = 0.02;
pub const MAX_FINGER_STEP: f32 = 0.2;

/// Index of a feature by name (for readers of the observation).
pub fn feature(name: &str) -> Option<usize> {
    FEATURES.iter().position(|&f| f == name)
}

/// Everything the observation is made of, before flattening.
#[derive(Clone, Debug, Default)]
pub struct ObservationParts {
    pub n_c: usize,
    pub dist: f32,
    pub object: [f32; 3],
    pub cone: bool,
    pub relative: [f32; 3],
    pub in_hand: [f32; 3],
    pub force: [f32; 3],
    pub torque: [f32; 3],
    pub commands: [f32; 5],
    pub grip: f32,
    pub progress: f32,
    pub objective: Option<Objective>,
    pub topology: Option<Topology>,
}

impl ObservationParts {
    pub fn to_vec(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(FEATURES.len());
        out.push(self.n_c as f32);
        out.push(self.dist);
        out.extend_from_slice(&self.object);
        out.push(if self.cone { 1.0 } else { 0.0 });
        out.extend_from_slice(&self.relative);
        out.extend_from_slice(&self.in_hand);
        out.extend_from_slice(&self.force);
        out.extend_from_slice(&self.torque);
        out.extend_from_slice(&self.commands);
        out.push(self.grip);
        out.push(self.progress);
        let objective = self.objective.map(Objective::index);
        out.extend(Objective::ALL.iter().map(|o| {
            if Some(o.index()) == objective {
                1.0
            } else {
                0.0
            }
        }));
        let topology = self.topology.map(Topology::index);
        out.extend(Topology::ALL.iter().map(|t| {
            if Some(t.index()) == topology {
                1.0
            } else {
                0.0
            }
        }));
        debug_assert_eq!(out.len(), FEATURES.len());
        out
    }
}
