//! [`HandModel`]: a description and its profile checked against each other once, kept in
//! memory so that every reset builds the hand without reading a file.

use std::collections::BTreeMap;
use std::path::Path;

use rapier3d::prelude::*;

use super::description::{Description, JointKind, Source};
pub use super::finger::FingerModel;
use super::finger::{beyond_limits, finger_model};
use super::names::did_you_mean;
use super::profile::{Motor, Profile, Wrist};
use crate::error::{Error, Result};
use crate::taxonomy::{FINGERS, FingerShape, Topology};

/// A link of the hand: its pose at rest in the palm frame, shapes and mass.
#[derive(Clone, Debug)]
pub struct ModelLink {
    pub name: String,
    pub rest: Pose,
    pub shapes: Vec<(Pose, SharedShape)>,
    pub mass: f32,
    /// The description's visual meshes (viewers draw them instead of the shapes).
    pub visuals: Vec<super::description::VisualMesh>,
}

/// A joint of the hand, parent before child (indices into [`HandModel::links`]).
#[derive(Clone, Debug)]
pub struct ModelJoint {
    pub name: String,
    pub kind: JointKind,
    pub parent: usize,
    pub child: usize,
    pub frame1: Pose,
    pub frame2: Pose,
    pub limits: Option<[f32; 2]>,
    /// Motor torque limit (N m).
    pub torque: f32,
    /// Rotor inertia (kg m²) the child link carries: the description's `armature`, or the
    /// profile's `motor.armature` where it gives one.
    pub armature: f32,
}

/// A hand ready to be built at any pose: links, joints, the finger actions and the shapes of
/// the six topologies.
#[derive(Clone, Debug)]
pub struct HandModel {
    pub source: Source,
    /// Link 0 is the palm.
    pub links: Vec<ModelLink>,
    pub joints: Vec<ModelJoint>,
    pub fingers: [FingerModel; 5],
    /// Links whose contacts count as the palm's (the palm first).
    pub palm_links: Vec<usize>,
    /// The point (palm frame) a task's grasp location is for, unless the topology has its own
    /// ([`HandModel::grasp_point_of`]).
    pub grasp_point: Vec3,
    /// Topologies' own grasp points (palm frame).
    topology_grasp_points: BTreeMap<Topology, Vec3>,
    /// The palm's orientation in the world at a task's zero yaw.
    pub base_rotation: Rotation,
    /// The frame a task's grasp orientation places, in the palm frame (profile `grasp_frame`).
    pub grasp_frame: Rotation,
    /// The direction the palm approaches along, in the palm frame (unit).
    pub approach_axis: Vec3,
    /// Commands held through the approach (profile `relaxed`), if the hand preshapes late.
    pub relaxed: Option<[f32; 5]>,
    pub friction: f32,
    pub wrist: Wrist,
    pub motor: Motor,
    shapes: BTreeMap<Topology, [FingerShape; 5]>,
    /// Per topology, the angle of every joint no finger commands.
    held: BTreeMap<Topology, Vec<(usize, f32)>>,
    /// The profile's couplings against the description's (`crm world check` refuses the
    /// conflicts it does not override).
    pub couplings: super::couplings::Couplings,
}

fn finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

/// `[x, y, z, w]` as a rotation, if finite and of norm 1 (within 1e-3).
pub fn unit_quaternion(q: [f32; 4]) -> Option<Rotation> {
    let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    (finite(&q) && (norm - 1.0).abs() <= 1e-3)
        .then(|| Rotation::from_xyzw(q[0], q[1], q[2], q[3]).normalize())
}

impl HandModel {
    /// Checks `profile` against `description`; `path` (the profile's file) names errors.
    pub fn new(description: &Description, profile: &Profile, path: &Path) -> Result<Self> {
        let invalid = |at: String, message: String| Error::Invalid {
            path: path.display().to_string(),
            at,
            message,
        };
        let palm = description.link(&profile.palm).ok_or_else(|| {
            invalid(
                "palm".into(),
                format!(
                    "the description has no link {:?}{}",
                    profile.palm,
                    did_you_mean(
                        &profile.palm,
                        description.links.iter().map(|l| l.name.as_str())
                    )
                ),
            )
        })?;
        // The palm's subtree, depth first in the description's order; joint k holds link
        // k + 1 to its parent, and a hand is built in this order.
        let mut order = vec![palm];
        let mut joints_in = Vec::new();
        subtree(description, palm, &mut order, &mut joints_in);
        let palm_rest = description.links[palm].rest;
        let links: Vec<ModelLink> = order
            .iter()
            .map(|&l| {
                let link = &description.links[l];
                ModelLink {
                    name: link.name.clone(),
                    rest: palm_rest.inverse() * link.rest,
                    shapes: link.shapes.clone(),
                    mass: link.mass,
                    visuals: link.visuals.clone(),
                }
            })
            .collect();
        let link_index = |name: &str| links.iter().position(|l| l.name == name);
        let link_names: Vec<String> = links.iter().map(|l| l.name.clone()).collect();
        let position = |l: usize| order.iter().position(|&o| o == l).unwrap_or(0);
        let joints: Vec<ModelJoint> = joints_in
            .iter()
            .map(|&j| {
                let joint = &description.joints[j];
                ModelJoint {
                    name: joint.name.clone(),
                    kind: joint.kind,
                    parent: position(joint.parent),
                    child: position(joint.child),
                    frame1: joint.frame1,
                    frame2: joint.frame2,
                    limits: joint.limits,
                    torque: profile.motor.torque,
                    armature: profile.motor.armature.unwrap_or(joint.armature),
                }
            })
            .collect();
        let mut model_joints = joints;
        if let Some(joint) = model_joints.iter().find(|j| j.kind == JointKind::Other) {
            return Err(invalid(
                "palm".into(),
                format!(
                    "joint {:?} below the palm is neither revolute (hinge) nor fixed; a hand \
                     holds only those",
                    joint.name
                ),
            ));
        }
        let joint_index =
            |joints: &[ModelJoint], name: &str| joints.iter().position(|j| j.name == name);

        for (value, field) in [
            (profile.friction, "friction"),
            (profile.wrist.stiffness, "wrist.stiffness"),
            (profile.wrist.damping, "wrist.damping"),
            (profile.wrist.max_force, "wrist.max_force"),
            (profile.motor.stiffness, "motor.stiffness"),
            (profile.motor.damping, "motor.damping"),
            (profile.motor.torque, "motor.torque"),
            (profile.motor.armature.unwrap_or(0.0), "motor.armature"),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(invalid(
                    field.into(),
                    format!("must be finite and >= 0, got {value}"),
                ));
            }
        }
        let axis = |v: [f32; 3], field: &str| {
            let v = Vec3::from(v);
            if finite(&v.to_array()) && v.length() > 1e-6 {
                Ok(v.normalize())
            } else {
                Err(invalid(
                    field.into(),
                    "must be a finite, non-zero vector".into(),
                ))
            }
        };
        let approach = axis(profile.approach_axis, "approach_axis")?;
        let along = axis(profile.finger_axis, "finger_axis")?;
        if approach.dot(along).abs() > 1e-3 {
            return Err(invalid(
                "finger_axis".into(),
                "must be perpendicular to approach_axis".into(),
            ));
        }
        if !finite(&profile.grasp_point) {
            return Err(invalid("grasp_point".into(), "must be finite".into()));
        }
        let grasp_frame = match profile.grasp_frame {
            None => Rotation::IDENTITY,
            Some(q) => unit_quaternion(q).ok_or_else(|| {
                invalid(
                    "grasp_frame".into(),
                    "must be a unit quaternion [x, y, z, w]".into(),
                )
            })?,
        };

        let mut fingers = Vec::new();
        let mut commanded = Vec::new();
        for (f, finger) in profile.fingers.all().into_iter().enumerate() {
            let at = format!("fingers.{}", FINGERS[f]);
            let Some(finger) = finger else {
                fingers.push(FingerModel::absent());
                continue;
            };
            fingers.push(finger_model(
                f,
                finger,
                &at,
                description,
                &mut model_joints,
                &link_index,
                &link_names,
                &invalid,
            )?);
            commanded.extend(fingers[f].coupled.iter().map(|c| c.0));
            if joint_index(&model_joints, &finger.command).is_none() {
                return Err(invalid(
                    format!("{at}.command"),
                    format!(
                        "the hand has no joint {:?} below the palm{}",
                        finger.command,
                        did_you_mean(
                            &finger.command,
                            model_joints.iter().map(|j| j.name.as_str())
                        )
                    ),
                ));
            }
        }
        let fingers: [FingerModel; 5] = fingers
            .try_into()
            .map_err(|_| invalid("fingers".into(), "five fingers".into()))?;

        let mut palm_links = vec![0];
        for (k, name) in profile.palm_links.iter().enumerate() {
            let link = link_index(name).ok_or_else(|| {
                invalid(
                    format!("palm_links[{k}]"),
                    format!(
                        "the hand has no link {name:?}{}",
                        did_you_mean(name, link_names.iter().map(String::as_str))
                    ),
                )
            })?;
            palm_links.push(link);
        }

        let finger_index = |name: &str, at: &str| {
            let f = FINGERS.iter().position(|f| *f == name).ok_or_else(|| {
                invalid(
                    at.to_string(),
                    format!("unknown finger {name:?}; one of {FINGERS:?}"),
                )
            })?;
            if !fingers[f].present {
                return Err(invalid(
                    at.to_string(),
                    format!(
                        "the hand has no {name} finger (the profile's `fingers` leaves it out); \
                         a topology of this hand uses only the fingers it has"
                    ),
                ));
            }
            Ok(f)
        };
        // A command by finger name at `at`: the finger, if the value is within its range.
        let command = |name: &str, value: f32, at: &str| {
            let f = finger_index(name, at)?;
            let [lo, hi] = fingers[f].range;
            if !(value.is_finite() && value >= lo.min(hi) && value <= lo.max(hi)) {
                return Err(invalid(
                    format!("{at}.{name}"),
                    format!(
                        "must be within the finger's range {:?}, got {value}",
                        fingers[f].range
                    ),
                ));
            }
            Ok(f)
        };
        let relaxed = if profile.relaxed.is_empty() {
            None
        } else {
            let mut commands = [0.0; 5];
            for (name, &value) in &profile.relaxed {
                commands[command(name, value, "relaxed")?] = value;
            }
            Some(commands)
        };
        let mut shapes = BTreeMap::new();
        let mut held = BTreeMap::new();
        let mut topology_grasp_points = BTreeMap::new();
        for topology in Topology::ALL {
            let at = format!("topologies.{}", topology.name());
            let Some(shape) = profile.topologies.get(&topology) else {
                return Err(invalid(at, "every topology needs a shape".into()));
            };
            let mut fingers_shape = [FingerShape {
                active: false,
                preshape: 0.0,
                closed: 0.0,
            }; 5];
            for name in &shape.active {
                fingers_shape[finger_index(name, &format!("{at}.active"))?].active = true;
            }
            if let Some(point) = shape.grasp_point {
                if !finite(&point) {
                    return Err(invalid(
                        format!("{at}.grasp_point"),
                        "must be finite".into(),
                    ));
                }
                topology_grasp_points.insert(topology, Vec3::from(point));
            }
            for (field, values) in [("preshape", &shape.preshape), ("closed", &shape.closed)] {
                for (name, &value) in values {
                    let f = command(name, value, &format!("{at}.{field}"))?;
                    if field == "preshape" {
                        fingers_shape[f].preshape = value;
                    } else {
                        fingers_shape[f].closed = value;
                    }
                }
            }
            let mut angles: Vec<(usize, f32)> = model_joints
                .iter()
                .enumerate()
                .filter(|(j, joint)| joint.kind == JointKind::Revolute && !commanded.contains(j))
                .map(|(j, _)| (j, 0.0))
                .collect();
            for (field, values) in [
                ("held", &profile.held),
                (&*format!("{at}.held"), &shape.held),
            ] {
                for (name, &value) in values {
                    let Some(j) = joint_index(&model_joints, name) else {
                        return Err(invalid(
                            format!("{field}.{name}"),
                            format!(
                                "the hand has no joint {name:?} below the palm{}",
                                did_you_mean(name, model_joints.iter().map(|j| j.name.as_str()))
                            ),
                        ));
                    };
                    let Some(entry) = angles.iter_mut().find(|(k, _)| *k == j) else {
                        return Err(invalid(
                            format!("{field}.{name}"),
                            "a finger commands this joint; it cannot also be held".into(),
                        ));
                    };
                    if !value.is_finite() {
                        return Err(invalid(format!("{field}.{name}"), "must be finite".into()));
                    }
                    if let Some(message) = beyond_limits(&model_joints[j], value) {
                        return Err(invalid(
                            format!("{field}.{name}"),
                            format!("{value} is {message}"),
                        ));
                    }
                    entry.1 = value;
                }
            }
            // A joint nobody holds explicitly is held at 0, which must lie in its limits too.
            if let Some((j, message)) = angles
                .iter()
                .find_map(|&(j, value)| Some((j, beyond_limits(&model_joints[j], value)?)))
            {
                let name = &model_joints[j].name;
                return Err(invalid(
                    format!("held.{name}"),
                    format!(
                        "no finger commands this joint, so it is held at 0, which is {message}; hold it within them in `held`"
                    ),
                ));
            }
            shapes.insert(topology, fingers_shape);
            held.insert(topology, angles);
        }
        if let Some(name) = profile
            .topologies
            .keys()
            .find(|t| !Topology::ALL.contains(t))
        {
            return Err(invalid(
                format!("topologies.{}", name.name()),
                "unknown topology".into(),
            ));
        }

        // Rows of the palm's world rotation at zero yaw: fingers along +x, approach along -z.
        let side = (-approach).cross(along);
        let base_rotation =
            if (along - Vec3::X).length() < 1e-7 && (approach + Vec3::Z).length() < 1e-7 {
                Rotation::IDENTITY
            } else {
                // The rotation taking the palm frame's (along, side, -approach) to world (x, y, z).
                Rotation::from_mat3(
                    &rapier3d::math::Matrix::from_cols(along, side, -approach).transpose(),
                )
            };
        for (k, name) in profile.description_overrides.iter().enumerate() {
            if description.joint(name).is_none() {
                return Err(invalid(
                    format!("description_overrides[{k}]"),
                    format!(
                        "the description has no joint {name:?}{}",
                        did_you_mean(name, description.joints.iter().map(|j| j.name.as_str()))
                    ),
                ));
            }
        }
        Ok(Self {
            source: description.source,
            links,
            joints: model_joints,
            fingers,
            palm_links,
            grasp_point: Vec3::from(profile.grasp_point),
            topology_grasp_points,
            base_rotation,
            grasp_frame,
            approach_axis: approach,
            relaxed,
            friction: profile.friction,
            wrist: profile.wrist,
            motor: profile.motor,
            shapes,
            held,
            couplings: super::couplings::Couplings::default(),
        })
        .map(|mut model| {
            model.couplings = super::couplings::check(description, profile, &model);
            model
        })
    }

    /// The topology's finger shapes, thumb first.
    pub fn shape(&self, topology: Topology) -> [FingerShape; 5] {
        self.shapes.get(&topology).copied().unwrap_or(
            [FingerShape {
                active: false,
                preshape: 0.0,
                closed: 0.0,
            }; 5],
        )
    }

    /// The point (palm frame) that `topology` brings to a task's grasp location.
    pub fn grasp_point_of(&self, topology: Topology) -> Vec3 {
        self.topology_grasp_points
            .get(&topology)
            .copied()
            .unwrap_or(self.grasp_point)
    }

    /// The joints held still in `topology` and their angles.
    pub fn held(&self, topology: Topology) -> &[(usize, f32)] {
        self.held.get(&topology).map_or(&[], Vec::as_slice)
    }

    /// The most closed command of a finger.
    pub fn max_command(&self, finger: usize) -> f32 {
        self.fingers[finger].range[1]
    }

    /// How many joints move (revolute ones).
    pub fn revolute_joints(&self) -> usize {
        self.joints
            .iter()
            .filter(|j| j.kind == JointKind::Revolute)
            .count()
    }
}

fn subtree(
    description: &Description,
    link: usize,
    order: &mut Vec<usize>,
    joints: &mut Vec<usize>,
) {
    for (j, joint) in description.joints.iter().enumerate() {
        if joint.parent == link && !order.contains(&joint.child) {
            order.push(joint.child);
            joints.push(j);
            subtree(description, joint.child, order, joints);
        }
    }
}
