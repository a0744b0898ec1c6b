//! The benchmark as data: 20 objects, 7 objectives, 6 topologies and 26 tasks, loaded from a
//! JSON file (`worlds/crm/benchmark.json` is built in) and validated.

pub mod mesh;
mod object;
mod task;

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

pub use crate::taxonomy::{FINGERS, FingerShape, Fragility, Objective, Topology};
pub use object::{Anchor, Axis, OBJECT_FEATURES, Object, ObjectFlags, Part, Shape};
pub use task::{GraspLocation, Task};

use crate::assets::Assets;
use crate::error::{Error, Result, parse_json, read_text};
use crate::hand::HandModel;

const BUILTIN: &str = include_str!("../../../../worlds/crm/benchmark.json");

/// The whole benchmark.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Benchmark {
    pub objects: Vec<Object>,
    pub tasks: Vec<Task>,
    /// The hand the tasks are grasped with: the built-in one unless a world names another.
    #[serde(skip)]
    pub hand: SharedHand,
    /// Observation features the world's robot cannot measure (indices, read as zero).
    #[serde(skip)]
    pub sensors_without: Vec<usize>,
}

/// A hand model shared by every environment of a world (compared by identity).
#[derive(Clone, Debug)]
pub struct SharedHand(pub Arc<HandModel>);

impl Default for SharedHand {
    fn default() -> Self {
        Self(crate::hand::builtin::model())
    }
}

impl PartialEq for SharedHand {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl std::ops::Deref for SharedHand {
    type Target = Arc<HandModel>;
    fn deref(&self) -> &Arc<HandModel> {
        &self.0
    }
}

impl Benchmark {
    /// The benchmark that ships with the crate.
    pub fn builtin() -> Self {
        match Self::from_json(BUILTIN, "worlds/crm/benchmark.json") {
            Ok(benchmark) => benchmark,
            // The built-in file is checked by the crate's tests.
            Err(err) => panic!("built-in benchmark is invalid: {err}"),
        }
    }

    /// Reads and validates a benchmark file; mesh parts are found next to it or in
    /// `CRM_ASSETS`.
    pub fn load(path: &Path) -> Result<Self> {
        Self::load_with(path, &Assets::from_env())
    }

    /// [`Benchmark::load`] with the asset folders given.
    pub fn load_with(path: &Path, assets: &Assets) -> Result<Self> {
        let text = read_text(path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::from_json_in(&text, &path.display().to_string(), base, assets)
    }

    /// Parses and validates benchmark JSON; `origin` names the source in errors, mesh parts
    /// are found from the working folder or in `CRM_ASSETS`.
    pub fn from_json(text: &str, origin: &str) -> Result<Self> {
        Self::from_json_in(text, origin, Path::new("."), &Assets::from_env())
    }

    /// Parses and validates benchmark JSON, reading mesh parts relative to `base`.
    pub fn from_json_in(text: &str, origin: &str, base: &Path, assets: &Assets) -> Result<Self> {
        let mut benchmark: Benchmark = parse_json(text, origin)?;
        benchmark.load_meshes(origin, base, assets)?;
        benchmark.validate(origin)?;
        Ok(benchmark)
    }

    fn load_meshes(&mut self, origin: &str, base: &Path, assets: &Assets) -> Result<()> {
        for (i, object) in self.objects.iter_mut().enumerate() {
            for (k, part) in object.parts.iter_mut().enumerate() {
                let Shape::Mesh {
                    file,
                    scale,
                    axis_angle,
                    decomposition,
                    geometry,
                } = &mut part.shape
                else {
                    continue;
                };
                let at = format!("objects[{i}] ({}).parts[{k}]", object.name);
                let invalid = |field: &str, message: String| Error::Invalid {
                    path: origin.to_string(),
                    at: format!("{at}.{field}"),
                    message,
                };
                if scale.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                    return Err(invalid("scale", format!("must be positive, got {scale:?}")));
                }
                if axis_angle.iter().any(|a| !a.is_finite()) {
                    return Err(invalid("axis_angle", "must be finite".into()));
                }
                if decomposition.resolution < 8
                    || decomposition.max_convex_hulls == 0
                    || !(decomposition.concavity.is_finite() && decomposition.concavity > 0.0)
                {
                    return Err(invalid(
                        "decomposition",
                        "resolution >= 8, max_convex_hulls >= 1 and a positive concavity".into(),
                    ));
                }
                let path = assets.file(file, base).ok_or_else(|| {
                    invalid(
                        "file",
                        format!(
                            "mesh {file:?} not found (relative to {}, or in CRM_ASSETS)",
                            base.display()
                        ),
                    )
                })?;
                let loaded = mesh::load(&path, *scale, *axis_angle, decomposition)
                    .map_err(|err| invalid("file", err.to_string()))?;
                *geometry = Arc::new(loaded);
            }
        }
        Ok(())
    }

    pub fn object(&self, name: &str) -> Option<&Object> {
        self.objects.iter().find(|o| o.name == name)
    }

    pub fn task(&self, id: &str) -> Option<&Task> {
        self.tasks.iter().find(|t| t.id == id)
    }

    /// The index of the task with this id (what `TaskChoice::Fixed` takes).
    pub fn task_index(&self, id: &str) -> Option<usize> {
        self.tasks.iter().position(|t| t.id == id)
    }

    /// The object a task refers to (validated to exist).
    pub fn object_of(&self, task: &Task) -> &Object {
        self.object(&task.object)
            .unwrap_or_else(|| panic!("validated task {} names a missing object", task.id))
    }

    fn validate(&self, path: &str) -> Result<()> {
        let invalid = |at: String, message: String| Error::Invalid {
            path: path.to_string(),
            at,
            message,
        };
        let mut names = BTreeSet::new();
        for (i, object) in self.objects.iter().enumerate() {
            let at = format!("objects[{i}] ({})", object.name);
            if !names.insert(object.name.as_str()) {
                return Err(invalid(at, "duplicate object name".into()));
            }
            if !(object.mass.is_finite() && object.mass > 0.0) {
                return Err(invalid(
                    format!("{at}.mass"),
                    format!("must be positive, got {}", object.mass),
                ));
            }
            if let Some(damping) = object.angular_damping
                && !(damping.is_finite() && damping >= 0.0)
            {
                return Err(invalid(
                    format!("{at}.angular_damping"),
                    format!("must be finite and >= 0, got {damping}"),
                ));
            }
            if !(object.friction.is_finite() && (0.0..=2.0).contains(&object.friction)) {
                return Err(invalid(
                    format!("{at}.friction"),
                    format!("must be in [0, 2], got {}", object.friction),
                ));
            }
            if object.parts.is_empty() {
                return Err(invalid(
                    format!("{at}.parts"),
                    "an object needs at least one part".into(),
                ));
            }
            for (k, part) in object.parts.iter().enumerate() {
                let dims = part.shape.dimensions();
                if dims.iter().any(|d| !(d.is_finite() && *d > 0.0))
                    || part.pos.iter().any(|p| !p.is_finite())
                {
                    return Err(invalid(
                        format!("{at}.parts[{k}]"),
                        "sizes must be positive and positions finite".into(),
                    ));
                }
            }
            if let Some(anchor) = &object.anchor
                && !(anchor.resist_torque.is_finite() && anchor.resist_torque > 0.0)
            {
                return Err(invalid(
                    format!("{at}.anchor.resist_torque"),
                    "must be positive".into(),
                ));
            }
        }
        let mut ids = BTreeSet::new();
        for (i, task) in self.tasks.iter().enumerate() {
            let at = format!("tasks[{i}] ({})", task.id);
            if !ids.insert(task.id.as_str()) {
                return Err(invalid(at, "duplicate task id".into()));
            }
            let Some(object) = self.object(&task.object) else {
                return Err(invalid(
                    format!("{at}.object"),
                    format!("unknown object {:?}", task.object),
                ));
            };
            if task
                .grasp
                .offset
                .iter()
                .chain(&task.motion)
                .any(|v| !v.is_finite())
                || !task.grasp.yaw.is_finite()
            {
                return Err(invalid(
                    format!("{at}.grasp"),
                    "values must be finite".into(),
                ));
            }
            if let Some(q) = task.grasp.orientation {
                if crate::hand::model::unit_quaternion(q).is_none() {
                    return Err(invalid(
                        format!("{at}.grasp.orientation"),
                        "must be a unit quaternion [x, y, z, w]".into(),
                    ));
                }
                if task.grasp.yaw != 0.0 {
                    return Err(invalid(
                        format!("{at}.grasp.yaw"),
                        "a grasp with an orientation takes no yaw".into(),
                    ));
                }
            }
            let needs_required = matches!(task.objective, Objective::Twist | Objective::Press);
            match (needs_required, task.required) {
                (true, None) => {
                    return Err(invalid(
                        format!("{at}.required"),
                        format!(
                            "a {} task needs a required torque or force",
                            task.objective.name()
                        ),
                    ));
                }
                (true, Some(value)) if !(value.is_finite() && value != 0.0) => {
                    return Err(invalid(
                        format!("{at}.required"),
                        "must be finite and non-zero".into(),
                    ));
                }
                _ => {}
            }
            if task.objective == Objective::Twist && object.anchor.is_none() {
                return Err(invalid(
                    format!("{at}.objective"),
                    format!(
                        "twist needs an anchored object, {} has no anchor",
                        object.name
                    ),
                ));
            }
            if task.objective != Objective::Twist && object.anchor.is_some() {
                return Err(invalid(
                    format!("{at}.objective"),
                    format!("{} is anchored and only takes twist tasks", object.name),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_task_is_found_by_its_id() {
        let benchmark = Benchmark::builtin();
        let index = benchmark
            .task_index("mouse-press")
            .expect("a built-in task");
        assert_eq!(benchmark.tasks[index].id, "mouse-press");
        assert_eq!(benchmark.task("mouse-press"), Some(&benchmark.tasks[index]));
        assert_eq!(benchmark.task_index("no-such-task"), None);
    }
}
