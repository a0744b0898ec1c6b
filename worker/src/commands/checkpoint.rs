//! `crm checkpoint show FILE`: what a checkpoint is and how it was made (its lineage);
//! `crm checkpoint export FILE --onnx OUT`: its deterministic policy as an ONNX model for a
//! robot's runtime, with sample observations and actions to check that runtime against.

use std::path::PathBuf;

use anyhow::Context;
use crm_learn::Checkpoint;

use super::emit;

#[derive(clap::Subcommand, Debug)]
pub enum CheckpointCommand {
    /// Print a checkpoint's header: algorithm, world, steps, and every training run that led
    /// to it (its lineage).
    Show(ShowArgs),
    /// Write the deterministic policy as ONNX (`crm_learn::onnx`): the observation's
    /// normalization, the stage's one-hot and action mask, the network and the squashing, with
    /// the contract (features, actions, stages, world hash, lineage) in its metadata.
    Export(Box<ExportArgs>),
}

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// The checkpoint (`.safetensors`).
    pub file: PathBuf,
    /// Where to write the ONNX model.
    #[arg(long, value_name = "OUT.onnx")]
    pub onnx: PathBuf,
    /// Also write this many steps of the policy's deterministic episodes (observation, stage,
    /// action, as `crm` computes them) as JSON, to check a runtime against.
    #[arg(long, value_name = "N", requires = "samples_out")]
    pub samples: Option<usize>,
    #[arg(long, value_name = "FILE.json")]
    pub samples_out: Option<PathBuf>,
    /// The sample episodes' seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub env: super::EnvArgs,
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
        CheckpointCommand::Export(args) => export(*args),
    }
}

fn export(args: ExportArgs) -> anyhow::Result<()> {
    let bytes = crm_run::export::onnx(&args.file, args.env.env())
        .with_context(|| format!("exporting {}", args.file.display()))?;
    std::fs::write(&args.onnx, &bytes)
        .with_context(|| format!("writing {}", args.onnx.display()))?;
    eprintln!("wrote {} ({} bytes)", args.onnx.display(), bytes.len());
    if let (Some(count), Some(out)) = (args.samples, &args.samples_out) {
        let samples = crm_run::export::samples(&args.file, args.env.env(), count, args.seed)?;
        std::fs::write(out, serde_json::to_vec(&samples)?)
            .with_context(|| format!("writing {}", out.display()))?;
        eprintln!("wrote {} ({} steps)", out.display(), samples.stage.len());
    }
    Ok(())
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
