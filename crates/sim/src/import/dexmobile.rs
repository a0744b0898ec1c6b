//! `crm world import-dexmobile`: the paper's own world from a copy of the authors' repository
//! (github.com/hhelium/DexMobile): the right SVH hand of `robots/dual_2hand.urdf`, the
//! AffordPose objects of `objects/<id>/`, and the tasks of `crm_ppo/topo/pos_all.csv`.
//!
//! How a task becomes ours (the authors' `Helper.calculate_rigid_trans`): the object stands
//! on our table turned by the row's `q_obj` (folded into its mesh, so our object frame is
//! upright; our randomization turns it about the vertical as their `lower`/`upper` do); the
//! hand's end-effector link goes to `C(q_obj) Trans` from the object's origin, turned by
//! `q_obj ⊗ Orientation ⊗ convert_hand` (the profile's `grasp_frame` carries the link and
//! the turn, the task `q_obj ⊗ Orientation`). The row's `p_obj` places their object in their
//! robot's workspace; ours stands at the table's centre, so it is not used.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rapier3d::math::{Rotation, Vec3};
use serde_json::{Value, json};

use super::csv::{self, Row};
use super::svh;
use crate::assets::Assets;
use crate::benchmark::Objective;
use crate::error::{Error, Result, invalid_at, read_text};
use crate::hand::description::Description;
use crate::staging::{refuse_occupied, write_json, write_world};
use crate::world::World;

/// Where the authors publish it.
pub const SOURCE: &str = "https://github.com/hhelium/DexMobile";

/// Files a copy of the repository has, checked in this order.
pub const REQUIRED: [&str; 4] = [
    "crm_ppo/topo/pos_all.csv",
    "crm_ppo/Helper.py",
    svh::DESCRIPTION,
    "robots/schunk_svh_description/package.xml",
];

/// What the import writes besides the tasks.
#[derive(Clone, Debug)]
pub struct Options {
    /// The world's name (default `dexmobile`).
    pub name: String,
    /// Sensors the robot lacks (`world.json` `sensors.without`).
    pub without: Vec<String>,
    /// The approach geometry (`world.json` `approach`; free when absent): the authors' arm
    /// is [`crate::config::Approach::Authors`].
    pub approach: Option<crate::config::Approach>,
    /// Corrections to the tasks' grasp locations (`crm world fit-grasps`' `corrections.json`,
    /// the text), written beside the import and named in its `world.json`.
    pub corrections: Option<String>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            name: "dexmobile".into(),
            without: Vec::new(),
            approach: None,
            corrections: None,
        }
    }
}

/// A written world.
#[derive(Clone, Debug)]
pub struct Imported {
    pub dir: PathBuf,
    pub objects: usize,
    pub tasks: usize,
    pub hash: String,
}

/// Physical values per AffordPose category: the URDFs give every object 0.6 kg and a
/// placeholder inertia, so mass is ours, with its source; friction is the URDFs' own.
struct Category {
    mass: f32,
    fragility: &'static str,
    flags: &'static [&'static str],
    source: &'static str,
}

fn category(name: &str) -> Category {
    let (mass, fragility, flags, source): (f32, &str, &[&str], &str) = match name {
        "faucet" => (
            0.3,
            "sturdy",
            &["handle"],
            "the built-in world's faucet (a tap lever)",
        ),
        "handle_bottle" => (
            0.35,
            "normal",
            &["handle", "round"],
            "a part-filled 0.5 l bottle with a carry handle (estimate)",
        ),
        "bottle" => (
            0.3,
            "normal",
            &["round", "elongated"],
            "a part-filled 0.3-0.5 l bottle (estimate)",
        ),
        "dispenser" => (
            0.35,
            "normal",
            &["button", "round"],
            "the built-in world's spray bottle (0.35 kg)",
        ),
        "knife" => (
            0.15,
            "normal",
            &["handle", "elongated"],
            "a kitchen knife, 100-200 g in retail listings",
        ),
        "jar" => (0.3, "sturdy", &["round"], "the built-in world's jar"),
        "earphone" => (
            0.25,
            "normal",
            &["handle"],
            "over-ear headphones, 200-300 g in retail listings",
        ),
        "scissors" => (
            0.1,
            "sturdy",
            &["handle", "elongated"],
            "office scissors, 80-120 g in retail listings",
        ),
        _ => (
            0.3,
            "normal",
            &[],
            "the built-in world's median object mass",
        ),
    };
    Category {
        mass,
        fragility,
        flags,
        source,
    }
}

/// The resisting torque of a twist object's anchor (N m) and the torque a twist must reach:
/// the built-in world's jar (worlds/crm/benchmark.json).
const TWIST_RESIST: f32 = 0.3;
const TWIST_REQUIRED: f32 = 0.15;
/// The force a press must reach (N): the built-in world's spray bottle and dispenser.
const PRESS_REQUIRED: f32 = 6.0;
/// Angular damping (1/s) standing in for the `rolling_friction` and `spinning_friction` of
/// 1.0 in every target.urdf (PyBullet resists an object's rolling; rapier has no such
/// friction): without it a bottle rocked 1.6 cm off its start in 5 s; 5 was the smallest of
/// 2, 5, 10, 20 that held every object that stands still.
const ANGULAR_DAMPING: f32 = 5.0;
/// Half side and thickness (m) of the plate an object that does not stand by itself is put
/// on (their rolling friction held up a standing knife, scissors and headphones).
const STAND_HALF: f32 = 0.06;
const STAND_THICKNESS: f32 = 0.005;
/// Control steps (5 s) an object must stand alone without tipping (tilt under 0.15 rad).
const SETTLE_STEPS: usize = 150;

/// An object's mesh as its `target.urdf` names it.
struct ObjectFile {
    /// Relative to the repository.
    mesh: String,
    scale: [f32; 3],
    origin: (Vec3, Rotation),
    friction: f32,
}

fn rpy(r: [f64; 3]) -> Rotation {
    Rotation::from_rotation_z(r[2] as f32)
        * Rotation::from_rotation_y(r[1] as f32)
        * Rotation::from_rotation_x(r[0] as f32)
}

/// `objects/<id>/`, or a folder named `<id>_...` (the repository has `103416_dispensor`).
fn object_folder(repo: &Path, id: &str) -> Option<PathBuf> {
    let plain = repo.join("objects").join(id);
    if plain.is_dir() {
        return Some(plain);
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(repo.join("objects"))
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with(&format!("{id}_")))
        })
        .collect();
    found.sort();
    found.into_iter().next()
}

fn object_file(repo: &Path, csv_path: &Path, row: &Row) -> Result<ObjectFile> {
    let at = format!("line {}, column \"Object ID\"", row.line);
    let folder = object_folder(repo, &row.object).ok_or_else(|| {
        invalid_at(
            csv_path,
            &at,
            format!(
                "no folder objects/{0} or objects/{0}_* in {1}",
                row.object,
                repo.display()
            ),
        )
    })?;
    let urdf_path = folder.join("target.urdf");
    if !urdf_path.is_file() {
        return Err(invalid_at(
            csv_path,
            &at,
            format!("{} is missing", urdf_path.display()),
        ));
    }
    let text = read_text(&urdf_path)?;
    let robot = rapier3d_urdf::urdf_rs::read_from_string(&text)
        .map_err(|e| invalid_at(&urdf_path, "robot", e.to_string()))?;
    let collision = robot
        .links
        .iter()
        .flat_map(|l| l.collision.iter())
        .next()
        .ok_or_else(|| invalid_at(&urdf_path, "collision", "no collision element"))?;
    let rapier3d_urdf::urdf_rs::Geometry::Mesh { filename, scale } = &collision.geometry else {
        return Err(invalid_at(&urdf_path, "collision", "not a mesh"));
    };
    let mesh = folder.join(filename);
    let empty = std::fs::metadata(&mesh)
        .map(|m| m.len() == 0)
        .unwrap_or(true);
    if empty {
        return Err(invalid_at(
            csv_path,
            &at,
            format!("mesh {} is missing or empty", mesh.display()),
        ));
    }
    let relative = mesh
        .strip_prefix(repo)
        .map(|p| p.to_string_lossy().replace('\\', "/"))
        .map_err(|_| invalid_at(&urdf_path, "collision", "mesh outside the repository"))?;
    let s = scale.map(|s| *s).unwrap_or([1.0; 3]);
    let o = &collision.origin;
    // PyBullet's lateral friction, as every target.urdf writes it.
    let friction = text
        .split("lateral_friction")
        .nth(1)
        .and_then(|rest| rest.split('"').nth(1))
        .and_then(csv::number)
        .unwrap_or(1.0);
    Ok(ObjectFile {
        mesh: relative,
        scale: s.map(|v| v as f32),
        origin: (
            Vec3::new(o.xyz[0] as f32, o.xyz[1] as f32, o.xyz[2] as f32),
            rpy([o.rpy[0], o.rpy[1], o.rpy[2]]),
        ),
        friction,
    })
}

fn quat(q: [f32; 4]) -> Rotation {
    Rotation::from_xyzw(q[0], q[1], q[2], q[3]).normalize()
}

/// Six decimals, as f64 so the JSON reads `0.026199`, not `0.026198999956250191`.
fn round(v: f32) -> f64 {
    (f64::from(v) * 1e6).round() / 1e6
}

fn round_all<const N: usize>(v: [f32; N]) -> [f64; N] {
    v.map(round)
}

/// Where the authors' arm starts the hand's end-effector link (`Helper.endEffectorPos`, their
/// world frame); a task's start is this minus its grasp location there.
const ARM_START: [f32; 3] = [0.65, -0.7, 0.6];

/// The objects and tasks of `rows` (benchmark.json) and where each value comes from.
fn benchmark(repo: &Path, csv_path: &Path, rows: &[Row]) -> Result<(Value, Value)> {
    let mut objects: Vec<Value> = Vec::new();
    let mut names: BTreeMap<String, String> = BTreeMap::new();
    let mut sources = serde_json::Map::new();
    let mut tasks = Vec::new();
    for row in rows {
        let file = object_file(repo, csv_path, row)?;
        let anchored = row.objective == Objective::Twist;
        let q_obj = quat(row.q_obj);
        let key = format!(
            "{}|{anchored}|{:?}",
            row.object,
            row.q_obj.map(|v| (v * 1e4).round() / 1e4)
        );
        let name = match names.get(&key) {
            Some(name) => name.clone(),
            None => {
                let base = format!(
                    "{}-{}{}",
                    row.category,
                    row.object,
                    if anchored { "-fixed" } else { "" }
                );
                let taken = names.values().filter(|n| n.starts_with(&base)).count();
                let name = if taken == 0 {
                    base
                } else {
                    format!("{base}-{}", taken + 1)
                };
                let cat = category(&row.category);
                // A twist turns a part of an anchored object (a cap, a pump, a lever): the
                // hand does not carry it, so it is sturdy whatever its category (over 3 seeds
                // per task the oracle crushed 10 objects with them `normal`, 2 `sturdy`:
                // docs/notebook/worlds.md).
                let fragility = if anchored { "sturdy" } else { cat.fragility };
                let turn = q_obj * file.origin.1;
                let flags: serde_json::Map<String, Value> = cat
                    .flags
                    .iter()
                    .map(|f| ((*f).to_string(), Value::Bool(true)))
                    .collect();
                let mut object = json!({
                    "name": name,
                    "mass": round(cat.mass),
                    "friction": round(file.friction),
                    "fragility": fragility,
                    "parts": [{
                        "shape": "mesh",
                        "file": file.mesh,
                        "scale": round_all(file.scale),
                        "axis_angle": round_all(turn.to_scaled_axis().to_array()),
                        "pos": round_all((q_obj * file.origin.0).to_array()),
                    }],
                    "flags": flags,
                    "angular_damping": ANGULAR_DAMPING,
                });
                if anchored {
                    object["anchor"] = json!({ "resist_torque": TWIST_RESIST });
                }
                sources.insert(
                    name.clone(),
                    json!({
                        "mesh": file.mesh,
                        "pose": format!("q_obj of {} line {}", REQUIRED[0], row.line),
                        "mass": format!("{} kg: {}", cat.mass, cat.source),
                        "friction": format!("{}: lateral_friction of its target.urdf", file.friction),
                        "fragility": if anchored {
                            "sturdy: anchored, the hand turns a part of it".to_string()
                        } else {
                            format!("{}: ours, by category", cat.fragility)
                        },
                        "anchor": anchored.then(|| format!(
                            "{TWIST_RESIST} N m resisting, {TWIST_REQUIRED} N m to reach: the built-in jar's"
                        )),
                    }),
                );
                names.insert(key, name.clone());
                objects.push(object);
                name
            }
        };
        let offset = q_obj * Vec3::from(row.trans);
        let orientation = q_obj * quat(row.orientation);
        let start = Vec3::from(ARM_START) - (Vec3::from(row.p_obj) + offset);
        let (motion, required) = match row.objective {
            Objective::Press => ([0.0, 0.0, -1.0f32], Some(PRESS_REQUIRED)),
            Objective::Pull => ([-1.0, 0.0, 1.0], None),
            Objective::Twist => {
                // Along the tangent of a counter-clockwise turn (seen from above) at the grasp.
                let radial = Vec3::new(offset.x, offset.y, 0.0);
                let tangent = if radial.length() > 0.01 {
                    Vec3::Z.cross(radial).normalize()
                } else {
                    Vec3::Y
                };
                (tangent.to_array(), Some(TWIST_REQUIRED))
            }
            _ => ([0.0, 0.0, 1.0], None),
        };
        let mut task = json!({
            "id": format!("t{:02}-{}-{}", row.task, row.category, row.objective.name()),
            "object": name,
            "objective": row.objective.name(),
            "topology": row.topology.name(),
            "grasp": {
                "offset": round_all(offset.to_array()),
                "orientation": round_all([orientation.x, orientation.y, orientation.z, orientation.w]),
            },
            "motion": round_all(motion),
            "start": round_all(start.to_array()),
        });
        if let Some(required) = required {
            task["required"] = json!(required);
        }
        tasks.push(task);
    }
    Ok((
        json!({ "objects": objects, "tasks": tasks }),
        Value::Object(sources),
    ))
}

/// The objects that do not stand still on our table for [`SETTLE_STEPS`] with the hand at
/// its start, each task's object once.
fn tipping_objects(world: &World) -> Result<Vec<String>> {
    let mut seen = std::collections::BTreeSet::new();
    let mut tipping = Vec::new();
    for (t, task) in world.benchmark.tasks.iter().enumerate() {
        if !seen.insert(task.object.clone()) {
            continue;
        }
        let mut env =
            crate::GraspEnv::new(world.benchmark.clone(), crate::SimConfig::deterministic());
        env.set_task_choice(crate::TaskChoice::Fixed(t))?;
        let machine = crate::spec::grasping_machine();
        let mut episode = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
        episode.reset(0)?;
        let mut tipped = false;
        for _ in 0..SETTLE_STEPS {
            let step = episode.step(&[0.0; 3])?;
            let env = episode.env();
            let tilt = env
                .scene()
                .and_then(|s| s.world.bodies.get(s.object))
                .map(|b| {
                    (b.position().rotation * Vec3::Z)
                        .dot(Vec3::Z)
                        .clamp(-1.0, 1.0)
                        .acos()
                })
                .unwrap_or(0.0);
            if tilt > 0.15 || step.done || step.truncated {
                tipped = tilt > 0.15 || step.done;
                break;
            }
        }
        if tipped {
            tipping.push(task.object.clone());
        }
    }
    Ok(tipping)
}

/// Checks that `repo` is a copy of the authors' repository, naming the first file missing.
pub fn check_layout(repo: &Path) -> Result<()> {
    for file in REQUIRED {
        if !repo.join(file).is_file() {
            return Err(invalid_at(
                &repo.join(file),
                "file",
                format!("missing, so {} is not a copy of {SOURCE}", repo.display()),
            ));
        }
    }
    Ok(())
}

/// Imports the repository at `repo` into a new world folder `out` (which must not exist or
/// be empty). Nothing is written unless the whole world loads.
pub fn import(repo: &Path, out: &Path, options: &Options) -> Result<Imported> {
    check_layout(repo)?;
    let repo = repo.canonicalize().map_err(|error| Error::Io {
        path: repo.display().to_string(),
        error,
    })?;
    refuse_occupied(out)?;
    let csv_path = repo.join(REQUIRED[0]);
    let rows = csv::parse(&read_text(&csv_path)?, &csv_path)?;
    let (benchmark, sources) = benchmark(&repo, &csv_path, &rows)?;
    let assets = Assets {
        folders: vec![repo.clone()],
    };
    let description_path = repo.join(svh::DESCRIPTION);
    let description = Description::load(&description_path, &assets)?;
    let mut profile = svh::profile(&description)
        .map_err(|message| invalid_at(&description_path, "robot", message))?;
    // Where the authors' hand couples, commands or holds a joint otherwise than the SVH's
    // description does, the import keeps theirs and says so (`crm world check` asks it).
    if let Ok(model) = crate::hand::HandModel::new(&description, &profile, &description_path) {
        let mut joints: Vec<String> = model
            .couplings
            .conflicts
            .iter()
            .map(|c| c.joint.clone())
            .collect();
        joints.dedup();
        profile.description_overrides = joints;
    }

    let world = write_world(out, "import", |staging| {
        let mut world = json!({
            "name": options.name,
            "hand": "hand.json",
            "benchmark": "benchmark.json",
            "assets": [repo],
        });
        if !options.without.is_empty() {
            world["sensors"] = json!({ "without": options.without });
        }
        if let Some(approach) = options.approach {
            world["approach"] = json!(approach);
        }
        if let Some(text) = &options.corrections {
            let path = staging.join("corrections.json");
            std::fs::write(&path, text).map_err(|error| crate::error::Error::Io {
                path: path.display().to_string(),
                error,
            })?;
            world["corrections"] = json!("corrections.json");
        }
        write_json(&staging.join("world.json"), &world)?;
        write_json(&staging.join("hand.json"), &profile)?;
        write_json(&staging.join("benchmark.json"), &benchmark)?;
        let sources = json!({
            "repository": SOURCE,
            "copy": repo,
            "tasks": REQUIRED[0],
            "hand": format!("{} (the right SVH; profile from crm_ppo/Helper.py)", svh::DESCRIPTION),
            "objects": sources,
        });
        write_json(&staging.join("sources.json"), &sources)?;
        let world = World::load_with(staging, &Assets::default())?;
        let tipping = tipping_objects(&world)?;
        if tipping.is_empty() {
            return Ok(world);
        }
        let mut benchmark = benchmark.clone();
        let mut sources = sources.clone();
        for name in &tipping {
            let Some(object) = world.benchmark.object(name) else {
                continue;
            };
            let (min, max) = object.bounds();
            let plate = json!({
                "shape": "cuboid",
                "half_extents": [STAND_HALF, STAND_HALF, STAND_THICKNESS / 2.0],
                "pos": round_all([
                    (min[0] + max[0]) / 2.0,
                    (min[1] + max[1]) / 2.0,
                    min[2] - STAND_THICKNESS / 2.0,
                ]),
            });
            if let Some(parts) = benchmark["objects"]
                .as_array_mut()
                .and_then(|objects| objects.iter_mut().find(|o| o["name"] == name.as_str()))
                .and_then(|o| o["parts"].as_array_mut())
            {
                parts.push(plate);
            }
            sources["objects"][name]["stand"] = json!(format!(
                "tipped over alone on our table (rapier has no rolling friction), so it stands \
                 on a {0} x {0} x {1} m plate",
                2.0 * STAND_HALF,
                STAND_THICKNESS
            ));
        }
        write_json(&staging.join("benchmark.json"), &benchmark)?;
        write_json(&staging.join("sources.json"), &sources)?;
        let world = World::load_with(staging, &Assets::default())?;
        match tipping_objects(&world)?.first() {
            Some(name) => Err(invalid_at(
                &staging.join("benchmark.json"),
                format!("objects.{name}"),
                "tips over on our table even on a stand",
            )),
            None => Ok(world),
        }
    })?;
    Ok(Imported {
        dir: out.to_path_buf(),
        objects: world.benchmark.objects.len(),
        tasks: world.benchmark.tasks.len(),
        hash: world.hash,
    })
}
