//! `crm world check DIR`: load a world folder as every command would and print what it holds.
//! `crm world import-dexmobile PATH --out DIR`: write the paper's own world from a copy of the
//! authors' repository (`grasp_sim::import::dexmobile`), pointing at its files.

use std::path::PathBuf;

use super::emit;

#[derive(clap::Subcommand, Debug)]
pub enum WorldCommand {
    /// Load a world folder (hand description and profile, objects and meshes, tasks, spec,
    /// sensors) and print one JSON line; exits 2 naming the file and field that is wrong.
    Check(CheckArgs),
    /// Write a world folder from a copy of github.com/hhelium/DexMobile (the right SVH hand,
    /// the AffordPose objects, the 27 tasks of crm_ppo/topo/pos_all.csv). Nothing is copied:
    /// the world names PATH in its `assets`. Exits 2 naming the file (and the CSV's line and
    /// column) that is wrong, with nothing written.
    ImportDexmobile(ImportArgs),
}

#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The world folder (with `world.json`).
    pub dir: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// The authors' repository (a clone or an unpacked archive).
    pub path: PathBuf,
    /// The world folder to write; it must not exist, or be empty.
    #[arg(long)]
    pub out: PathBuf,
    /// The world's name.
    #[arg(long, default_value = "dexmobile")]
    pub name: String,
    /// Sensors the robot lacks (features or the paper's groups, e.g. `o_force`); repeat or
    /// separate with commas. The paper's real SVH: `--without o_force,o_torque,o_cone`.
    #[arg(long, value_delimiter = ',')]
    pub without: Vec<String>,
}

pub fn run(command: WorldCommand) -> anyhow::Result<()> {
    match command {
        WorldCommand::Check(args) => {
            let world = grasp_sim::World::load(&args.dir)?;
            emit(&format!("{}\n", world.summary()))
        }
        WorldCommand::ImportDexmobile(args) => {
            let options = grasp_sim::import::dexmobile::Options {
                name: args.name,
                without: args.without,
            };
            let imported = grasp_sim::import::dexmobile::import(&args.path, &args.out, &options)?;
            let line = serde_json::json!({
                "world": imported.dir,
                "objects": imported.objects,
                "tasks": imported.tasks,
                "hash": imported.hash,
            });
            emit(&format!("{line}\n"))
        }
    }
}
