//! Mesh parts of objects: OBJ or STL files read into convex pieces once, when a world loads.
//!
//! An OBJ whose groups (`o`/`g`) are each convex (the AffordPose objects of the paper's world
//! come as 64 convex pieces) becomes a compound of their convex hulls. Any other mesh is
//! decomposed with parry's VHACD, whose parameters are part of the data; the hulls are cached
//! on disk under the file's content hash and the parameters, so the next load reads them.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rapier3d::parry::transformation::vhacd::VHACDParameters;
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::error::{Error, Result, invalid_at};

/// VHACD's parameters for a non-convex mesh (defaults: parry's, with at most 32 hulls).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Decomposition {
    /// Voxels along the longest axis (parry's default 64).
    #[serde(default = "default_resolution")]
    pub resolution: u32,
    /// Largest concavity kept in a piece, as a fraction of the mesh size (parry's 0.01).
    #[serde(default = "default_concavity")]
    pub concavity: f32,
    /// Most convex pieces (parry's default is unbounded; 32 keeps contacts cheap).
    #[serde(default = "default_max_hulls")]
    pub max_convex_hulls: u32,
}

fn default_resolution() -> u32 {
    64
}
fn default_concavity() -> f32 {
    0.01
}
fn default_max_hulls() -> u32 {
    32
}

impl Default for Decomposition {
    fn default() -> Self {
        Self {
            resolution: default_resolution(),
            concavity: default_concavity(),
            max_convex_hulls: default_max_hulls(),
        }
    }
}

/// A mesh read into convex pieces, in the part's frame (scale and rotation applied).
#[derive(Clone, Debug, Default)]
pub struct MeshGeometry {
    /// The compound of convex hulls (`None` before loading).
    pub shape: Option<SharedShape>,
    /// Axis-aligned bounds of the pieces.
    pub min: [f32; 3],
    pub max: [f32; 3],
    pub volume: f32,
    /// How it was made: `"convex groups"` or `"vhacd"`.
    pub method: &'static str,
    pub pieces: usize,
}

/// Geometry is compared by what it is made of, not by its handles.
impl PartialEq for MeshGeometry {
    fn eq(&self, other: &Self) -> bool {
        self.min == other.min
            && self.max == other.max
            && self.volume == other.volume
            && self.pieces == other.pieces
    }
}

/// Triangles of a mesh file, grouped as the file groups them.
struct RawMesh {
    vertices: Vec<Vec3>,
    groups: Vec<Vec<[u32; 3]>>,
}

fn bad(path: &Path, message: impl Into<String>) -> Error {
    invalid_at(path, "mesh", message)
}

fn read_obj(path: &Path, text: &str) -> Result<RawMesh> {
    let mut vertices = Vec::new();
    let mut groups: Vec<Vec<[u32; 3]>> = vec![Vec::new()];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let xyz: Vec<f32> = words
                    .take(3)
                    .map(|w| w.parse().unwrap_or(f32::NAN))
                    .collect();
                if xyz.len() != 3 || xyz.iter().any(|v| !v.is_finite()) {
                    return Err(bad(
                        path,
                        format!("line {}: a vertex needs three finite numbers", n + 1),
                    ));
                }
                vertices.push(Vec3::new(xyz[0], xyz[1], xyz[2]));
            }
            Some("o" | "g") if groups.last().is_some_and(|g| !g.is_empty()) => {
                groups.push(Vec::new());
            }
            Some("f") => {
                let mut face = Vec::new();
                for word in words {
                    let index: i64 = word
                        .split('/')
                        .next()
                        .and_then(|i| i.parse().ok())
                        .ok_or_else(|| {
                            bad(path, format!("line {}: bad face index {word:?}", n + 1))
                        })?;
                    let resolved = if index < 0 {
                        vertices.len() as i64 + index
                    } else {
                        index - 1
                    };
                    if !(0..vertices.len() as i64).contains(&resolved) {
                        return Err(bad(
                            path,
                            format!("line {}: face index {index} out of range", n + 1),
                        ));
                    }
                    face.push(resolved as u32);
                }
                let group = groups.last_mut().expect("one group at least");
                for k in 1..face.len().saturating_sub(1) {
                    group.push([face[0], face[k], face[k + 1]]);
                }
            }
            _ => {}
        }
    }
    groups.retain(|g| !g.is_empty());
    Ok(RawMesh { vertices, groups })
}

fn read_stl(path: &Path, bytes: &[u8]) -> Result<RawMesh> {
    let mut vertices = Vec::new();
    let binary_len = bytes
        .get(80..84)
        .map(|c| 84 + 50 * u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as usize);
    if binary_len == Some(bytes.len()) {
        for facet in bytes[84..].chunks_exact(50) {
            for v in 0..3 {
                let at = 12 + 12 * v;
                let f = |k: usize| {
                    let b = &facet[at + 4 * k..at + 4 * k + 4];
                    f32::from_le_bytes([b[0], b[1], b[2], b[3]])
                };
                vertices.push(Vec3::new(f(0), f(1), f(2)));
            }
        }
    } else {
        let text =
            std::str::from_utf8(bytes).map_err(|_| bad(path, "neither binary nor ASCII STL"))?;
        for line in text.lines() {
            let mut words = line.split_whitespace();
            if words.next() == Some("vertex") {
                let xyz: Vec<f32> = words
                    .take(3)
                    .map(|w| w.parse().unwrap_or(f32::NAN))
                    .collect();
                if xyz.len() != 3 {
                    return Err(bad(path, "a vertex needs three numbers"));
                }
                vertices.push(Vec3::new(xyz[0], xyz[1], xyz[2]));
            }
        }
    }
    if vertices.iter().any(|v| !v.is_finite()) {
        return Err(bad(path, "a vertex is not finite"));
    }
    let triangles = (0..vertices.len() as u32 / 3)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    Ok(RawMesh {
        vertices,
        groups: vec![triangles],
    })
}

/// Whether every vertex of a group lies on its convex hull (a dent puts some inside).
fn is_convex(points: &[Vec3], hull: &SharedShape) -> bool {
    let size = hull.compute_local_aabb().extents().length();
    points.iter().all(|p| {
        // Not solid: a point inside projects onto the boundary, at its depth.
        let projection = hull.project_local_point(*p, false);
        !projection.is_inside || (projection.point - *p).length() <= 1e-3 * size
    })
}

fn cache_folder() -> PathBuf {
    if let Ok(dir) = std::env::var("CRM_CACHE") {
        return PathBuf::from(dir);
    }
    let base = std::env::var("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .unwrap_or_else(|_| {
            PathBuf::from(std::env::var("HOME").unwrap_or_else(|_| "/tmp".into())).join(".cache")
        });
    base.join("crm-grasp").join("vhacd")
}

/// Reads `path`, scales and rotates it into the part frame and makes its convex pieces.
pub fn load(
    path: &Path,
    scale: [f32; 3],
    axis_angle: [f32; 3],
    decomposition: &Decomposition,
) -> Result<MeshGeometry> {
    let bytes = std::fs::read(path).map_err(|error| Error::Io {
        path: path.display().to_string(),
        error,
    })?;
    let raw = match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("obj") => read_obj(path, &String::from_utf8_lossy(&bytes))?,
        Some("stl") => read_stl(path, &bytes)?,
        _ => return Err(bad(path, "a mesh part is an .obj or .stl file")),
    };
    if raw.vertices.is_empty() || raw.groups.is_empty() {
        return Err(bad(path, "the mesh is empty"));
    }
    let rotation = Rotation::from_scaled_axis(Vec3::from(axis_angle));
    let scale = Vec3::from(scale);
    let vertices: Vec<Vec3> = raw
        .vertices
        .iter()
        .map(|v| rotation * (*v * scale))
        .collect();
    let mut hulls = Vec::new();
    let mut convex = true;
    for group in &raw.groups {
        let mut points: Vec<Vec3> = group
            .iter()
            .flatten()
            .map(|&i| vertices[i as usize])
            .collect();
        points.dedup();
        match SharedShape::convex_hull(&points) {
            Some(hull) if is_convex(&points, &hull) => hulls.push((Pose::IDENTITY, hull)),
            _ => {
                convex = false;
                break;
            }
        }
    }
    let method = if convex { "convex groups" } else { "vhacd" };
    if !convex {
        hulls = decompose(
            path,
            &bytes,
            &vertices,
            &raw.groups,
            scale,
            axis_angle,
            decomposition,
        )?;
    }
    if hulls.is_empty() {
        return Err(bad(path, "the mesh has no volume"));
    }
    let pieces = hulls.len();
    let shape = SharedShape::compound(hulls);
    let aabb = shape.compute_local_aabb();
    let volume = shape.mass_properties(1.0).mass();
    if !(volume.is_finite() && volume > 0.0) {
        return Err(bad(path, "the mesh has no volume"));
    }
    Ok(MeshGeometry {
        shape: Some(shape),
        min: aabb.mins.into(),
        max: aabb.maxs.into(),
        volume,
        method,
        pieces,
    })
}

#[allow(clippy::too_many_arguments)]
fn decompose(
    path: &Path,
    bytes: &[u8],
    vertices: &[Vec3],
    groups: &[Vec<[u32; 3]>],
    scale: Vec3,
    axis_angle: [f32; 3],
    decomposition: &Decomposition,
) -> Result<Vec<(Pose, SharedShape)>> {
    let mut hasher = Sha256::new();
    hasher.update(bytes);
    hasher.update(format!("{scale:?}{axis_angle:?}{decomposition:?}").as_bytes());
    let key = format!("{:x}", hasher.finalize());
    let cached = cache_folder().join(format!("{key}.json"));
    let pieces: Vec<Vec<[f32; 3]>> = match std::fs::read_to_string(&cached)
        .ok()
        .and_then(|text| serde_json::from_str(&text).ok())
    {
        Some(pieces) => pieces,
        None => {
            let indices: Vec<[u32; 3]> = groups.iter().flatten().copied().collect();
            let params = VHACDParameters {
                resolution: decomposition.resolution,
                concavity: decomposition.concavity,
                max_convex_hulls: decomposition.max_convex_hulls,
                ..VHACDParameters::default()
            };
            let decomposed = rapier3d::parry::transformation::vhacd::VHACD::decompose(
                &params, vertices, &indices, false,
            );
            let pieces: Vec<Vec<[f32; 3]>> = decomposed
                .compute_convex_hulls(4)
                .into_iter()
                .map(|(points, _)| points.into_iter().map(Into::into).collect())
                .collect();
            // A cache that cannot be written only costs the next load a decomposition.
            if std::fs::create_dir_all(cache_folder()).is_ok()
                && let Ok(text) = serde_json::to_string(&pieces)
            {
                let partial = cached.with_extension("partial");
                if std::fs::write(&partial, text).is_ok() {
                    let _ = std::fs::rename(&partial, &cached);
                }
            }
            pieces
        }
    };
    let hulls: Vec<(Pose, SharedShape)> = pieces
        .iter()
        .filter_map(|points| {
            let points: Vec<Vec3> = points.iter().map(|p| Vec3::from(*p)).collect();
            SharedShape::convex_hull(&points).map(|hull| (Pose::IDENTITY, hull))
        })
        .collect();
    if hulls.is_empty() {
        return Err(bad(path, "VHACD found no convex piece"));
    }
    Ok(hulls)
}

/// The geometry shared by every episode (cheap to clone).
pub type Shared = Arc<MeshGeometry>;

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("crm-mesh-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join(name);
        std::fs::write(&path, text).expect("write");
        path
    }

    /// A unit cube at `at`, its vertices numbered from `first` (1-based).
    fn cube(at: f32, first: u32) -> String {
        let mut text = String::new();
        for (x, y, z) in [
            (0, 0, 0),
            (1, 0, 0),
            (1, 1, 0),
            (0, 1, 0),
            (0, 0, 1),
            (1, 0, 1),
            (1, 1, 1),
            (0, 1, 1),
        ] {
            text += &format!("v {} {y} {z}\n", at + x as f32);
        }
        for face in [
            [1, 2, 3, 4],
            [5, 6, 7, 8],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [3, 4, 8, 7],
            [4, 1, 5, 8],
        ] {
            let face: Vec<String> = face.iter().map(|i| (i + first - 1).to_string()).collect();
            text += &format!("f {}\n", face.join(" "));
        }
        text
    }

    #[test]
    fn convex_groups_become_one_hull_each() {
        let two = format!("o a\n{}o b\n{}", cube(0.0, 1), cube(2.0, 9));
        let path = write("two.obj", &two);
        let mesh = load(&path, [0.1; 3], [0.0; 3], &Decomposition::default()).expect("mesh");
        assert_eq!((mesh.method, mesh.pieces), ("convex groups", 2));
        assert!((mesh.volume - 2.0 * 0.001).abs() < 1e-6, "{}", mesh.volume);
        assert!((mesh.max[0] - 0.3).abs() < 1e-6);
    }

    #[test]
    fn empty_non_finite_and_missing_meshes_are_refused_naming_the_file() {
        let empty = write("empty.obj", "# nothing\n");
        let err = load(&empty, [1.0; 3], [0.0; 3], &Decomposition::default()).expect_err("empty");
        assert!(
            err.to_string().contains("empty.obj") && err.to_string().contains("empty"),
            "{err}"
        );
        let nan = write("nan.obj", "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        let err = load(&nan, [1.0; 3], [0.0; 3], &Decomposition::default()).expect_err("nan");
        assert!(
            err.to_string().contains("nan.obj") && err.to_string().contains("finite"),
            "{err}"
        );
        let missing = Path::new("/nonexistent/mug.obj");
        let err =
            load(missing, [1.0; 3], [0.0; 3], &Decomposition::default()).expect_err("missing");
        assert!(err.to_string().contains("/nonexistent/mug.obj"), "{err}");
    }
}
