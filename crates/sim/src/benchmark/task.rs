//! A task of the benchmark: an object, an objective, a topology and where to grasp.

use serde::{Deserialize, Serialize};

use crate::taxonomy::{Objective, Topology};

/// Where the hand goes: its grasp point (the profile's `grasp_point`) at `offset` in the
/// object frame, with the hand turned by `yaw` (radians) about the vertical from the object's
/// heading, or, where `orientation` is given, with the hand's grasp frame (the profile's
/// `grasp_frame`) at that orientation in the object frame. Orientation is not an action: the
/// wrist holds it, as the authors' IK does (DESIGN.md: the arm's IK is abstracted).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraspLocation {
    pub offset: [f32; 3],
    #[serde(default)]
    pub yaw: f32,
    /// A unit quaternion `[x, y, z, w]` (the authors' order); excludes a non-zero `yaw`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation: Option<[f32; 4]>,
}

/// One of the benchmark's tasks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Task {
    pub id: String,
    pub object: String,
    pub objective: Objective,
    pub topology: Topology,
    pub grasp: GraspLocation,
    /// The direction the hand moves once it holds the object, in the object frame (lift: up;
    /// pull: up and towards the robot; twist: along the tangent of the turn).
    pub motion: [f32; 3],
    /// Where the hand's grasp point starts, relative to the grasp location (m, world frame;
    /// default: the config's `hand_start`). An imported world puts its source's start here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start: Option<[f32; 3]>,
    /// Twist: the torque to reach about the object's vertical axis (N m, sign gives the
    /// direction). Press: the force to reach along the press direction, straight down (N).
    #[serde(default)]
    pub required: Option<f32>,
}
