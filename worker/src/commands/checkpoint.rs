//! `crm checkpoint show FILE`: what a checkpoint is and how it was made (its lineage).

use std::path::PathBuf;

use anyhow::Context;
use crm_learn::Checkpoint;

use super::emit;

#[derive(clap::Subcommand, Debug)]
pub enum CheckpointCommand {
    /// Print a checkpoint's header: algorithm, world, steps, and every training run that led
    /// to it (its lineage).
    Show(ShowArgs),
}

#[derive(clap::Args, Debug)]
pub struct ShowArgs {
    /// The checkpoint (`.safetensors`).
    pub file: PathBuf,
    /// The whole header as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(command: CheckpointCommand) -> anyhow::Result<()> {
    match command {
        CheckpointCommand::Show(args) => show(args),
    }
}

fn show(args: ShowArgs) -> anyhow::Result<()> {
    let header = Checkpoint::read_header(&args.file)
        .with_context(|| format!("reading {}", args.file.display()))?;
    if args.json {
        return emit(&format!("{}\n", serde_json::to_string_pretty(&header)?));
    }
    let mut text = format!(
        "{}: {} checkpoint, {} environment steps, seed {}\n\
         environment {}, world {} ({}), crm spec {}\n\
         network: {} inputs, hidden {:?}, {} actions\n\n",
        args.file.display(),
        header.algorithm,
        header.steps,
        header.seed,
        header.env_version,
        header.world.as_deref().unwrap_or("crm"),
        header.world_hash.as_deref().unwrap_or("built-in"),
        header.spec_hash,
        header.layout.input_width(),
        header.hidden,
        header.layout.actions,
    );
    if header.lineage.is_empty() {
        text.push_str("How it was made: not recorded in this file's header.\n");
    } else {
        text.push_str("How it was made:\n");
        text.push_str(&crm_learn::lineage::describe(&header.lineage));
    }
    emit(&text)
}
