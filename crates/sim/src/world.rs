//! A world is a folder: `world.json` names the hand (a profile, which names its description),
//! the objects and tasks (a benchmark file), the CRM spec, the randomization and what the
//! robot senses. File names are relative to the folder or found in `CRM_ASSETS`.
//!
//! ```json
//! { "name": "crm", "hand": "hand.json", "benchmark": "benchmark.json",
//!   "spec": null, "randomization": null, "sensors": { "without": ["o_force"] } }
//! ```
//!
//! The built-in world (`worlds/crm/`) is compiled in: [`World::builtin`].

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::assets::Assets;
use crate::benchmark::{Benchmark, SharedHand};
use crate::config::{Approach, Randomization};
use crate::corrections::Corrections;
use crate::error::{Error, Result, parse_json, read_text};
use crate::hand::HandModel;
use crate::hand::description::{Description, Source};
use crate::hand::profile::Profile;
use crate::observation::{ACTIONS, FEATURES};

/// `world.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldFile {
    /// Letters, digits, `-`, `_` and `.`; what jobs and checkpoints call the world.
    pub name: String,
    /// The hand profile.
    pub hand: String,
    /// Objects and tasks (default: the built-in benchmark).
    #[serde(default)]
    pub benchmark: Option<String>,
    /// The CRM spec (default: the built-in grasping spec).
    #[serde(default)]
    pub spec: Option<String>,
    /// Domain randomization (default: the paper's, `SimConfig::default`).
    #[serde(default)]
    pub randomization: Option<Randomization>,
    /// What the robot senses (default: every feature).
    #[serde(default)]
    pub sensors: Sensors,
    /// How palm actions move the hand in the approach: `"free"` (default) or `"authors"`
    /// (the authors' slowed, clamped steps; [`Approach`]). Part of the hash when not free.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<Approach>,
    /// Folders searched for files after the world's own and before `CRM_ASSETS` (absolute,
    /// or relative to the world's folder): where an imported world's source lies. Not part
    /// of the hash, so a copy of the same files elsewhere makes the same world.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub assets: Vec<PathBuf>,
    /// Corrections to the tasks' grasp locations (`crm world fit-grasps`; [`Corrections`]).
    /// Part of the hash when present.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corrections: Option<String>,
}

/// Observation features a real robot cannot measure: features by name (`force_x`) or the
/// paper's groups (`n_c`, `o_dist`, `o_object`, `o_cone`, `o_relative`, `o_force`,
/// `o_torque`), read as zero.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sensors {
    #[serde(default)]
    pub without: Vec<String>,
}

/// The indices of [`FEATURES`] that a group or feature name covers.
pub fn feature_indices(name: &str) -> Option<Vec<usize>> {
    let group: &[&str] = match name {
        "n_c" => &["n_c"],
        "o_dist" => &["dist"],
        "o_object" => &["object_x", "object_y", "object_z"],
        "o_cone" => &["cone"],
        "o_relative" => &[
            "rel_x",
            "rel_y",
            "rel_z",
            "in_hand_x",
            "in_hand_y",
            "in_hand_z",
        ],
        "o_force" => &["force_x", "force_y", "force_z"],
        "o_torque" => &["torque_x", "torque_y", "torque_z"],
        other => return FEATURES.iter().position(|f| *f == other).map(|i| vec![i]),
    };
    Some(
        group
            .iter()
            .filter_map(|g| FEATURES.iter().position(|f| f == g))
            .collect(),
    )
}

/// A loaded world.
#[derive(Clone, Debug)]
pub struct World {
    pub name: String,
    /// The folder it came from (`None`: built in).
    pub dir: Option<PathBuf>,
    pub source: Source,
    /// Objects, tasks, the hand and the sensors, ready for environments.
    pub benchmark: Arc<Benchmark>,
    pub spec: Option<crm::Spec>,
    pub randomization: Option<Randomization>,
    /// How palm actions move the hand in the approach.
    pub approach: Approach,
    /// A hash of what shapes a policy's observation and action: the hand profile, the spec,
    /// the sensors and every file of the hand by content (its description, the files that
    /// includes, its meshes), never where the files lie. Checkpoints record it.
    pub hash: String,
    /// What the world corrects in its tasks' grasp locations, if anything.
    pub corrections: Option<Corrections>,
    /// [`World::hash`] without the corrections: what shapes a policy's observation and action
    /// (the same as `hash` for a world that corrects nothing). Checkpoints record it, so a
    /// policy trained in a corrected world runs in the world as imported and the other way
    /// round.
    pub policy_hash: String,
    /// The hash of the profile, the spec and the sensors alone: what checkpoints recorded
    /// before the hand's files were in [`World::hash`]. A checkpoint that recorded it is
    /// accepted where the three match.
    pub profile_hash: String,
}

impl World {
    /// The built-in world, `worlds/crm/`, compiled in.
    pub fn builtin() -> Self {
        let benchmark = Benchmark::builtin();
        let profile_hash = world_hash(
            crate::hand::builtin::PROFILE,
            &spec_text(&crate::spec::grasping_spec()),
            &[],
            Approach::Free,
        );
        let mut content = Sha256::new();
        crate::hand::includes::add_content(
            &mut content,
            crate::hand::builtin::DESCRIPTION.as_bytes(),
        );
        let hash = with_content(&profile_hash, &content.finalize().into());
        Self {
            name: "crm".into(),
            dir: None,
            source: benchmark.hand.source,
            benchmark: Arc::new(benchmark),
            spec: None,
            randomization: None,
            approach: Approach::Free,
            hash: hash.clone(),
            policy_hash: hash,
            profile_hash,
            corrections: None,
        }
    }

    /// The world's CRM: the machine of its spec, or the built-in grasping machine, as
    /// [`Self::machine_with`] masks it.
    pub fn machine(&self) -> Result<crm::Machine> {
        match &self.spec {
            None if self.benchmark.hand.fingers.iter().all(|f| f.present) => {
                Ok(crate::spec::grasping_machine())
            }
            spec => self.machine_with(spec.clone().unwrap_or_else(crate::spec::grasping_spec)),
        }
    }

    /// The machine of `spec` in this world. The action of a finger the hand lacks is left out
    /// of every stage's action set, so the policy's mask hides it; the action space and the
    /// spec's file stay the paper's.
    pub fn machine_with(&self, mut spec: crm::Spec) -> Result<crm::Machine> {
        let missing: Vec<&str> = self
            .benchmark
            .hand
            .fingers
            .iter()
            .zip(&ACTIONS[3..])
            .filter(|(finger, _)| !finger.present)
            .map(|(_, &name)| name)
            .collect();
        for stage in &mut spec.stages {
            stage.actions.retain(|a| !missing.contains(&a.dim.as_str()));
        }
        Ok(crm::Machine::from_spec(spec)?)
    }

    /// Loads the world in `dir`, finding files through `CRM_ASSETS`.
    pub fn load(dir: &Path) -> Result<Self> {
        Self::load_with(dir, &Assets::from_env())
    }

    /// Loads the world in `dir`, finding files through `assets`.
    pub fn load_with(dir: &Path, assets: &Assets) -> Result<Self> {
        let path = dir.join("world.json");
        let origin = path.display().to_string();
        let text = read_text(&path)?;
        let file: WorldFile = parse_json(&text, &origin)?;
        let assets = &Assets {
            folders: file
                .assets
                .iter()
                .map(|folder| dir.join(folder))
                .chain(assets.folders.iter().cloned())
                .collect(),
        };
        let invalid = |at: &str, message: String| Error::Invalid {
            path: origin.clone(),
            at: at.to_string(),
            message,
        };
        if file.name.is_empty()
            || file.name.len() > 64
            || !file
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
        {
            return Err(invalid(
                "name",
                format!(
                    "1 to 64 letters, digits, '-', '_' or '.', got {:?}",
                    file.name
                ),
            ));
        }
        let find = |field: &str, name: &str| {
            assets.file(name, dir).ok_or_else(|| {
                invalid(
                    field,
                    format!(
                        "{name:?} not found (in {}, or in CRM_ASSETS)",
                        dir.display()
                    ),
                )
            })
        };
        let profile_path = find("hand", &file.hand)?;
        let profile_text = read_text(&profile_path)?;
        let profile: Profile = parse_json(&profile_text, &profile_path.display().to_string())?;
        let profile_dir = profile_path.parent().unwrap_or(dir);
        let description_path = assets
            .file(&profile.description, profile_dir)
            .ok_or_else(|| Error::Invalid {
                path: profile_path.display().to_string(),
                at: "description".into(),
                message: format!(
                    "{:?} not found (in {}, or in CRM_ASSETS)",
                    profile.description,
                    profile_dir.display()
                ),
            })?;
        let description = Description::load(&description_path, assets)?;
        let hand = HandModel::new(&description, &profile, &profile_path)?;

        let mut benchmark = match &file.benchmark {
            Some(name) => Benchmark::load_with(&find("benchmark", name)?, assets)?,
            None => Benchmark::builtin(),
        };
        benchmark.hand = SharedHand(Arc::new(hand));
        let (spec, spec_text) = match &file.spec {
            Some(name) => {
                let spec_path = find("spec", name)?;
                let spec = crm::Spec::load(&spec_path)?;
                crate::spec::check_compatible(&spec)?;
                let text = spec_text(&spec);
                (Some(spec), text)
            }
            None => (None, spec_text(&crate::spec::grasping_spec())),
        };
        let mut without = Vec::new();
        for (k, name) in file.sensors.without.iter().enumerate() {
            let indices = feature_indices(name).ok_or_else(|| {
                invalid(
                    &format!("sensors.without[{k}]"),
                    format!(
                        "{name:?} is neither an observation feature nor one of the paper's groups"
                    ),
                )
            })?;
            without.extend(indices);
        }
        without.sort_unstable();
        without.dedup();
        benchmark.sensors_without = without.clone();
        let approach = file.approach.unwrap_or_default();
        let corrections = match &file.corrections {
            Some(name) => {
                let path = find("corrections", name)?;
                let text = read_text(&path)?;
                let corrections: Corrections = parse_json(&text, &path.display().to_string())?;
                corrections.apply(&mut benchmark, &path)?;
                Some((corrections, text))
            }
            None => None,
        };
        let profile_hash = world_hash(&profile_text, &spec_text, &without, approach);
        let policy_hash = with_content(&profile_hash, &description.content);
        let hash = match &corrections {
            Some((_, text)) => {
                with_content(&with_corrections(&profile_hash, text), &description.content)
            }
            None => policy_hash.clone(),
        };
        if let Some(randomization) = &file.randomization
            && [
                randomization.position,
                randomization.yaw,
                randomization.joint,
            ]
            .iter()
            .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err(invalid(
                "randomization",
                "widths must be finite and >= 0".into(),
            ));
        }
        Ok(Self {
            name: file.name,
            dir: Some(dir.to_path_buf()),
            source: description.source,
            benchmark: Arc::new(benchmark),
            spec,
            randomization: file.randomization,
            approach,
            hash,
            policy_hash,
            profile_hash,
            corrections: corrections.map(|(c, _)| c),
        })
    }

    /// Revolute joints of the hand, its links and the fingers it acts with.
    pub fn summary(&self) -> serde_json::Value {
        let hand = &self.benchmark.hand;
        let mut summary = serde_json::json!({
            "world": self.name,
            "hand": {
                "source": self.source,
                "links": hand.links.len(),
                "joints": hand.revolute_joints(),
                "fingers": hand.fingers.iter().filter(|f| f.present).count(),
            },
            "objects": self.benchmark.objects.len(),
            "tasks": self.benchmark.tasks.len(),
            "hash": self.hash,
        });
        if let Some(corrections) = &self.corrections {
            summary["corrections"] = serde_json::json!(corrections.offsets());
        }
        let couplings = &hand.couplings;
        if !couplings.overridden.is_empty() {
            summary["description_overrides"] = couplings
                .overridden
                .iter()
                .map(ToString::to_string)
                .collect();
        }
        summary
    }

    /// The profile's couplings that contradict the description's without an override, each
    /// naming the joint and both couplings (`crm world check` refuses a world with any), and
    /// overrides that name a joint without a conflict.
    pub fn coupling_conflicts(&self) -> (Vec<String>, Vec<String>) {
        let couplings = &self.benchmark.hand.couplings;
        (
            couplings
                .conflicts
                .iter()
                .map(ToString::to_string)
                .collect(),
            couplings.needless.clone(),
        )
    }
}

fn spec_text(spec: &crm::Spec) -> String {
    serde_json::to_string(spec).unwrap_or_default()
}

/// A profile re-serialized, so whitespace and key order do not change a world's hash.
fn canonical(text: &str) -> String {
    serde_json::from_str::<serde_json::Value>(text)
        .map(|v| v.to_string())
        .unwrap_or_else(|_| text.to_string())
}

/// A profile as [`canonical`] without its `description_overrides`, which acknowledge the
/// description's couplings and change nothing the hand does.
fn canonical_profile(text: &str) -> String {
    match serde_json::from_str::<serde_json::Value>(text) {
        Ok(mut value) => {
            if let Some(map) = value.as_object_mut() {
                map.remove("description_overrides");
            }
            value.to_string()
        }
        Err(_) => text.to_string(),
    }
}

/// A hash and a corrections file's canonical text.
fn with_corrections(hash: &str, text: &str) -> String {
    let mut hasher = Sha256::new();
    hasher.update(hash.as_bytes());
    hasher.update([0]);
    hasher.update(canonical(text).as_bytes());
    let digest = hasher.finalize();
    digest.iter().take(8).map(|b| format!("{b:02x}")).collect()
}

/// The world's hash: its profile hash and the hand's files' content.
fn with_content(profile_hash: &str, content: &[u8; 32]) -> String {
    let mut hasher = Sha256::new();
    hasher.update(profile_hash.as_bytes());
    hasher.update(content);
    let digest = hasher.finalize();
    digest.iter().take(8).map(|b| format!("{b:02x}")).collect()
}

/// The hash of the profile, spec, sensors and (when not free, so that free worlds keep the
/// hashes their checkpoints recorded) the approach geometry.
fn world_hash(profile: &str, spec: &str, without: &[usize], approach: Approach) -> String {
    let mut hasher = Sha256::new();
    hasher.update(canonical_profile(profile).as_bytes());
    hasher.update([0]);
    hasher.update(canonical(spec).as_bytes());
    hasher.update([0]);
    hasher.update(format!("{without:?}").as_bytes());
    if approach != Approach::Free {
        hasher.update([0]);
        hasher.update(approach.name().as_bytes());
    }
    let digest = hasher.finalize();
    digest.iter().take(8).map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_and_features_name_observation_indices() {
        assert_eq!(feature_indices("o_force").map(|v| v.len()), Some(3));
        assert_eq!(feature_indices("cone"), Some(vec![5]));
        assert_eq!(feature_indices("o_cone"), Some(vec![5]));
        assert_eq!(feature_indices("nothing"), None);
    }

    #[test]
    fn the_builtin_world_folder_is_the_compiled_in_world() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../worlds/crm");
        let world = World::load_with(&dir, &Assets::default()).expect("worlds/crm");
        let builtin = World::builtin();
        assert_eq!(world.name, builtin.name);
        assert_eq!(world.hash, builtin.hash);
        assert_eq!(world.benchmark.tasks, builtin.benchmark.tasks);
        assert_eq!(world.summary()["hand"]["joints"], 14);
    }

    #[test]
    fn the_authors_approach_is_a_world_setting_in_its_hash() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../worlds/crm-authors-approach");
        let world = World::load_with(&dir, &Assets::default()).expect("crm-authors-approach");
        let builtin = World::builtin();
        assert_eq!(world.approach, Approach::Authors);
        assert_eq!(world.benchmark.tasks, builtin.benchmark.tasks);
        assert_ne!(world.hash, builtin.hash);
        let settings = crate::EnvSettings::default();
        assert_eq!(world.sim_config(&settings).approach, Approach::Authors);
        assert_eq!(builtin.sim_config(&settings).approach, Approach::Free);
    }

    #[test]
    fn a_world_without_a_spec_runs_the_grasping_machine_and_one_with_a_spec_runs_its_own() {
        let mut world = World::builtin();
        let grasping = crate::spec::grasping_machine();
        let machine = world.machine().expect("built-in machine");
        assert_eq!(machine.stage_count(), grasping.stage_count());
        world.spec = Some(crate::spec::flat_spec());
        let flat = world.machine().expect("flat machine");
        assert_eq!(
            flat.stage_name(0),
            crm::Machine::from_spec(crate::spec::flat_spec())
                .expect("flat")
                .stage_name(0)
        );
        assert_ne!(flat.stage_count(), grasping.stage_count());
    }
}
