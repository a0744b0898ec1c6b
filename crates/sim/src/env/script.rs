//! The arm's objective controllers: what the arm does once the grasp is ready (the paper's
//! protocol runs them inside the environment step; the oracle runs them as its last phase).
//! Lift (along the task's motion) to just above the success height, twist (the execution
//! turns the wrist about the object's axis, [`twist_spin`]; before a hand-over the palm
//! pushes along the tangent), backing off when the grip nears the fragility limit, or press
//! down under force regulation. The fingers keep the grasp they were given: they open a
//! little when the grip nears the fragility limit and close a little when it relaxes under
//! 80% of the grip they are to `hold` (the grip at the hand-over for the environment's
//! execution, at least a share of the limit for a twist; [`wanted_grip`] for the oracle). A
//! loose grasp stays loose.

use rapier3d::prelude::Vec3;

use super::GraspEnv;
use crate::benchmark::Objective;
use crate::observation::ACTIONS;

/// Step scales of the grasping spec's grasp stage: palm metres and finger radians per unit
/// action.
pub const GRASP_SCALE: f32 = 0.003;
pub const FINGER_SCALE: f32 = 0.1;
/// Fraction of the grasp step used to move a held object (slower swings less).
const LIFT_SPEED: f32 = 0.6;
/// Height (m) above the success test's lift height to which a held object is raised.
const LIFT_MARGIN: f32 = 0.02;
/// Fractions of the grasp step with which a twist pushes along the tangent and backs off
/// when the grip nears the fragility limit (0.2: the back-off that took the paper world's
/// `t20-dispenser-twist` from 18 crushed episodes of 100 to 3; docs/notebook/benchmarks.md,
/// "The twist: the control step's torque").
const TWIST_PUSH: f32 = 0.5;
const TWIST_BACK_OFF: f32 = 0.2;

/// Shortest radius (m) from the twist axis that a twist's turn is paced for: a grasp point on
/// the axis would otherwise turn without bound.
const TWIST_MIN_RADIUS: f32 = 0.02;

/// The wrist's turn (rad) about the object's twist axis for one control step of a twist: the
/// grasp point moves along its circle at the tangential push's speed ([`TWIST_PUSH`] of a
/// grasp step, [`TWIST_BACK_OFF`] back when the grip nears the fragility limit), in the
/// direction of the task's torque. Turning the whole hand, the fingers twist the object
/// whichever side of its axis they hold it on.
pub fn twist_spin(env: &GraspEnv) -> f32 {
    let Some(scene) = env.scene() else {
        return 0.0;
    };
    let (grip, limit) = grip_and_limit(env);
    let speed = twist_pace(near_limit(grip, limit)) * GRASP_SCALE;
    let (pivot, axis) = scene.twist_axis();
    let arm = scene.hand.grasp_point(&scene.world) - pivot;
    let radius = (arm - arm.dot(axis) * axis).length().max(TWIST_MIN_RADIUS);
    env.task().required.unwrap_or(1.0).signum() * speed / radius
}

/// The last control step's grip and the task's object's fragility limit (N).
pub(super) fn grip_and_limit(env: &GraspEnv) -> (f32, f32) {
    let limit = env
        .benchmark()
        .object_of(env.task())
        .fragility
        .grasp_force_limit();
    (env.observation_parts().grip * limit, limit)
}

/// Whether a grip is near the fragility limit: the fingers open a little and a twist backs
/// off.
fn near_limit(grip: f32, limit: f32) -> bool {
    grip > 0.8 * limit
}

/// A twist's pace along its tangent, in grasp steps: it pushes, and backs off when the grip
/// nears the fragility limit. A push on an object that resists it squeezes the fingers, and
/// pushing on would crush the object before the test's time. (Holding still once the torque
/// is there lets it relax under a part that turns.)
fn twist_pace(near_limit: bool) -> f32 {
    if near_limit {
        -TWIST_BACK_OFF
    } else {
        TWIST_PUSH
    }
}

fn unit(value: f32, scale: f32) -> f32 {
    (value / scale).clamp(-1.0, 1.0)
}

/// The grip (N) the oracle closes to: [`crate::ready::carrying_grip`] of the task's object.
pub fn wanted_grip(env: &GraspEnv) -> f32 {
    crate::ready::carrying_grip(env.benchmark().object_of(env.task()))
}

/// The arm's next action for the current task's objective, in the grasp stage's units
/// (`[-1, 1]` per dimension; see [`GRASP_SCALE`] and [`FINGER_SCALE`]); the fingers close
/// when the grip falls under 80% of `hold` (N).
pub fn objective_action(env: &GraspEnv, hold: f32) -> Vec<f32> {
    let mut action = vec![0.0; ACTIONS.len()];
    let parts = env.observation_parts();
    let task = env.task();
    let shape = env.hand_shape();
    let (grip, limit) = grip_and_limit(env);
    // Near the fragility limit the fingers open, and a twist's palm backs off.
    let near_limit = near_limit(grip, limit);
    // Keep the grip under the fragility limit and near the grip to hold.
    for finger in 0..5 {
        if shape[finger].active && task.objective != Objective::Press {
            action[3 + finger] = if near_limit {
                -0.3
            } else if grip < 0.8 * hold {
                0.3
            } else {
                0.0
            };
        }
    }
    let start_yaw = env
        .scene()
        .map(|s| s.object_start.rotation)
        .unwrap_or_default();
    let motion = start_yaw * Vec3::from(task.motion).normalize_or_zero();
    match task.objective {
        Objective::Press => {
            // Centre the palm over the button while pressing.
            action[0] = unit(parts.relative[0], GRASP_SCALE);
            action[1] = unit(parts.relative[1], GRASP_SCALE);
            let required = task.required.unwrap_or(0.0).abs();
            let press = -parts.force[2];
            action[2] = if press > 0.7 * limit {
                0.5
            } else if press < 1.3 * required {
                -0.5
            } else {
                0.0
            };
        }
        Objective::Twist => {
            // Push along the tangent at the twist's pace.
            let speed = twist_pace(near_limit);
            for axis in 0..3 {
                action[axis] = speed * motion[axis];
            }
        }
        _ => {
            // Lift until the object stands clear of the success height: a rule on an
            // observed quantity, so a policy cloned from the oracle can tell when to stop.
            if parts.object[2] < env.config().lift_height + LIFT_MARGIN {
                for axis in 0..3 {
                    action[axis] = LIFT_SPEED * motion[axis];
                }
            }
        }
    }
    action
}
