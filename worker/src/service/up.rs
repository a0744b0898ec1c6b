//! `crm up`: the coordinator and local workers in one process, on loopback by default. The
//! workers talk to the coordinator over real gRPC, as remote ones would.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use crm_server::ServerConfig;

use super::{WorkerOptions, run_worker};

/// Starts everything and serves until ctrl-c.
pub fn up_main(config: ServerConfig, workers: usize, options: WorkerOptions) -> anyhow::Result<()> {
    crm_server::init_logging();
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(async move {
        let running = crm_server::start(config).await?;
        let token = running.state.tokens.for_workers();
        let scheme = if running.tls { "https" } else { "http" };
        println!("crm-grasp is up");
        println!("  dashboard  {scheme}://{}/", running.http_addr);
        println!(
            "  REST API   {scheme}://{}/api/v1  (OpenAPI: /api/v1/openapi.json)",
            running.http_addr
        );
        println!("  gRPC       {scheme}://{}", running.grpc_addr);
        println!("  data       {}", running.state.config.data_dir.display());
        println!("  workers    {workers} local");
        let stop = Arc::new(AtomicBool::new(false));
        let mut handles = Vec::new();
        for k in 0..workers {
            let options = WorkerOptions {
                coordinator: format!("{scheme}://{}", running.grpc_addr),
                token: token.clone(),
                name: format!("{}-local{}", options.name, k + 1),
                ..options.clone()
            };
            let stop = stop.clone();
            handles.push(tokio::spawn(async move {
                if let Err(err) = run_worker(options, stop).await {
                    tracing::error!(err = format!("{err:#}"), "local worker stopped");
                }
            }));
        }
        tokio::signal::ctrl_c().await?;
        tracing::info!("shutting down");
        stop.store(true, Ordering::Relaxed);
        for handle in handles {
            handle.abort();
        }
        running.stop().await
    });
    // A job still learning on a blocking thread is not waited for: its lease runs out and
    // the coordinator re-queues it, to be resumed from its last checkpoint.
    runtime.shutdown_timeout(std::time::Duration::from_secs(2));
    result
}
