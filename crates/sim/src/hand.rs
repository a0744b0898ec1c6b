//! The five-finger hand: a palm on a compliant Cartesian wrist and five motor-driven fingers
//! with the paper's joint coupling (section IV-B).
//!
//! Hand frame: the palm faces -z, the fingers point along +x and flex towards -z; the thumb
//! opposes them from the proximal edge, pointing along -x, and flexes down towards them. The palm follows a kinematic
//! mount (the arm, whose IK is abstracted) through a joint with bounded linear motor force, so
//! pressing and pulling forces are bounded as an arm's are; orientation is locked. Hand links
//! ignore gravity (the arm and finger motors compensate their own weight).

use rapier3d::prelude::*;

use crate::benchmark::FingerShape;

/// `alpha_DIP` for index, middle, ring, little (paper, section IV-B).
pub const ALPHA_DIP: [f32; 4] = [0.77, 0.75, 0.75, 0.57];
/// `alpha_MCP` for all fingers (paper, section IV-B).
pub const ALPHA_MCP: f32 = 0.67;
/// `alpha_TMCP`: thumb IP = 0.5 * TMCP (paper, section IV-B).
pub const ALPHA_TMCP: f32 = 0.5;
/// Largest PIP (thumb: TMCP) command, radians.
pub const MAX_FLEX: f32 = 1.7;
/// Largest thumb TMCP command, radians.
pub const MAX_THUMB_FLEX: f32 = 2.1;

/// Largest command of a finger (thumb first).
pub fn max_flex(finger: usize) -> f32 {
    if finger == 0 {
        MAX_THUMB_FLEX
    } else {
        MAX_FLEX
    }
}

/// The point of the hand that goes to the grasp location, in the hand frame: the centre of
/// the space the fingers close around.
pub const GRASP_POINT: [f32; 3] = [0.0, THUMB_Y, -0.04];

/// The thumb sits across from the index and middle fingers, as a human thumb opposes them.
const THUMB_Y: f32 = 0.02;
const PALM_HALF: [f32; 3] = [0.045, 0.042, 0.012];
const PALM_MASS: f32 = 0.4;
const HAND_FRICTION: f32 = 1.0;
const WRIST_STIFFNESS: f32 = 2500.0;
const WRIST_DAMPING: f32 = 80.0;
const WRIST_MAX_FORCE: f32 = 50.0;
const FINGER_STIFFNESS: f32 = 3.0;
const FINGER_DAMPING: f32 = 0.06;

/// Collision group of hand colliders.
pub const HAND_GROUP: Group = Group::GROUP_1;
/// Collision group of the object.
pub const OBJECT_GROUP: Group = Group::GROUP_2;
/// Collision group of the table.
pub const TABLE_GROUP: Group = Group::GROUP_3;

struct LinkSpec {
    length: f32,
    radius: f32,
    mass: f32,
    max_torque: f32,
}

struct ChainSpec {
    /// Joint of the first link, in the hand frame.
    base: [f32; 3],
    /// Rotation about the hand's y axis giving the straight chain's direction (0: along +x).
    base_pitch: f32,
    /// +1: flexion about +y (fingers); -1: about -y (thumb).
    axis_sign: f32,
    links: Vec<LinkSpec>,
}

fn link(length: f32, radius: f32, mass: f32, max_torque: f32) -> LinkSpec {
    LinkSpec {
        length,
        radius,
        mass,
        max_torque,
    }
}

fn chains() -> [ChainSpec; 5] {
    let finger = |y: f32, scale: f32| ChainSpec {
        base: [PALM_HALF[0], y, -0.004],
        base_pitch: 0.0,
        axis_sign: 1.0,
        links: vec![
            link(0.045 * scale, 0.0085, 0.03, 0.6),
            link(0.028 * scale, 0.008, 0.02, 0.4),
            link(0.022 * scale, 0.0075, 0.015, 0.2),
        ],
    };
    [
        ChainSpec {
            // Opposite the fingers at the proximal edge, pointing back; it flexes down and
            // forward, so an open hand is flat and clears low objects.
            base: [-PALM_HALF[0], THUMB_Y, -0.004],
            base_pitch: std::f32::consts::PI,
            axis_sign: -1.0,
            links: vec![link(0.05, 0.0095, 0.04, 1.0), link(0.04, 0.009, 0.02, 0.5)],
        },
        finger(0.03, 1.0),
        finger(0.01, 1.05),
        finger(-0.01, 1.0),
        finger(-0.03, 0.85),
    ]
}

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
    /// All hand bodies: the palm first, then each finger's links proximal to distal.
    pub bodies: Vec<RigidBodyHandle>,
    /// Finger links per finger, proximal first (thumb first).
    pub links: Vec<Vec<RigidBodyHandle>>,
    /// Joints per finger, proximal first.
    pub joints: Vec<Vec<ImpulseJointHandle>>,
    /// Per-joint calibration offsets (domain randomization), added to every motor target.
    pub joint_offsets: Vec<Vec<f32>>,
    /// The PIP (thumb: TMCP) commands now in force.
    pub commands: [f32; 5],
}

fn hand_groups() -> InteractionGroups {
    InteractionGroups::new(
        HAND_GROUP,
        OBJECT_GROUP | TABLE_GROUP,
        InteractionTestMode::And,
    )
}

impl Hand {
    /// Builds the hand at `pose` (hand frame in the world) with the given finger shape.
    pub fn build(
        world: &mut PhysicsWorld,
        pose: Pose,
        shape: &[FingerShape; 5],
        joint_offsets: Vec<Vec<f32>>,
        hooks: ActiveHooks,
    ) -> Self {
        let mount = world.insert_body(RigidBodyBuilder::kinematic_position_based().pose(pose));
        let palm_body = RigidBodyBuilder::dynamic().pose(pose).gravity_scale(0.0);
        let palm_collider = ColliderBuilder::cuboid(PALM_HALF[0], PALM_HALF[1], PALM_HALF[2])
            .mass(PALM_MASS)
            .friction(HAND_FRICTION)
            .active_hooks(hooks)
            .collision_groups(hand_groups());
        let (palm, _) = world.insert(palm_body, palm_collider);
        let mut wrist = GenericJointBuilder::new(JointAxesMask::ANG_AXES);
        for axis in [JointAxis::LinX, JointAxis::LinY, JointAxis::LinZ] {
            wrist = wrist
                .motor_model(axis, MotorModel::ForceBased)
                .motor_position(axis, 0.0, WRIST_STIFFNESS, WRIST_DAMPING)
                .motor_max_force(axis, WRIST_MAX_FORCE);
        }
        world.insert_impulse_joint(mount, palm, wrist);

        let mut bodies = vec![palm];
        let mut links = Vec::new();
        let mut joints = Vec::new();
        let commands: [f32; 5] = std::array::from_fn(|i| shape[i].preshape);
        for (index, chain) in chains().iter().enumerate() {
            let angles = coupled_angles(index, commands[index]);
            let axis_frame =
                Rotation::from_rotation_z(chain.axis_sign * std::f32::consts::FRAC_PI_2);
            let mut parent = palm;
            let mut parent_anchor = Vec3::from(chain.base);
            let mut parent_rotation = Rotation::from_rotation_y(chain.base_pitch);
            // World pose of the current joint.
            let mut joint_pose = pose * Pose::from_parts(parent_anchor, parent_rotation);
            let mut finger_links = Vec::new();
            let mut finger_joints = Vec::new();
            for (k, spec) in chain.links.iter().enumerate() {
                let flex = Rotation::from_rotation_y(chain.axis_sign * angles[k]);
                let link_pose = joint_pose * Pose::from_rotation(flex);
                let body = RigidBodyBuilder::dynamic()
                    .pose(link_pose)
                    .gravity_scale(0.0);
                let collider = ColliderBuilder::capsule_x(spec.length * 0.5, spec.radius)
                    .translation(Vec3::new(spec.length * 0.5, 0.0, 0.0))
                    .mass(spec.mass)
                    .friction(HAND_FRICTION)
                    .active_hooks(hooks)
                    .collision_groups(hand_groups());
                let (handle, _) = world.insert(body, collider);
                let offset = joint_offsets
                    .get(index)
                    .and_then(|o| o.get(k))
                    .copied()
                    .unwrap_or(0.0);
                let joint = GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES)
                    .local_frame1(Pose::from_parts(
                        parent_anchor,
                        parent_rotation * axis_frame,
                    ))
                    .local_frame2(Pose::from_parts(Vec3::ZERO, axis_frame))
                    .limits(JointAxis::AngX, [-0.2, max_flex(index) + 0.3])
                    .motor_model(JointAxis::AngX, MotorModel::ForceBased)
                    .motor_position(
                        JointAxis::AngX,
                        angles[k] + offset,
                        FINGER_STIFFNESS,
                        FINGER_DAMPING,
                    )
                    .motor_max_force(JointAxis::AngX, spec.max_torque);
                finger_joints.push(world.insert_impulse_joint(parent, handle, joint));
                finger_links.push(handle);
                bodies.push(handle);
                parent = handle;
                parent_anchor = Vec3::new(spec.length, 0.0, 0.0);
                parent_rotation = Rotation::IDENTITY;
                joint_pose = link_pose * Pose::from_translation(parent_anchor);
            }
            links.push(finger_links);
            joints.push(finger_joints);
        }
        Self {
            mount,
            palm,
            bodies,
            links,
            joints,
            joint_offsets,
            commands,
        }
    }

    /// Sets one finger's PIP (thumb: TMCP) command; the coupled joints follow.
    pub fn set_command(&mut self, world: &mut PhysicsWorld, finger: usize, command: f32) {
        let command = command.clamp(0.0, max_flex(finger));
        self.commands[finger] = command;
        let chain = chains();
        for (k, angle) in coupled_angles(finger, command).into_iter().enumerate() {
            let offset = self
                .joint_offsets
                .get(finger)
                .and_then(|o| o.get(k))
                .copied()
                .unwrap_or(0.0);
            if let Some(joint) = world.impulse_joints.get_mut(self.joints[finger][k], true) {
                joint.data.set_motor_position(
                    JointAxis::AngX,
                    angle + offset,
                    FINGER_STIFFNESS,
                    FINGER_DAMPING,
                );
                joint
                    .data
                    .set_motor_max_force(JointAxis::AngX, chain[finger].links[k].max_torque);
            }
        }
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

    /// The grasp point of the hand in the world.
    pub fn grasp_point(&self, world: &PhysicsWorld) -> Vec3 {
        self.palm_pose(world)
            .transform_point(Vec3::from(GRASP_POINT))
    }

    /// Which finger (thumb first) and link (proximal first) `body` is, if it is a finger link.
    pub fn link_of(&self, body: RigidBodyHandle) -> Option<(usize, usize)> {
        self.links
            .iter()
            .enumerate()
            .find_map(|(f, links)| links.iter().position(|&l| l == body).map(|k| (f, k)))
    }

    /// Moves the mount to `translation` at the end of the next physics step.
    pub fn move_mount(&self, world: &mut PhysicsWorld, translation: Vec3) {
        if let Some(body) = world.bodies.get_mut(self.mount) {
            body.set_next_kinematic_translation(translation);
        }
    }
}
