//! Where each link of the hand stands in the object's mesh frame at the first grasp step of
//! a task, the oracle approaching (no randomization): one JSON object on stdout.
//!
//! `scripts/dexmobile-pybullet-frames` prints the same from the authors' PyBullet
//! environment and compares the two, which is how an imported hand is checked against the
//! code it was imported from (docs/WORLDS.md, "Checking the import against PyBullet").
//!
//! ```sh
//! cargo run --release -p grasp-sim --example link-frames -- WORLD_DIR TASK_ID
//! ```

use std::path::Path;

use anyhow::{Context, bail};
use grasp_sim::benchmark::Shape;
use grasp_sim::oracle::Oracle;
use grasp_sim::{GraspEnv, SimConfig, TaskChoice, World};
use rapier3d::prelude::{Pose, Rotation, Vec3};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, id] = args.as_slice() else {
        bail!("usage: link-frames WORLD_DIR TASK_ID");
    };
    let world = World::load(Path::new(dir)).with_context(|| format!("loading {dir}"))?;
    let benchmark = world.benchmark.clone();
    let task = benchmark
        .task_index(id)
        .with_context(|| format!("no task {id:?} in {dir}"))?;
    let object = benchmark.object_of(&benchmark.tasks[task]);
    let part = object
        .parts
        .iter()
        .find_map(|part| match &part.shape {
            Shape::Mesh { axis_angle, .. } => Some(Pose::from_parts(
                Vec3::from(part.pos),
                Rotation::from_scaled_axis(Vec3::from(*axis_angle)),
            )),
            _ => None,
        })
        .with_context(|| format!("object {:?} has no mesh part", object.name))?;
    let machine = world.machine()?;
    let mut env = GraspEnv::new(benchmark.clone(), SimConfig::deterministic());
    env.set_task_choice(TaskChoice::Fixed(task))?;
    let mut crm_env = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
    let (mut stage, _) = crm_env.reset(0)?;
    let mut oracle = Oracle::new();
    loop {
        let name = crm_env.machine().stage_name(stage).to_string();
        let action = oracle.act(crm_env.env(), &name);
        let step = crm_env.step(&action)?;
        stage = step.stage;
        if step.done || step.truncated {
            bail!("{id}: the episode ended before the grasp stage");
        }
        if crm_env.machine().stage_name(stage) != "approach" {
            break;
        }
    }
    let scene = crm_env.env().scene().context("no scene")?;
    let body = scene
        .world
        .bodies
        .get(scene.object)
        .context("no object body")?;
    let to_mesh = (*body.position() * part).inverse();
    let mut links = serde_json::Map::new();
    for (i, link) in scene.hand.model.links.iter().enumerate() {
        let Some(body) = scene.world.bodies.get(scene.hand.bodies[i]) else {
            continue;
        };
        let pose = to_mesh * (*body.position() * scene.hand.offsets[i]);
        let (t, q) = (pose.translation, pose.rotation);
        links.insert(
            link.name.clone(),
            serde_json::json!([[t.x, t.y, t.z], [q.x, q.y, q.z, q.w]]),
        );
    }
    println!("{}", serde_json::json!({ "task": id, "links": links }));
    Ok(())
}
