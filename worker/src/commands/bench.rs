//! `crm bench`: figures from the real environment.

#[derive(clap::Subcommand, Debug)]
pub enum BenchCommand {
    /// Control steps per second of the grasping environment with random actions.
    Env(EnvBenchArgs),
}

#[derive(clap::Args, Debug)]
pub struct EnvBenchArgs {
    #[arg(long)]
    pub json: bool,
}

pub fn run(command: BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Env(_) => anyhow::bail!("not yet"),
    }
}
