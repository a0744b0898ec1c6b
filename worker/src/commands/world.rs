//! `crm world check DIR`: load a world folder as every command would and print what it holds.

use std::path::PathBuf;

use super::emit;

#[derive(clap::Subcommand, Debug)]
pub enum WorldCommand {
    /// Load a world folder (hand description and profile, objects and meshes, tasks, spec,
    /// sensors) and print one JSON line; exits 2 naming the file and field that is wrong.
    Check(CheckArgs),
}

#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The world folder (with `world.json`).
    pub dir: PathBuf,
}

pub fn run(command: WorldCommand) -> anyhow::Result<()> {
    match command {
        WorldCommand::Check(args) => {
            let world = grasp_sim::World::load(&args.dir)?;
            emit(&format!("{}\n", world.summary()))
        }
    }
}
