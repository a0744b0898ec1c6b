//! `crm topology train|predict|table`: the grasp-topology network (`crm_run::topology`) on
//! the benchmark's objects.

use std::path::PathBuf;

use crm_run::topology;

use super::{EnvArgs, emit};

#[derive(clap::Subcommand, Debug)]
pub enum TopologyCommand {
    /// Train on the benchmark's (object, objective) -> topologies with feature noise; report
    /// held-out accuracy.
    Train(TrainArgs),
    /// The network's topology probabilities for an object and an objective.
    Predict(PredictArgs),
    /// The network's probabilities and pick for every task of the benchmark, beside its
    /// assigned topology (JSON; `models/topology-picks.json` is this for the shipped network
    /// and feeds the dashboard's topology page).
    Table(TableArgs),
}

#[derive(clap::Args, Debug)]
pub struct TableArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// A network from `crm topology train`; the shipped one when absent.
    #[arg(long)]
    pub model: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// Where to write the network (safetensors).
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Noisy samples per (object, objective) pair; a fifth of them are held out.
    #[arg(long, default_value_t = 50)]
    pub samples: usize,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct PredictArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    #[arg(long)]
    pub model: PathBuf,
    #[arg(long)]
    pub object: String,
    /// lift, pull, press, twist, lever, wrap_grasp or handle_grasp.
    #[arg(long)]
    pub objective: String,
    #[arg(long)]
    pub json: bool,
}

pub fn run(command: TopologyCommand) -> anyhow::Result<()> {
    match command {
        TopologyCommand::Train(args) => train(args),
        TopologyCommand::Predict(args) => predict(args),
        TopologyCommand::Table(args) => {
            let benchmark = args.env.env().benchmark()?;
            let table = topology::table(&benchmark, args.model.as_deref())?;
            emit(&format!("{}\n", serde_json::to_string_pretty(&table)?))
        }
    }
}

fn train(args: TrainArgs) -> anyhow::Result<()> {
    let benchmark = args.env.env().benchmark()?;
    let report = topology::train(&benchmark, &args.out, args.seed, args.samples)?;
    print(&report, args.json)
}

fn predict(args: PredictArgs) -> anyhow::Result<()> {
    let benchmark = args.env.env().benchmark()?;
    let report = topology::predict(&benchmark, &args.model, &args.object, &args.objective)?;
    print(&report, args.json)
}

fn print(report: &serde_json::Value, json: bool) -> anyhow::Result<()> {
    emit(&format!(
        "{}\n",
        if json {
            report.to_string()
        } else {
            serde_json::to_string_pretty(report)?
        }
    ))
}
