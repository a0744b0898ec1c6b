//! `crm`: the command-line front of crm-grasp. Thin glue over the library crates.

mod commands;
mod mlflow;
mod record;
mod service;
mod video;

use clap::{Parser, Subcommand};

/// Sets `RAYON_NUM_THREADS` to the threads rayon would use anyway (the available
/// parallelism), unless it is set. candle asks for its thread count before every matrix
/// product and, without the variable, counts the physical cores by reading `/proc/cpuinfo`:
/// three reads per policy step of every environment, about 8% of a training iteration's time
/// (docs/BENCHMARKS.md, "Learning speed end to end"). With it, the count is one variable
/// lookup; rayon's pool is the same size, and every product still runs on one thread
/// (`crm_learn::kernels`), so results are bit for bit the same.
///
/// Sets `CANDLE_NUM_THREADS` to 1, unless it is set: candle splits an element-wise op of
/// 65,536 elements or more (a 256-row minibatch through a 256-wide layer: CRM-SAC's update)
/// over a pool of its own whose threads spin while they wait, against the environments'
/// rayon threads. On one thread those ops run inline; each element is computed alone either
/// way, so results are bit for bit the same, and CRM-SAC trains faster (docs/BENCHMARKS.md,
/// "CRM-SAC's element-wise ops").
fn name_thread_count() {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    for (name, value) in [
        ("RAYON_NUM_THREADS", threads.to_string()),
        ("CANDLE_NUM_THREADS", "1".to_string()),
    ] {
        if std::env::var_os(name).is_some() {
            continue;
        }
        // SAFETY: called first thing in `main`, before any other thread exists, so nothing
        // reads the environment while it changes.
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var(name, value);
        }
    }
}

#[derive(Parser)]
#[command(
    name = "crm",
    version,
    about = "Task-oriented dexterous grasping with a Contextual Reward Machine"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Start crm-grasp on this machine: the coordinator (REST, gRPC, sqlite) and local workers.
    Up(commands::service::UpArgs),
    /// A rollout worker: lease jobs from a coordinator and run them.
    Worker(commands::service::WorkerArgs),
    /// Serve a checkpoint's policy over gRPC (the `Policy` service).
    ServePolicy(commands::service::ServePolicyArgs),
    /// Run the scripted oracle (no learning) over the benchmark's tasks.
    Oracle(commands::oracle::OracleArgs),
    /// List the benchmark: objects, objectives, topologies and tasks.
    Tasks(commands::tasks::TasksArgs),
    /// Print the grasping CRM: stages, events, edges and rewards.
    Spec(commands::tasks::SpecArgs),
    /// Train a policy with PPO inside the grasping CRM (crm-ppo, ippo, lppo) or flat (ppo).
    Train(commands::train::TrainArgs),
    /// Evaluate a checkpoint over random tasks: success and episode length per objective.
    Eval(commands::eval::EvalArgs),
    /// Replay one evaluation episode of a checkpoint into a rerun recording or a live viewer.
    Record(commands::record::RecordArgs),
    /// Drive one seeded episode with a file of actions; print each step as a JSON line.
    Replay(commands::replay::ReplayArgs),
    /// Train and evaluate every algorithm at one budget; write RESULTS.md and PNG curves.
    Results(commands::results::ResultsArgs),
    /// The grasp-topology selection network: train it or ask it.
    #[command(subcommand)]
    Topology(commands::topology::TopologyCommand),
    /// Benchmarks that print figures.
    #[command(subcommand)]
    Bench(commands::bench::BenchCommand),
    /// Worlds as folders: check one.
    #[command(subcommand)]
    World(commands::world::WorldCommand),
    /// Checkpoints: what one is and how it was made.
    #[command(subcommand)]
    Checkpoint(commands::checkpoint::CheckpointCommand),
    /// TLS certificates to try the coordinator's TLS with.
    #[command(subcommand)]
    Certs(commands::certs::CertsCommand),
}

fn main() -> std::process::ExitCode {
    name_thread_count();
    let cli = Cli::parse();
    // Parallel environments, one thread per matrix product (see `crm_learn::kernels`).
    crm_learn::kernels::one_thread_per_product();
    let result = match cli.command {
        Command::Up(args) => commands::service::up(args),
        Command::Worker(args) => commands::service::worker(args),
        Command::ServePolicy(args) => commands::service::serve_policy(args),
        Command::Oracle(args) => commands::oracle::run(args),
        Command::Tasks(args) => commands::tasks::run(args),
        Command::Spec(args) => commands::tasks::run_spec(args),
        Command::Train(args) => commands::train::run(args),
        Command::Eval(args) => commands::eval::run(args),
        Command::Record(args) => commands::record::run(args),
        Command::Replay(args) => commands::replay::run(args),
        Command::Results(args) => commands::results::run(args),
        Command::Topology(command) => commands::topology::run(command),
        Command::Bench(command) => commands::bench::run(command),
        Command::World(command) => commands::world::run(command),
        Command::Checkpoint(command) => commands::checkpoint::run(command),
        Command::Certs(command) => commands::certs::run(command),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::from(2)
        }
    }
}
