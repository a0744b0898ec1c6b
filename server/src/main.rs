//! `crm-server`: the coordinator alone (REST, gRPC, sqlite), for a deployment where workers
//! run on other machines (`crm worker --coordinator URL`).

use clap::Parser;
use crm_server::ServerConfig;

#[derive(Parser)]
#[command(name = "crm-server", version, about = "The crm-grasp coordinator")]
struct Cli {
    #[command(flatten)]
    config: ServerConfig,
    /// A JSON file with the settings (flags given on the command line are ignored then).
    #[arg(long, value_name = "FILE")]
    config_file: Option<std::path::PathBuf>,
}

#[tokio::main]
async fn main() -> std::process::ExitCode {
    crm_server::init_logging();
    let cli = Cli::parse();
    let result = async {
        let config = match &cli.config_file {
            Some(path) => crm_server::config::load(path)?,
            None => cli.config,
        };
        let running = crm_server::start(config).await?;
        let scheme = if running.tls { "https" } else { "http" };
        println!(
            "crm-server: dashboard {scheme}://{0}/  REST {scheme}://{0}/api/v1  gRPC {scheme}://{1}",
            running.http_addr, running.grpc_addr
        );
        running.wait().await
    }
    .await;
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::from(2)
        }
    }
}
