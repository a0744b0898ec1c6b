//! A robot description (URDF through `rapier3d-urdf`, MJCF through `rapier3d-mjcf`) read into
//! plain links and joints: each link's rest pose, collision shapes and mass, each joint's frames
//! and limits. Nothing here is inserted into a physics world; [`super::HandModel`] builds hands
//! from it at every reset.
//!
//! Both loaders are wrapped where they would be silent or wrong (measured with 0.36.1):
//! `rapier3d-urdf` joins `package://` paths to a folder as plain text and drops a mesh it
//! cannot open without a word, `rapier3d-mjcf` skips a mesh it cannot find with a log line and
//! refuses files whose `<include>`d parts have `<mujocoinclude>` roots, and both read `nan` as
//! a number. Mesh paths are resolved here (see [`crate::assets`], `meshes.rs`) and a missing
//! mesh is an error naming it; includes are expanded (`includes.rs`) before the MJCF is parsed;
//! numbers are checked in every file read (`numbers.rs`); a file that is only a part of a model
//! is refused, naming the files that include it.

use std::path::Path;

use rapier3d::prelude::*;
use rapier3d_mjcf::mjcf_rs::Model;
use rapier3d_mjcf::{MjcfLoaderOptions, MjcfRobot};
use rapier3d_urdf::{UrdfLoaderOptions, UrdfRobot, urdf_rs};
use sha2::{Digest, Sha256};

use super::includes::{Expansion, add_content, fragment_reason, includers};
use super::meshes::resolve as resolve_meshes;
use super::numbers::{self, Format};
use crate::assets::Assets;
use crate::error::{Error, Result, invalid_at as invalid, read_text as read};

/// Which format a description came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    Urdf,
    Mjcf,
}

/// One rigid link: its pose at rest (all joints at zero) in the description's frame, its
/// collision shapes in the link frame, and its mass.
#[derive(Clone, Debug)]
pub struct Link {
    pub name: String,
    /// A body the loader added to hold one of several joints of one description body.
    pub intermediate: bool,
    pub rest: Pose,
    pub shapes: Vec<(Pose, SharedShape)>,
    /// kg; 0 when the description gives none.
    pub mass: f32,
    /// What the description draws (meshes, in the link frame), for viewers.
    pub visuals: Vec<VisualMesh>,
}

/// A triangle mesh to draw, placed in its link's frame.
#[derive(Clone, Debug)]
pub struct VisualMesh {
    pub pose: Pose,
    pub vertices: std::sync::Arc<[[f32; 3]]>,
    pub triangles: std::sync::Arc<[[u32; 3]]>,
}

impl VisualMesh {
    /// A drawable mesh of `shape` (a triangle mesh or a convex hull), if it is one.
    pub fn of(pose: Pose, shape: &SharedShape) -> Option<Self> {
        let (vertices, triangles): (Vec<[f32; 3]>, Vec<[u32; 3]>) =
            if let Some(mesh) = shape.as_trimesh() {
                (
                    mesh.vertices().iter().map(|v| v.to_array()).collect(),
                    mesh.indices().to_vec(),
                )
            } else if let Some(hull) = shape.as_convex_polyhedron() {
                let (points, faces) = hull.to_trimesh();
                (points.iter().map(|v| v.to_array()).collect(), faces)
            } else {
                return None;
            };
        Some(Self {
            pose,
            vertices: vertices.into(),
            triangles: triangles.into(),
        })
    }
}

/// What a joint lets move.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointKind {
    /// One rotation about the x axis of both frames.
    Revolute,
    /// Nothing: the child is welded to the parent.
    Fixed,
    /// Anything else (slide, ball): kept to count, refused in a hand.
    Other,
}

/// One joint between two links (indices into [`Description::links`]).
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    pub parent: usize,
    pub child: usize,
    /// The joint frame in the parent's frame and in the child's; a revolute joint turns about
    /// their x axis.
    pub frame1: Pose,
    pub frame2: Pose,
    /// Angle limits (radians) when the description gives them.
    pub limits: Option<[f32; 2]>,
    /// A coupling the description declares (URDF `<mimic>`, MJCF `<equality><joint>` or a
    /// fixed tendon of two joints with opposite coefficients, as Adroit couples DIP to PIP):
    /// `angle = ratio * leader + offset`.
    pub mimic: Option<Mimic>,
    /// Whether the description declares it (loaders add unnamed fixed joints of their own).
    pub declared: bool,
    /// Reflected rotor inertia (kg m², MJCF `armature`; 0 where the description has none).
    pub armature: f32,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Mimic {
    pub leader: String,
    pub ratio: f32,
    pub offset: f32,
}

/// A description's links and joints.
#[derive(Clone, Debug)]
pub struct Description {
    pub source: Source,
    pub links: Vec<Link>,
    pub joints: Vec<Joint>,
    /// SHA-256 of every file the description read, by content (its text, its includes', its
    /// meshes'), in the order read: where the files lie is not in it.
    pub content: [u8; 32],
}

impl Description {
    /// Loads `path` (`.urdf` or `.xml`/`.mjcf`), resolving mesh files with `assets`.
    pub fn load(path: &Path, assets: &Assets) -> Result<Self> {
        let text = read(path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        match path.extension().and_then(|e| e.to_str()) {
            Some("urdf") => Self::from_urdf(&text, path, base, assets),
            Some("xml" | "mjcf") => Self::from_mjcf(&text, path, base, assets),
            _ => Err(invalid(
                path,
                "description",
                "a hand description is a .urdf or an MJCF .xml file",
            )),
        }
    }

    /// Parses MJCF text; `path` names it in errors, `base` (its folder) and `assets` resolve
    /// its includes and meshes.
    pub fn from_mjcf(text: &str, path: &Path, base: &Path, assets: &Assets) -> Result<Self> {
        let mut expansion = Expansion::new(base, assets);
        let expanded = expansion.expand(text, path, 0)?;
        let mut digest = expansion.digest;
        if let Some(reason) = fragment_reason(&expanded) {
            let instead: Vec<String> = includers(path)
                .iter()
                .map(|p| p.display().to_string())
                .collect();
            let hint = match instead.as_slice() {
                [] => "load the model file that includes it".to_string(),
                files => format!("load the file that includes it: {}", files.join(" or ")),
            };
            return Err(invalid(
                path,
                "mujoco",
                format!("this file is a part meant to be included ({reason}); {hint}"),
            ));
        }
        let options = MjcfLoaderOptions {
            disable_joint_motors: true,
            mesh_converter: Some(MeshConverter::ConvexHull),
            ..MjcfLoaderOptions::default()
        };
        let mut model = Model::from_str(&expanded, base)
            .map_err(|err| invalid(path, "mujoco", format!("{err:#}")))?;
        resolve_meshes(&mut model, base, assets, path, &mut digest)?;
        let robot = MjcfRobot::from_model(&model, options, base);
        let links = robot
            .bodies
            .iter()
            .enumerate()
            .map(|(i, body)| Link {
                name: body.name.clone().unwrap_or_else(|| format!("body{i}")),
                intermediate: body.is_intermediate,
                visuals: body
                    .visual_meshes
                    .iter()
                    .filter_map(|v| VisualMesh::of(v.local_pose, &v.shape))
                    .collect(),
                rest: *body.body.position(),
                shapes: shapes_of(&body.colliders),
                mass: body.mass,
            })
            .collect();
        let mut joints: Vec<Joint> = Vec::new();
        for (i, joint) in robot.joints.iter().enumerate() {
            let name = joint.name.clone().unwrap_or_else(|| format!("joint{i}"));
            let mut converted = convert_joint(name, joint.link1, joint.link2, &joint.joint);
            converted.declared = joint.name.is_some();
            converted.armature = joint.armature_per_dof;
            joints.push(converted);
        }
        for tendon in &model.tendons {
            if let [follower, leader] = tendon.joints.as_slice()
                && follower.coef * leader.coef < 0.0
                && let Some(joint) = joints.iter_mut().find(|j| j.name == follower.joint)
                && joint.mimic.is_none()
            {
                joint.mimic = Some(Mimic {
                    leader: leader.joint.clone(),
                    ratio: (-leader.coef / follower.coef) as f32,
                    offset: 0.0,
                });
            }
        }
        // `<equality><joint joint1 joint2 polycoef>` as MuJoCo defines it: joint1 follows
        // joint2, `q1 = polycoef[0] + polycoef[1] q2` (higher terms are not couplings a
        // finger's command can carry). The loader's own `joint_couplings` take joint2 as the
        // follower and add its approximation of every fixed tendon; neither is the
        // description's word.
        for equality in &model.equality {
            if let rapier3d_mjcf::mjcf_rs::equality::Equality::Joint(eq) = equality
                && eq.common.active
                && let Some(leader) = &eq.joint2
                && let Some(joint) = joints.iter_mut().find(|j| j.name == eq.joint1)
            {
                joint.mimic = Some(Mimic {
                    leader: leader.clone(),
                    ratio: eq.polycoef[1] as f32,
                    offset: eq.polycoef[0] as f32,
                });
            }
        }
        Ok(Self {
            source: Source::Mjcf,
            links,
            joints,
            content: digest.finalize().into(),
        })
    }

    /// Parses URDF text; mesh files are resolved (`package://NAME/...`, relative to `base`,
    /// or found through `assets`) before `rapier3d-urdf` sees them.
    pub fn from_urdf(text: &str, path: &Path, base: &Path, assets: &Assets) -> Result<Self> {
        numbers::check(text, path, Format::Urdf)?;
        let mut digest = Sha256::new();
        add_content(&mut digest, text.as_bytes());
        let mut robot = urdf_rs::read_from_string(text)
            .map_err(|err| invalid(path, "robot", err.to_string()))?;
        for link in &mut robot.links {
            let name = link.name.clone();
            let geometries = link
                .collision
                .iter_mut()
                .map(|c| ("collision", &mut c.geometry))
                .chain(link.visual.iter_mut().map(|v| ("visual", &mut v.geometry)));
            for (kind, geometry) in geometries {
                if let urdf_rs::Geometry::Mesh { filename, .. } = geometry {
                    let found = assets.mesh(filename, base).ok_or_else(|| {
                        invalid(
                            path,
                            format!("link {name:?} {kind} mesh"),
                            format!(
                                "mesh {filename:?} not found; searched relative to {}, its ancestors for a package://, then each CRM_ASSETS folder ({})",
                                base.display(),
                                searched_folders(assets)
                            ),
                        )
                    })?;
                    let bytes = std::fs::read(&found).map_err(|error| Error::Io {
                        path: found.display().to_string(),
                        error,
                    })?;
                    add_content(&mut digest, &bytes);
                    *filename = found.display().to_string();
                }
            }
        }
        let options = UrdfLoaderOptions {
            create_colliders_from_collision_shapes: true,
            create_colliders_from_visual_shapes: false,
            mesh_converter: Some(MeshConverter::ConvexHull),
            ..UrdfLoaderOptions::default()
        };
        let loaded = UrdfRobot::from_robot(&robot, options, Path::new("/"));
        // The visual geometry, loaded as triangle meshes, for viewers only.
        let visual_options = UrdfLoaderOptions {
            create_colliders_from_collision_shapes: false,
            create_colliders_from_visual_shapes: true,
            mesh_converter: Some(MeshConverter::TriMesh),
            ..UrdfLoaderOptions::default()
        };
        let visuals = UrdfRobot::from_robot(&robot, visual_options, Path::new("/"));
        let mut links = Vec::new();
        for link in &loaded.links {
            let source = &robot.links[link.urdf_link_index];
            let colliders: Vec<Collider> =
                link.colliders.iter().map(|c| c.collider.clone()).collect();
            let meshes = source
                .collision
                .iter()
                .filter(|c| matches!(c.geometry, urdf_rs::Geometry::Mesh { .. }))
                .count();
            if meshes > 0 && colliders.is_empty() {
                return Err(invalid(
                    path,
                    format!("link {:?} collision mesh", source.name),
                    "the mesh could not be read (empty, or not STL, OBJ or Collada)",
                ));
            }
            let drawn = visuals
                .links
                .iter()
                .find(|v| v.urdf_link_index == link.urdf_link_index)
                .map(|v| {
                    v.colliders
                        .iter()
                        .filter_map(|c| {
                            let collider = &c.collider;
                            let pose = collider
                                .position_wrt_parent()
                                .copied()
                                .unwrap_or(*collider.position());
                            VisualMesh::of(pose, collider.shared_shape())
                        })
                        .collect()
                })
                .unwrap_or_default();
            links.push(Link {
                name: source.name.clone(),
                intermediate: false,
                visuals: drawn,
                rest: *link.body.position(),
                shapes: shapes_of(&colliders),
                mass: source.inertial.mass.value as f32,
            });
        }
        let mut joints = Vec::new();
        for joint in &loaded.joints {
            let source = &robot.joints[joint.source_urdf_joint_index()];
            let mut converted =
                convert_joint(source.name.clone(), joint.link1, joint.link2, &joint.joint);
            converted.mimic = source.mimic.as_ref().map(|m| Mimic {
                leader: m.joint.clone(),
                ratio: m.multiplier.unwrap_or(1.0) as f32,
                offset: m.offset.unwrap_or(0.0) as f32,
            });
            joints.push(converted);
        }
        Ok(Self {
            source: Source::Urdf,
            links,
            joints,
            content: digest.finalize().into(),
        })
    }

    pub fn link(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    pub fn joint(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }
}

/// The `CRM_ASSETS` folders, for errors.
fn searched_folders(assets: &Assets) -> String {
    if assets.folders.is_empty() {
        "CRM_ASSETS is not set".to_string()
    } else {
        let folders: Vec<String> = assets
            .folders
            .iter()
            .map(|f| f.display().to_string())
            .collect();
        folders.join(", ")
    }
}

fn shapes_of(colliders: &[Collider]) -> Vec<(Pose, SharedShape)> {
    colliders
        .iter()
        .map(|c| {
            // A collider not yet attached to a body keeps its local pose as its position.
            (
                c.position_wrt_parent().copied().unwrap_or(*c.position()),
                super::hulls::affordable(c.shared_shape()),
            )
        })
        .collect()
}

fn convert_joint(name: String, parent: usize, child: usize, joint: &GenericJoint) -> Joint {
    let kind = if joint.locked_axes == JointAxesMask::LOCKED_REVOLUTE_AXES {
        JointKind::Revolute
    } else if joint.locked_axes == JointAxesMask::LOCKED_FIXED_AXES {
        JointKind::Fixed
    } else {
        JointKind::Other
    };
    let limits = (kind == JointKind::Revolute && joint.limit_axes.contains(JointAxesMask::ANG_X))
        .then(|| {
            let limit = joint.limits[JointAxis::AngX as usize];
            [limit.min, limit.max]
        });
    Joint {
        name,
        kind,
        parent,
        child,
        frame1: joint.local_frame1,
        frame2: joint.local_frame2,
        limits,
        mimic: None,
        declared: true,
        armature: 0.0,
    }
}
