//! An object of the benchmark: primitive parts, mass, friction, fragility and the features the
//! topology network reads.

use serde::{Deserialize, Serialize};

use super::mesh::{Decomposition, MeshGeometry};
use crate::taxonomy::Fragility;
use std::sync::Arc;

/// The axis of a cylinder or capsule part, in the object frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    #[default]
    Z,
}

/// A primitive collision shape (metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case")]
pub enum Shape {
    Cuboid {
        half_extents: [f32; 3],
    },
    Cylinder {
        radius: f32,
        half_height: f32,
        #[serde(default)]
        axis: Axis,
    },
    Capsule {
        radius: f32,
        half_height: f32,
        #[serde(default)]
        axis: Axis,
    },
    Ball {
        radius: f32,
    },
    /// An OBJ or STL file (relative to the benchmark file or found in `CRM_ASSETS`), scaled
    /// per axis and then turned by `axis_angle` (a rotation vector, rad) into the part frame.
    Mesh {
        file: String,
        #[serde(default = "unit_scale")]
        scale: [f32; 3],
        #[serde(default)]
        axis_angle: [f32; 3],
        /// VHACD's parameters, used when the mesh is not made of convex groups.
        #[serde(default)]
        decomposition: Decomposition,
        /// The convex pieces, read when the benchmark loads.
        #[serde(skip)]
        geometry: Arc<MeshGeometry>,
    },
}

fn unit_scale() -> [f32; 3] {
    [1.0; 3]
}

impl Shape {
    /// The part's axis-aligned bounds `(min, max)` about its position.
    pub fn local_bounds(&self) -> ([f32; 3], [f32; 3]) {
        if let Shape::Mesh { geometry, .. } = self {
            return (geometry.min, geometry.max);
        }
        let half = self.half_box();
        (half.map(|h| -h), half)
    }

    /// Half extents of a primitive part's axis-aligned box in the object frame (a mesh's
    /// largest half extent about its position).
    pub fn half_box(&self) -> [f32; 3] {
        let along = |axis: Axis, half_length: f32, radius: f32| match axis {
            Axis::X => [half_length, radius, radius],
            Axis::Y => [radius, half_length, radius],
            Axis::Z => [radius, radius, half_length],
        };
        match *self {
            Shape::Cuboid { half_extents } => half_extents,
            Shape::Cylinder {
                radius,
                half_height,
                axis,
            } => along(axis, half_height, radius),
            Shape::Capsule {
                radius,
                half_height,
                axis,
            } => along(axis, half_height + radius, radius),
            Shape::Ball { radius } => [radius; 3],
            Shape::Mesh { ref geometry, .. } => {
                std::array::from_fn(|k| geometry.min[k].abs().max(geometry.max[k].abs()))
            }
        }
    }

    /// Volume in cubic metres (to share an object's mass between its parts).
    pub fn volume(&self) -> f32 {
        use std::f32::consts::PI;
        match *self {
            Shape::Cuboid { half_extents: h } => 8.0 * h[0] * h[1] * h[2],
            Shape::Cylinder {
                radius,
                half_height,
                ..
            } => PI * radius * radius * 2.0 * half_height,
            Shape::Capsule {
                radius,
                half_height,
                ..
            } => PI * radius * radius * (2.0 * half_height + 4.0 / 3.0 * radius),
            Shape::Ball { radius } => 4.0 / 3.0 * PI * radius.powi(3),
            Shape::Mesh { ref geometry, .. } => geometry.volume,
        }
    }

    pub(crate) fn dimensions(&self) -> Vec<f32> {
        match self {
            Shape::Cuboid { half_extents } => half_extents.to_vec(),
            Shape::Cylinder {
                radius,
                half_height,
                ..
            }
            | Shape::Capsule {
                radius,
                half_height,
                ..
            } => vec![*radius, *half_height],
            Shape::Ball { radius } => vec![*radius],
            Shape::Mesh { scale, .. } => scale.to_vec(),
        }
    }
}

/// One primitive part placed in the object frame (origin at the base centre, z up).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Part {
    #[serde(flatten)]
    pub shape: Shape,
    pub pos: [f32; 3],
}

/// A twist object turns about an axis through its origin against a resisting torque (a
/// valve, a lid): a revolute joint to the table whose motor holds up to `resist_torque`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    pub resist_torque: f32,
}

/// Qualitative features from perception (paper, section II-A), inputs of the topology network.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectFlags {
    #[serde(default)]
    pub handle: bool,
    #[serde(default)]
    pub round: bool,
    #[serde(default)]
    pub elongated: bool,
    #[serde(default)]
    pub button: bool,
}

/// An object of the benchmark.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Object {
    pub name: String,
    /// Kilograms.
    pub mass: f32,
    /// Coulomb friction coefficient of the surface.
    pub friction: f32,
    pub fragility: Fragility,
    pub parts: Vec<Part>,
    #[serde(default)]
    pub anchor: Option<Anchor>,
    #[serde(default)]
    pub flags: ObjectFlags,
    /// Angular damping of the body (1/s; default 0): what stands in for PyBullet's rolling
    /// and spinning friction, which rapier lacks, so a tall object resists tipping and
    /// spinning as it did in its source world.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_damping: Option<f32>,
}

/// Names of [`Object::features`], in order.
pub const OBJECT_FEATURES: [&str; 10] = [
    "size_x",
    "size_y",
    "size_z",
    "mass",
    "friction",
    "fragility",
    "handle",
    "round",
    "elongated",
    "button",
];

impl Object {
    /// Bounding box `(min, max)` of the parts in the object frame.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for part in &self.parts {
            let (low, high) = part.shape.local_bounds();
            for axis in 0..3 {
                min[axis] = min[axis].min(part.pos[axis] + low[axis]);
                max[axis] = max[axis].max(part.pos[axis] + high[axis]);
            }
        }
        (min, max)
    }

    /// Size of the bounding box (metres).
    pub fn dimensions(&self) -> [f32; 3] {
        let (min, max) = self.bounds();
        [max[0] - min[0], max[1] - min[1], max[2] - min[2]]
    }

    /// The feature vector of the topology network (section II-B), named by [`OBJECT_FEATURES`].
    pub fn features(&self) -> [f32; 10] {
        let size = self.dimensions();
        let flag = |value: bool| if value { 1.0 } else { 0.0 };
        [
            size[0],
            size[1],
            size[2],
            self.mass,
            self.friction,
            self.fragility.level(),
            flag(self.flags.handle),
            flag(self.flags.round),
            flag(self.flags.elongated),
            flag(self.flags.button),
        ]
    }
}
