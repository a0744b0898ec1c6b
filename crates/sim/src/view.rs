//! A read-only view of the current scene for viewers (the worker's rerun recordings): every
//! collider as a named part with its primitive shape and world pose, the hand-object contacts
//! with their forces, and the grasp location. Plain arrays, so a viewer needs no rapier types.

use crate::env::GraspEnv;

/// Finger names in the hand's order (thumb first).
pub const FINGERS: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];

/// A collider's primitive, in its own frame. Cylinders run along the local y axis (rapier's
/// convention); capsules are given by their segment's end points.
#[derive(Clone, Debug, PartialEq)]
pub enum PartShape {
    Cuboid {
        half_extents: [f32; 3],
    },
    Ball {
        radius: f32,
    },
    Capsule {
        a: [f32; 3],
        b: [f32; 3],
        radius: f32,
    },
    Cylinder {
        half_height: f32,
        radius: f32,
    },
    /// Convex pieces (a mesh object's hulls, a description's convex mesh links) as one
    /// triangle mesh in the collider's frame.
    Mesh {
        vertices: std::sync::Arc<[[f32; 3]]>,
        triangles: std::sync::Arc<[[u32; 3]]>,
    },
    /// A shape the view does not draw.
    Other,
}

/// One collider: a path-like name (`table`, `object/part_0`, `hand/palm`,
/// `hand/index/link_2`), its shape and its world pose (translation; rotation as x, y, z, w).
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    pub name: String,
    pub shape: PartShape,
    pub translation: [f32; 3],
    pub rotation: [f32; 4],
    /// Whether a viewer draws it: a collider of a link whose description has a visual mesh
    /// is listed but not drawn (the visual mesh is, as its own part).
    pub drawn: bool,
}

/// One hand-object contact point: where, and the force on the object (newtons).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactView {
    pub position: [f32; 3],
    pub force: [f32; 3],
}

fn shape_of(shape: &dyn rapier3d::parry::shape::Shape) -> PartShape {
    if let Some(c) = shape.as_cuboid() {
        PartShape::Cuboid {
            half_extents: c.half_extents.into(),
        }
    } else if let Some(b) = shape.as_ball() {
        PartShape::Ball { radius: b.radius }
    } else if let Some(c) = shape.as_capsule() {
        PartShape::Capsule {
            a: c.segment.a.into(),
            b: c.segment.b.into(),
            radius: c.radius,
        }
    } else if let Some(c) = shape.as_cylinder() {
        PartShape::Cylinder {
            half_height: c.half_height,
            radius: c.radius,
        }
    } else {
        let mut vertices: Vec<[f32; 3]> = Vec::new();
        let mut triangles: Vec<[u32; 3]> = Vec::new();
        let mut add = |pose: rapier3d::math::Pose, piece: &dyn rapier3d::parry::shape::Shape| {
            if let Some(hull) = piece.as_convex_polyhedron() {
                let (points, faces) = hull.to_trimesh();
                let first = vertices.len() as u32;
                vertices.extend(
                    points
                        .into_iter()
                        .map(|p| pose.transform_point(p).to_array()),
                );
                triangles.extend(faces.into_iter().map(|f| f.map(|i| i + first)));
            }
        };
        if let Some(compound) = shape.as_compound() {
            for (pose, piece) in compound.shapes() {
                add(*pose, piece.as_ref());
            }
        } else {
            add(rapier3d::math::Pose::IDENTITY, shape);
        }
        if triangles.is_empty() {
            PartShape::Other
        } else {
            PartShape::Mesh {
                vertices: vertices.into(),
                triangles: triangles.into(),
            }
        }
    }
}

impl GraspEnv {
    /// Every collider of the current scene, named by what it belongs to (a second collider of
    /// one body gets `_1`, ...), then the hand's visual meshes (`hand/LINK/visual_K`); empty
    /// before reset.
    pub fn parts(&self) -> Vec<Part> {
        let Some(scene) = self.scene() else {
            return Vec::new();
        };
        let hand = &scene.hand;
        let mut object_parts = 0;
        let mut parts = Vec::new();
        // How often each name was given, for the `_1`, `_2` of a body's further colliders.
        let mut names = std::collections::HashMap::new();
        for (_, collider) in scene.world.colliders.iter() {
            let name = match collider.parent() {
                None => "table".to_string(),
                Some(body) if body == scene.object => {
                    object_parts += 1;
                    format!("object/part_{}", object_parts - 1)
                }
                Some(body) if body == hand.palm => "hand/palm".to_string(),
                Some(body) => match (hand.link_of(body), hand.link_name(body)) {
                    (Some((f, k)), _) => format!("hand/{}/link_{k}", FINGERS[f]),
                    (None, Some(name)) => format!("hand/{name}"),
                    (None, None) => "other".to_string(),
                },
            };
            let seen = names.entry(name.clone()).or_insert(0);
            let name = if *seen == 0 {
                name
            } else {
                format!("{name}_{seen}")
            };
            *seen += 1;
            // A hand collider is drawn unless its body's links bring visual meshes.
            let drawn = collider.parent().is_none_or(|body| {
                hand.bodies
                    .iter()
                    .zip(&hand.model.links)
                    .all(|(&b, link)| b != body || link.visuals.is_empty())
            });
            let pose = collider.position();
            parts.push(Part {
                name,
                shape: shape_of(collider.shape()),
                translation: pose.translation.into(),
                rotation: pose.rotation.to_array(),
                drawn,
            });
        }
        for ((link, &body), offset) in hand.model.links.iter().zip(&hand.bodies).zip(&hand.offsets)
        {
            let Some(body) = scene.world.bodies.get(body) else {
                continue;
            };
            for (k, visual) in link.visuals.iter().enumerate() {
                let pose = body.position() * *offset * visual.pose;
                parts.push(Part {
                    name: format!("hand/{}/visual_{k}", link.name),
                    shape: PartShape::Mesh {
                        vertices: visual.vertices.clone(),
                        triangles: visual.triangles.clone(),
                    },
                    translation: pose.translation.into(),
                    rotation: pose.rotation.to_array(),
                    drawn: true,
                });
            }
        }
        parts
    }

    /// The hand-object contacts of the last control step.
    pub fn contacts_view(&self) -> Vec<ContactView> {
        self.hand_contacts()
            .points
            .iter()
            .map(|p| ContactView {
                position: p.position.into(),
                force: p.force.into(),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::{Benchmark, SimConfig, TaskChoice};

    #[test]
    fn every_collider_is_named_and_shaped() {
        let mut env = GraspEnv::new(Arc::new(Benchmark::builtin()), SimConfig::default());
        assert!(env.parts().is_empty());
        env.set_task_choice(TaskChoice::Fixed(0)).expect("task");
        env.reset_seeded(3).expect("reset");
        let parts = env.parts();
        let names: Vec<&str> = parts.iter().map(|p| p.name.as_str()).collect();
        assert!(names.contains(&"table"), "{names:?}");
        assert!(names.contains(&"hand/palm"), "{names:?}");
        assert!(names.contains(&"object/part_0"), "{names:?}");
        for finger in FINGERS {
            assert!(
                names
                    .iter()
                    .any(|n| n.starts_with(&format!("hand/{finger}/")))
            );
        }
        assert!(!names.contains(&"other"), "{names:?}");
        assert!(parts.iter().all(|p| p.shape != PartShape::Other));
        // Rotations are unit quaternions.
        for part in &parts {
            let norm: f32 = part.rotation.iter().map(|v| v * v).sum();
            assert!((norm - 1.0).abs() < 1e-4, "{part:?}");
        }
    }
}
