//! Static friction that holds position, not only velocity ("friction anchors").
//!
//! rapier solves friction at the velocity level: a sticking contact gets zero relative
//! tangential velocity, but the position error that every substep leaves behind is never
//! corrected, so an object held still in the hand creeps out of it over seconds
//! (docs/notebook/benchmarks.md, "The solver's contact settings against the hold's creep"). Engines
//! that hold grasps anchor each sticking contact (PhysX's friction anchors, Box2D v3's
//! anchored friction): the friction constraint also steers the contact back to where it
//! stuck. Here each hand body touching the object keeps the object's pose in its own frame
//! from the step it first touched; every physics step, each of its contacts with the object
//! asks the friction solver for a relative tangential velocity that closes the drift
//! (`gain` per second, at most `max_speed`). The solver still clamps friction to the Coulomb
//! cone, so a grasp that cannot hold still slides; a drift beyond `slip` counts as a slide
//! and re-anchors where the object is.

use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};

/// Settings of the friction anchors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StictionConfig {
    /// On by default (environment v4).
    pub enabled: bool,
    /// Drift closed per second (1/s). Default 60: a quarter of the drift per physics step
    /// (1/240 s), stable, and within 0.01 of the best of 3-100 measured
    /// (docs/notebook/benchmarks.md, "Friction anchors").
    pub gain: f32,
    /// Fastest correction (m/s). Default 0.2 (measured with `gain`).
    pub max_speed: f32,
    /// Drift (m) past which the contact has slid: the anchor moves to where the object is.
    /// Default 0.01, the tangential give of a soft fingertip pad before it slides (2 mm,
    /// 5 mm and 2 cm measured).
    pub slip: f32,
}

impl Default for StictionConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            gain: 60.0,
            max_speed: 0.2,
            slip: 0.01,
        }
    }
}

/// The anchors of one world: the object's pose in each touching hand body's frame.
#[derive(Clone, Debug)]
pub struct Stiction {
    config: StictionConfig,
    object: RigidBodyHandle,
    /// Each anchored hand body and the object's pose in that body's frame when it stuck.
    anchors: Vec<(RigidBodyHandle, Pose)>,
    /// A bound of the distance from the object's body origin to its surface (m), to bound
    /// how far a contact moves when the object turns.
    radius: f32,
}

impl Stiction {
    pub fn new(config: StictionConfig, object: RigidBodyHandle, radius: f32) -> Self {
        Self {
            config,
            object,
            anchors: Vec::new(),
            radius,
        }
    }

    /// The colliders' hook flags: hand colliders ask for the hook when anchors are on.
    pub fn hooks(config: &StictionConfig) -> ActiveHooks {
        if config.enabled {
            ActiveHooks::MODIFY_SOLVER_CONTACTS
        } else {
            ActiveHooks::empty()
        }
    }

    /// Updates the anchors after a physics step: `touching` lists the hand bodies in contact
    /// with the object now. New contacts anchor; lost ones drop; slid ones re-anchor.
    pub fn update(&mut self, bodies: &RigidBodySet, touching: &[RigidBodyHandle]) {
        if !self.config.enabled {
            return;
        }
        let Some(object) = bodies.get(self.object) else {
            return;
        };
        let object_pose = *object.position();
        self.anchors.retain(|(body, _)| touching.contains(body));
        for &body in touching {
            let Some(link) = bodies.get(body) else {
                continue;
            };
            let relative = link.position().inverse() * object_pose;
            match self.anchors.iter_mut().find(|(b, _)| *b == body) {
                Some((_, anchor)) => {
                    if drift_bound(anchor, &relative, self.radius) > self.config.slip {
                        *anchor = relative;
                    }
                }
                None => self.anchors.push((body, relative)),
            }
        }
    }

    /// How many hand bodies hold an anchor.
    pub fn anchored(&self) -> usize {
        self.anchors.len()
    }
}

/// An upper bound of how far any point of the object within `radius` of its centre moved
/// between two poses in the same frame.
fn drift_bound(a: &Pose, b: &Pose, radius: f32) -> f32 {
    let turn = (a.rotation.inverse() * b.rotation).to_axis_angle().1.abs();
    (a.translation - b.translation).length() + turn * radius
}

impl PhysicsHooks for Stiction {
    fn modify_solver_contacts(&self, context: &mut ContactModificationContext) {
        let (Some(body1), Some(body2)) = (context.rigid_body1, context.rigid_body2) else {
            return;
        };
        let (hand_body, object_first) = if body1 == self.object {
            (body2, true)
        } else if body2 == self.object {
            (body1, false)
        } else {
            return;
        };
        let Some((_, anchor)) = self.anchors.iter().find(|(b, _)| *b == hand_body) else {
            return;
        };
        let (Some(object), Some(link)) = (
            context.bodies.get(self.object),
            context.bodies.get(hand_body),
        ) else {
            return;
        };
        let object_pose = *object.position();
        let anchored_pose = *link.position() * *anchor;
        let StictionConfig {
            gain, max_speed, ..
        } = self.config;
        let Some(rigid) = context.rigid_mut() else {
            return;
        };
        let normal = *rigid.normal;
        for contact in rigid.solver_contacts.iter_mut() {
            let point = if object_first {
                contact.anchor1
            } else {
                contact.anchor2
            };
            // Where this point of the object would be had it stuck to the hand body.
            let stuck = anchored_pose.transform_point(object_pose.inverse_transform_point(point));
            let error = stuck - point;
            let tangential = error - normal * normal.dot(error);
            let velocity = (tangential * gain).clamp_length_max(max_speed);
            // The solver drives `v2 - v1` at the contact towards `tangent_velocity` (the unit
            // test below fails with the other sign).
            contact.tangent_velocity = if object_first { -velocity } else { velocity };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_drift_bound_adds_the_turn_at_the_radius_to_the_shift() {
        let a = Pose::from_translation(Vec3::new(0.1, 0.0, 0.0));
        assert!(drift_bound(&a, &a, 0.05) < 1e-6);
        let shifted = Pose::from_translation(Vec3::new(0.1, 0.003, 0.0));
        assert!((drift_bound(&a, &shifted, 0.05) - 0.003).abs() < 1e-6);
        let turned = Pose::from_parts(Vec3::new(0.1, 0.0, 0.0), Rotation::from_rotation_z(0.1));
        assert!((drift_bound(&a, &turned, 0.05) - 0.005).abs() < 1e-5);
    }

    /// A 4 cm box resting on a fixed plate (the "hand body"), and the anchors between them.
    fn box_on_plate(
        config: StictionConfig,
    ) -> (PhysicsWorld, RigidBodyHandle, RigidBodyHandle, Stiction) {
        let mut world = PhysicsWorld::new();
        world.gravity = Vec3::new(0.0, 0.0, -9.81);
        world.integration_parameters =
            crate::scene::integration_parameters(&crate::SimConfig::default());
        let plate = world.insert_body(RigidBodyBuilder::fixed());
        world.insert_collider(
            ColliderBuilder::cuboid(0.2, 0.2, 0.01)
                .translation(Vec3::new(0.0, 0.0, -0.01))
                .friction(1.0)
                .active_hooks(Stiction::hooks(&config)),
            Some(plate),
        );
        let object =
            world.insert_body(RigidBodyBuilder::dynamic().translation(Vec3::new(0.0, 0.0, 0.0199)));
        world.insert_collider(
            ColliderBuilder::cuboid(0.02, 0.02, 0.02)
                .mass(0.2)
                .friction(1.0),
            Some(object),
        );
        let stiction = Stiction::new(config, object, 0.035);
        (world, plate, object, stiction)
    }

    /// Settles the box, moves it 3 mm along x (within the slip distance) and steps 0.5 s;
    /// returns where it ends on x.
    fn displaced_box_ends_at(config: StictionConfig) -> f32 {
        let (mut world, plate, object, mut stiction) = box_on_plate(config);
        for _ in 0..60 {
            world.step_with_events(&stiction, &());
            stiction.update(&world.bodies, &[plate]);
        }
        assert_eq!(stiction.anchored(), usize::from(config.enabled));
        let body = world.bodies.get_mut(object).expect("the box");
        let moved = *body.position() * Pose::from_translation(Vec3::new(0.003, 0.0, 0.0));
        body.set_position(moved, true);
        for _ in 0..120 {
            world.step_with_events(&stiction, &());
            stiction.update(&world.bodies, &[plate]);
        }
        world.bodies[object].translation().x
    }

    #[test]
    fn an_anchored_contact_pulls_a_displaced_object_back_where_it_stuck() {
        // rapier's velocity-level friction leaves the box where it was put...
        let free = displaced_box_ends_at(StictionConfig {
            enabled: false,
            ..StictionConfig::default()
        });
        assert!(
            (free - 0.003).abs() < 5e-4,
            "without anchors the box stays: {free}"
        );
        // ...the anchor steers it back to where it stuck (a wrong sign pushes it away).
        let anchored = displaced_box_ends_at(StictionConfig::default());
        assert!(
            anchored.abs() < 5e-4,
            "with anchors the box returns: {anchored}"
        );
    }

    #[test]
    fn anchors_follow_contact_and_move_after_a_slide() {
        let config = StictionConfig::default();
        let (mut world, plate, object, mut stiction) = box_on_plate(config);
        stiction.update(&world.bodies, &[plate]);
        assert_eq!(stiction.anchored(), 1);
        let start = stiction.anchors[0].1;
        // A drift within the slip distance keeps the anchor...
        let body = world.bodies.get_mut(object).expect("the box");
        body.set_translation(Vec3::new(0.004, 0.0, 0.0199), true);
        stiction.update(&world.bodies, &[plate]);
        assert_eq!(stiction.anchors[0].1, start);
        // ...one past it is a slide: the anchor moves to where the object is.
        let body = world.bodies.get_mut(object).expect("the box");
        body.set_translation(Vec3::new(0.02, 0.0, 0.0199), true);
        stiction.update(&world.bodies, &[plate]);
        assert!((stiction.anchors[0].1.translation.x - 0.02).abs() < 1e-6);
        // Contact lost: no anchor.
        stiction.update(&world.bodies, &[]);
        assert_eq!(stiction.anchored(), 0);
        world.step();
    }
}
