//! The five-finger hand: a palm on a compliant Cartesian wrist and five motor-driven fingers
//! with the paper's joint coupling (section IV-B), built from a [`HandModel`] (a robot
//! description and its profile, read once) at every reset.
//!
//! The palm follows a kinematic mount (the arm, whose IK is abstracted) through a joint with
//! bounded linear motor force, so pressing and pulling forces are bounded as an arm's are;
//! orientation is locked. Hand links ignore gravity (the arm and finger motors compensate
//! their own weight). Every revolute joint has a position motor: a finger's joints follow
//! its command through the coupling, the others hold the topology's angles.

pub mod builtin;
pub mod couplings;
pub mod description;
pub mod draft;
mod finger;
mod hulls;
pub(crate) mod includes;
mod meshes;
pub mod model;
mod names;
mod numbers;
pub mod profile;

use std::sync::Arc;

use rapier3d::prelude::*;

use description::JointKind;

pub use model::HandModel;

use crate::taxonomy::Topology;

/// `alpha_DIP` for index, middle, ring, little (paper, section IV-B).
pub const ALPHA_DIP: [f32; 4] = [0.77, 0.75, 0.75, 0.57];
/// `alpha_MCP` for all fingers (paper, section IV-B).
pub const ALPHA_MCP: f32 = 0.67;
/// `alpha_TMCP`: thumb IP = 0.5 * TMCP (paper, section IV-B).
pub const ALPHA_TMCP: f32 = 0.5;
/// Mass (kg) of a link with neither shapes nor a mass in its description.
const SHAPELESS_MASS: f32 = 0.005;

/// Collision group of hand colliders.
pub const HAND_GROUP: Group = Group::GROUP_1;
/// Collision group of the object.
pub const OBJECT_GROUP: Group = Group::GROUP_2;
/// Collision group of the table.
pub const TABLE_GROUP: Group = Group::GROUP_3;

/// Joint angles of a finger for one PIP (thumb: TMCP) command, proximal first: the paper's
/// coupling `MCP = 0.67 PIP`, `DIP = a_DIP PIP`, thumb `IP = 0.5 TMCP`.
pub fn coupled_angles(finger: usize, command: f32) -> Vec<f32> {
    if finger == 0 {
        vec![command, ALPHA_TMCP * command]
    } else {
        vec![
            ALPHA_MCP * command,
            command,
            ALPHA_DIP[finger - 1] * command,
        ]
    }
}

/// Handles of one built hand.
#[derive(Clone, Debug)]
pub struct Hand {
    pub mount: RigidBodyHandle,
    pub palm: RigidBodyHandle,
    /// All hand bodies, in the model's link order (the palm first); a link welded to its
    /// parent (behind a fixed joint or one the topology holds) has its parent's body.
    pub bodies: Vec<RigidBodyHandle>,
    /// Each link's pose in its body (the identity but for welded links).
    pub offsets: Vec<Pose>,
    /// Links whose contacts count as each finger's, proximal first (thumb first).
    pub links: Vec<Vec<RigidBodyHandle>>,
    /// Links whose contacts count as the palm's (the palm first).
    pub palm_links: Vec<RigidBodyHandle>,
    /// Every joint of the model, in its order (`ImpulseJointHandle::invalid()` for the joint
    /// of a welded link).
    pub joints: Vec<ImpulseJointHandle>,
    /// Per finger, calibration offsets (domain randomization) of its coupled joints, added to
    /// their motor targets.
    pub joint_offsets: Vec<Vec<f32>>,
    /// The commands now in force, thumb first.
    pub commands: [f32; 5],
    /// How far (m) the hand, as built, reaches ahead of its grasp point along its approach
    /// axis (a thumb or a palm that stands out in front of the grasp point).
    pub reach: f32,
    /// The point (palm frame) brought to the task's grasp location: the topology's.
    pub grasp_point: Vec3,
    pub model: Arc<HandModel>,
}

fn hand_groups() -> InteractionGroups {
    InteractionGroups::new(
        HAND_GROUP,
        OBJECT_GROUP | TABLE_GROUP,
        InteractionTestMode::And,
    )
}

impl Hand {
    /// Builds `model` with its palm at `pose`, preshaped for `topology`.
    pub fn build(
        world: &mut PhysicsWorld,
        model: &Arc<HandModel>,
        pose: Pose,
        topology: Topology,
        joint_offsets: Vec<Vec<f32>>,
        hooks: ActiveHooks,
    ) -> Self {
        let shape = model.shape(topology);
        let commands: [f32; 5] = model
            .relaxed
            .unwrap_or_else(|| std::array::from_fn(|i| shape[i].preshape));
        let mut angles = vec![0.0; model.joints.len()];
        for &(j, angle) in model.held(topology) {
            angles[j] = angle;
        }
        for (f, finger) in model.fingers.iter().enumerate() {
            for &(j, ratio, offset) in &finger.coupled {
                angles[j] = ratio * commands[f] + offset;
            }
        }
        // Forward kinematics at the preshape: each child from its parent through the joint.
        let mut poses = vec![pose; model.links.len()];
        for (joint, angle) in model.joints.iter().zip(&angles) {
            poses[joint.child] = poses[joint.parent]
                * joint.frame1
                * Pose::from_rotation(Rotation::from_rotation_x(*angle))
                * joint.frame2.inverse();
        }
        let mut targets = angles;
        for (finger, offsets) in model.fingers.iter().zip(&joint_offsets) {
            for (&(j, _, _), offset) in finger.coupled.iter().zip(offsets) {
                targets[j] += offset;
            }
        }
        // Insertion order: the mount, the palm and the wrist, then each link with the joint
        // that holds it (joint k holds link k + 1), depth first.
        let mount = world.insert_body(RigidBodyBuilder::kinematic_position_based().pose(pose));
        // A link fixed to its parent, or moved by a joint the topology holds (a spread, the
        // thumb's opposition), is welded into its parent's body: light links held by impulse
        // joints between heavy ones sag and swing (the SVH holds its 130 g fingers through
        // 24 g spread links and three 10 g fixed ones), where the description means them
        // rigid and the topology keeps them still.
        let held: Vec<usize> = model.held(topology).iter().map(|&(j, _)| j).collect();
        let mut roots = Vec::with_capacity(model.links.len());
        let mut offsets: Vec<Pose> = Vec::with_capacity(model.links.len());
        for i in 0..model.links.len() {
            let parent = (i > 0
                && (model.joints[i - 1].kind == JointKind::Fixed || held.contains(&(i - 1))))
            .then(|| model.joints[i - 1].parent);
            match parent {
                Some(parent) => {
                    roots.push(roots[parent]);
                    offsets.push(offsets[parent] * poses[parent].inverse() * poses[i]);
                }
                None => {
                    roots.push(i);
                    offsets.push(Pose::IDENTITY);
                }
            }
        }
        // Mass a body's colliders do not carry: a link without shapes (a knuckle between two
        // joints) still needs mass and inertia, or the solver holds it as immovable (a 1 cm
        // sphere of its mass); the rotor inertia of the joint that moves a link (MuJoCo's
        // armature), on every axis, since impulse joints have no joint-space inertia.
        let mut extra: Vec<Option<MassProperties>> = vec![None; model.links.len()];
        for (i, link) in model.links.iter().enumerate() {
            let armature = if i > 0 {
                model.joints[i - 1].armature
            } else {
                0.0
            };
            let at = offsets[i].translation;
            let props = if link.shapes.is_empty() {
                let mass = if link.mass > 0.0 {
                    link.mass
                } else {
                    SHAPELESS_MASS
                };
                let inertia = 0.4 * mass * 0.01 * 0.01 + armature;
                MassProperties::new(at, mass, Vec3::splat(inertia))
            } else if armature > 0.0 {
                MassProperties::new(at, 0.0, Vec3::splat(armature))
            } else {
                continue;
            };
            let slot = &mut extra[roots[i]];
            *slot = Some(match slot.take() {
                Some(sum) => sum + props,
                None => props,
            });
        }
        let mut bodies: Vec<RigidBodyHandle> = Vec::with_capacity(model.links.len());
        let mut joints = Vec::with_capacity(model.joints.len());
        for (i, (link, pose)) in model.links.iter().zip(&poses).enumerate() {
            let body = if roots[i] == i {
                let mut builder = RigidBodyBuilder::dynamic().pose(*pose).gravity_scale(0.0);
                if let Some(props) = extra[i] {
                    builder = builder.additional_mass_properties(props);
                }
                world.insert_body(builder)
            } else {
                bodies[roots[i]]
            };
            let volumes: Vec<f32> = link
                .shapes
                .iter()
                .map(|(_, shape)| shape.mass_properties(1.0).mass())
                .collect();
            let total: f32 = volumes.iter().sum();
            for ((local, shape), volume) in link.shapes.iter().zip(&volumes) {
                let mut collider = ColliderBuilder::new(shape.clone())
                    .position(offsets[i] * *local)
                    .friction(model.friction)
                    .active_hooks(hooks)
                    .collision_groups(hand_groups());
                if link.mass > 0.0 && total > 0.0 {
                    collider = collider.mass(link.mass * volume / total);
                }
                world.insert_collider(collider, Some(body));
            }
            bodies.push(body);
            if i == 0 {
                let mut wrist = GenericJointBuilder::new(JointAxesMask::ANG_AXES);
                for axis in [JointAxis::LinX, JointAxis::LinY, JointAxis::LinZ] {
                    wrist = wrist
                        .motor_model(axis, MotorModel::ForceBased)
                        .motor_position(axis, 0.0, model.wrist.stiffness, model.wrist.damping)
                        .motor_max_force(axis, model.wrist.max_force);
                }
                world.insert_impulse_joint(mount, body, wrist);
                continue;
            }
            let joint = &model.joints[i - 1];
            if roots[i] != i {
                joints.push(ImpulseJointHandle::invalid());
                continue;
            }
            let data = match joint.kind {
                // A model holds no other kind (`HandModel::new` refuses them).
                JointKind::Fixed | JointKind::Other => {
                    GenericJointBuilder::new(JointAxesMask::LOCKED_FIXED_AXES)
                }
                JointKind::Revolute => {
                    let mut builder = GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES);
                    if let Some(limits) = joint.limits {
                        builder = builder.limits(JointAxis::AngX, limits);
                    }
                    builder
                        .motor_model(JointAxis::AngX, MotorModel::ForceBased)
                        .motor_position(
                            JointAxis::AngX,
                            targets[i - 1],
                            model.motor.stiffness,
                            model.motor.damping,
                        )
                        .motor_max_force(JointAxis::AngX, joint.torque)
                }
            }
            .local_frame1(offsets[joint.parent] * joint.frame1)
            .local_frame2(joint.frame2);
            joints.push(world.insert_impulse_joint(bodies[joint.parent], body, data));
        }
        let palm = bodies[0];
        let links = model
            .fingers
            .iter()
            .map(|f| f.links.iter().map(|&l| bodies[l]).collect())
            .collect();
        let palm_links = model.palm_links.iter().map(|&l| bodies[l]).collect();
        let to_palm = pose.inverse();
        let axis = model.approach_axis;
        let grasp_point = model.grasp_point_of(topology);
        let mut reach = 0.0f32;
        for body in bodies.iter().filter_map(|&b| world.bodies.get(b)) {
            for collider in body
                .colliders()
                .iter()
                .filter_map(|&c| world.colliders.get(c))
            {
                let aabb = collider
                    .shape()
                    .compute_aabb(&(to_palm * *collider.position()));
                let ahead: f32 = (0..3)
                    .map(|i| (aabb.mins[i] * axis[i]).max(aabb.maxs[i] * axis[i]))
                    .sum();
                reach = reach.max(ahead - grasp_point.dot(axis));
            }
        }
        Self {
            mount,
            palm,
            bodies,
            offsets,
            links,
            palm_links,
            joints,
            joint_offsets,
            commands,
            reach,
            grasp_point,
            model: model.clone(),
        }
    }

    /// Sets one finger's command (clamped to its range); the coupled joints follow.
    pub fn set_command(&mut self, world: &mut PhysicsWorld, finger: usize, command: f32) {
        let finger_model = &self.model.fingers[finger];
        let [lo, hi] = finger_model.range;
        let command = command.clamp(lo, hi);
        self.commands[finger] = command;
        for (k, &(j, ratio, offset)) in finger_model.coupled.iter().enumerate() {
            let calibration = self
                .joint_offsets
                .get(finger)
                .and_then(|o| o.get(k))
                .copied()
                .unwrap_or(0.0);
            if let Some(joint) = world.impulse_joints.get_mut(self.joints[j], true) {
                joint.data.set_motor_position(
                    JointAxis::AngX,
                    ratio * command + offset + calibration,
                    self.model.motor.stiffness,
                    self.model.motor.damping,
                );
            }
        }
    }

    /// The angle of a model joint now (rad), from its bodies' poses.
    pub fn joint_angle(&self, world: &PhysicsWorld, joint: usize) -> f32 {
        let model = &self.model.joints[joint];
        let pose = |link: usize| {
            world
                .bodies
                .get(self.bodies[link])
                .map(|b| *b.position() * self.offsets[link])
                .unwrap_or_default()
        };
        let frame1 = pose(model.parent) * model.frame1;
        let frame2 = pose(model.child) * model.frame2;
        let (axis, angle) = (frame1.rotation.inverse() * frame2.rotation).to_axis_angle();
        // `to_axis_angle` gives [0, 2 pi): a small negative turn comes as nearly 2 pi.
        let angle = if angle > std::f32::consts::PI {
            angle - std::f32::consts::TAU
        } else {
            angle
        };
        angle * axis.x.signum()
    }

    /// Where the arm holds the hand (the mount's pose).
    pub fn mount_pose(&self, world: &PhysicsWorld) -> Pose {
        world
            .bodies
            .get(self.mount)
            .map(|b| *b.position())
            .unwrap_or_default()
    }

    /// The palm's pose (it lags the mount by the wrist's compliance).
    pub fn palm_pose(&self, world: &PhysicsWorld) -> Pose {
        world
            .bodies
            .get(self.palm)
            .map(|b| *b.position())
            .unwrap_or_default()
    }

    /// The grasp point of the hand (its topology's) in the world.
    pub fn grasp_point(&self, world: &PhysicsWorld) -> Vec3 {
        self.palm_pose(world).transform_point(self.grasp_point)
    }

    /// Which finger (thumb first) and link (proximal first) `body` is, if it is a finger link.
    pub fn link_of(&self, body: RigidBodyHandle) -> Option<(usize, usize)> {
        self.links
            .iter()
            .enumerate()
            .find_map(|(f, links)| links.iter().position(|&l| l == body).map(|k| (f, k)))
    }

    /// Whether `body` counts as the palm.
    pub fn is_palm(&self, body: RigidBodyHandle) -> bool {
        self.palm_links.contains(&body)
    }

    /// The model's name of a hand body.
    pub fn link_name(&self, body: RigidBodyHandle) -> Option<&str> {
        self.bodies
            .iter()
            .position(|&b| b == body)
            .map(|i| self.model.links[i].name.as_str())
    }

    /// Moves the mount to `translation` (and turns it to `rotation`) at the end of the next
    /// physics step.
    pub fn move_mount(
        &self,
        world: &mut PhysicsWorld,
        translation: Vec3,
        rotation: Option<Rotation>,
    ) {
        if let Some(body) = world.bodies.get_mut(self.mount) {
            match rotation {
                Some(rotation) => {
                    body.set_next_kinematic_position(Pose::from_parts(translation, rotation))
                }
                None => body.set_next_kinematic_translation(translation),
            }
        }
    }
}
