//! One module per subcommand.

pub mod bench;
pub mod eval;
pub mod oracle;
pub mod record;
pub mod results;
pub mod service;
pub mod tasks;
pub mod topology;
pub mod train;

use std::path::PathBuf;
use std::sync::Arc;

use std::io::Write;

use anyhow::Context;
use grasp_sim::{Benchmark, SimConfig};

/// Options every environment-running command shares.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct EnvArgs {
    /// A benchmark file to use instead of the built-in one.
    #[arg(long, value_name = "FILE")]
    pub benchmark: Option<PathBuf>,
    /// A CRM spec file to use instead of the built-in grasping spec.
    #[arg(long, value_name = "FILE")]
    pub spec: Option<PathBuf>,
    /// Turn domain randomization off (it is on by default, as in the paper).
    #[arg(long)]
    pub no_randomization: bool,
}

impl EnvArgs {
    pub fn benchmark(&self) -> anyhow::Result<Arc<Benchmark>> {
        Ok(Arc::new(match &self.benchmark {
            Some(path) => Benchmark::load(path).context("loading the benchmark")?,
            None => Benchmark::builtin(),
        }))
    }

    /// The machine from `--spec`, or the built-in grasping machine.
    pub fn machine(&self) -> anyhow::Result<crm::Machine> {
        self.machine_or(grasp_sim::spec::grasping_spec())
    }

    /// The machine from `--spec`, or `default`.
    pub fn machine_or(&self, default: crm::Spec) -> anyhow::Result<crm::Machine> {
        let spec = match &self.spec {
            Some(path) => crm::Spec::load(path).context("loading the crm spec")?,
            None => default,
        };
        grasp_sim::spec::check_compatible(&spec)?;
        Ok(crm::Machine::from_spec(spec)?)
    }

    pub fn config(&self) -> SimConfig {
        if self.no_randomization {
            SimConfig::deterministic()
        } else {
            SimConfig::default()
        }
    }
}

/// A JSON settings file (`--config`-style flags) or, without one, the defaults.
pub fn read_json<T: serde::de::DeserializeOwned + Default>(
    path: &Option<PathBuf>,
) -> anyhow::Result<T> {
    match path {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
        }
        None => Ok(T::default()),
    }
}

/// The index of a task by id, or a message naming the flag and pointing at `crm tasks`.
pub fn task_index(benchmark: &Benchmark, id: &str) -> anyhow::Result<usize> {
    benchmark
        .tasks
        .iter()
        .position(|t| t.id == id)
        .with_context(|| format!("--task: unknown task {id:?} (see `crm tasks`)"))
}

/// Writes to standard output; a closed pipe (`crm tasks | head`) ends the output quietly.
pub fn emit(text: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(err) if err.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}
