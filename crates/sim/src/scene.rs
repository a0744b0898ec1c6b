//! Building the world for one task and seed: table, object (randomized pose), hand.

use std::sync::Arc;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rapier3d::prelude::*;

use crate::benchmark::{Axis, Object, Shape, Task};
use crate::config::SimConfig;
use crate::contacts::ContactMetrics;
use crate::hand::{HAND_GROUP, Hand, HandModel, OBJECT_GROUP, TABLE_GROUP};
use crate::stiction::Stiction;

/// Half extents of the table top; its surface is the plane z = 0.
pub const TABLE_HALF: [f32; 3] = [0.5, 0.5, 0.02];
const TABLE_FRICTION: f32 = 0.6;
/// Damping of the brake that holds an anchored (twist) object below its resisting torque.
const ANCHOR_BRAKE_DAMPING: f32 = 50.0;

/// One built world and the handles the environment needs.
pub struct Scene {
    pub world: PhysicsWorld,
    pub hand: Hand,
    /// The friction anchors between the hand and the object (see `stiction.rs`).
    pub stiction: Stiction,
    pub object: RigidBodyHandle,
    pub table: ColliderHandle,
    /// The object's pose after randomization, at reset.
    pub object_start: Pose,
    /// Where the hand's grasp point should go (world).
    pub grasp_location: Vec3,
    /// The hand's orientation at reset.
    pub hand_rotation: Rotation,
    /// The hand's orientation in the object's frame, which the wrist keeps in the approach.
    pub grasp_rotation: Rotation,
    /// The mount's position at reset (world).
    pub mount_start: Vec3,
}

impl Scene {
    /// The object's twist axis, a point on it and its direction: the object's vertical
    /// through its start position, the hinge of an anchored object.
    pub fn twist_axis(&self) -> (Vec3, Vec3) {
        (
            self.object_start.translation,
            self.object_start.rotation * Vec3::Z,
        )
    }

    /// Torque (N m) of `contacts` about the object's twist axis ([`Scene::twist_axis`]).
    pub fn twist_torque(&self, contacts: &ContactMetrics) -> f32 {
        let (point, axis) = self.twist_axis();
        contacts.torque_about(point, axis)
    }
}

/// A rapier collider for one primitive part.
pub fn part_collider(shape: &Shape) -> ColliderBuilder {
    let oriented = |builder: ColliderBuilder, axis: Axis| match axis {
        // rapier's cylinders run along y.
        Axis::X => builder.rotation(Vec3::new(0.0, 0.0, -std::f32::consts::FRAC_PI_2)),
        Axis::Y => builder,
        Axis::Z => builder.rotation(Vec3::new(std::f32::consts::FRAC_PI_2, 0.0, 0.0)),
    };
    match *shape {
        Shape::Cuboid { half_extents: h } => ColliderBuilder::cuboid(h[0], h[1], h[2]),
        Shape::Cylinder {
            radius,
            half_height,
            axis,
        } => oriented(ColliderBuilder::cylinder(half_height, radius), axis),
        Shape::Capsule {
            radius,
            half_height,
            axis,
        } => match axis {
            Axis::X => ColliderBuilder::capsule_x(half_height, radius),
            Axis::Y => ColliderBuilder::capsule_y(half_height, radius),
            Axis::Z => ColliderBuilder::capsule_z(half_height, radius),
        },
        Shape::Ball { radius } => ColliderBuilder::ball(radius),
        Shape::Mesh { ref geometry, .. } => match &geometry.shape {
            Some(shape) => ColliderBuilder::new(shape.clone()),
            // A mesh part is read when its benchmark loads; an unread one has no volume.
            None => ColliderBuilder::ball(1e-3),
        },
    }
}

fn symmetric(rng: &mut ChaCha8Rng, half_width: f32) -> f32 {
    if half_width > 0.0 {
        rng.random_range(-half_width..=half_width)
    } else {
        0.0
    }
}

/// The physics parameters of every world (DESIGN.md, rapier notes).
pub fn integration_parameters(config: &SimConfig) -> IntegrationParameters {
    let mut params = IntegrationParameters {
        dt: config.physics_dt,
        num_solver_iterations: config.solver_iterations.max(1),
        // Per-point Coulomb friction, so the friction-cone test reads real per-contact forces.
        friction_model: FrictionModel::Coulomb,
        // Keep the solver on the narrow phase's manifolds, whose points carry the impulses.
        contact_clustering: false,
        length_unit: 0.1,
        ..IntegrationParameters::default()
    };
    params.contact_softness.natural_frequency = 120.0;
    params
}

/// Builds the world of `task` for one episode; all randomness comes from `rng`.
pub fn build(
    hand: &Arc<HandModel>,
    task: &Task,
    object: &Object,
    config: &SimConfig,
    rng: &mut ChaCha8Rng,
) -> Scene {
    let mut world = PhysicsWorld::new();
    world.gravity = Vec3::new(0.0, 0.0, -9.81);
    world.integration_parameters = integration_parameters(config);

    let everything = InteractionGroups::new(
        TABLE_GROUP,
        HAND_GROUP | OBJECT_GROUP,
        InteractionTestMode::And,
    );
    let table = world.insert_collider(
        ColliderBuilder::cuboid(TABLE_HALF[0], TABLE_HALF[1], TABLE_HALF[2])
            .translation(Vec3::new(0.0, 0.0, -TABLE_HALF[2]))
            .friction(TABLE_FRICTION)
            .collision_groups(everything),
        None,
    );

    let noise = &config.randomization;
    let (dx, dy, dyaw) = if noise.enabled {
        (
            symmetric(rng, noise.position),
            symmetric(rng, noise.position),
            symmetric(rng, noise.yaw),
        )
    } else {
        (0.0, 0.0, 0.0)
    };
    let (min, _) = object.bounds();
    let object_start = Pose::from_parts(
        Vec3::new(dx, dy, -min[2] + 0.0005),
        Rotation::from_rotation_z(dyaw),
    );
    let handle = world.insert_body(
        RigidBodyBuilder::dynamic()
            .pose(object_start)
            .angular_damping(object.angular_damping.unwrap_or(0.0)),
    );
    let total_volume: f32 = object.parts.iter().map(|p| p.shape.volume()).sum();
    let object_groups = InteractionGroups::new(
        OBJECT_GROUP,
        HAND_GROUP | TABLE_GROUP,
        InteractionTestMode::And,
    );
    for part in &object.parts {
        let collider = part_collider(&part.shape);
        let local = Pose::from_translation(Vec3::from(part.pos)) * collider.position;
        world.insert_collider(
            collider
                .position(local)
                .mass(object.mass * part.shape.volume() / total_volume)
                .friction(object.friction)
                .collision_groups(object_groups),
            Some(handle),
        );
    }
    if let Some(anchor) = &object.anchor {
        let ground = world.insert_body(RigidBodyBuilder::fixed().pose(object_start));
        let joint = RevoluteJointBuilder::new(Vec3::Z)
            .motor_model(MotorModel::ForceBased)
            .motor_velocity(0.0, ANCHOR_BRAKE_DAMPING)
            .motor_max_force(anchor.resist_torque);
        world.insert_impulse_joint(ground, handle, joint);
    }

    let grasp_rotation = match task.grasp.orientation {
        Some(q) => {
            Rotation::from_xyzw(q[0], q[1], q[2], q[3]).normalize() * hand.grasp_frame.inverse()
        }
        None => Rotation::from_rotation_z(task.grasp.yaw) * hand.base_rotation,
    };
    let hand_rotation = object_start.rotation * grasp_rotation;
    let grasp_location = object_start.transform_point(Vec3::from(task.grasp.offset));
    let grasp_point = hand_rotation * hand.grasp_point_of(task.topology);
    let mount_start =
        grasp_location + Vec3::from(task.start.unwrap_or(config.hand_start)) - grasp_point;
    let joint_offsets = hand
        .fingers
        .iter()
        .map(|finger| {
            finger
                .coupled
                .iter()
                .map(|_| {
                    if noise.enabled {
                        symmetric(rng, noise.joint)
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let hand = Hand::build(
        &mut world,
        hand,
        Pose::from_parts(mount_start, hand_rotation),
        task.topology,
        joint_offsets,
        Stiction::hooks(&config.stiction),
    );
    let (min, max) = object.bounds();
    let radius = Vec3::from(min).length().max(Vec3::from(max).length());
    let stiction = Stiction::new(config.stiction, handle, radius);
    Scene {
        world,
        hand,
        stiction,
        object: handle,
        table,
        object_start,
        grasp_location,
        hand_rotation,
        grasp_rotation,
        mount_start,
    }
}
