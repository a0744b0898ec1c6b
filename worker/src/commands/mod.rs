//! One module per subcommand.

pub mod bench;
mod bench_hold;
pub mod certs;
pub mod checkpoint;
pub mod eval;
pub mod fit_grasps;
pub mod oracle;
pub mod record;
pub mod remote;
pub mod replay;
pub mod results;
pub mod service;
pub mod tasks;
pub mod topology;
pub mod train;
pub mod world;

use std::path::PathBuf;
use std::sync::OnceLock;

use std::io::Write;

use anyhow::Context;
use crm_api::ObjectiveMode;
use crm_run::{Env, EnvSpec};
use grasp_sim::EnvSettings;

/// Options every environment-running command shares: a [`crm_run::EnvSpec`] on the command
/// line.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct EnvArgs {
    /// A world folder (`world.json`: hand, objects, tasks, spec, sensors) to run instead of
    /// the built-in world; its files are found in the folder or in `CRM_ASSETS`.
    #[arg(long, value_name = "DIR", conflicts_with = "benchmark")]
    pub world: Option<PathBuf>,
    /// A benchmark file to use instead of the built-in one (with the built-in hand).
    #[arg(long, value_name = "FILE")]
    pub benchmark: Option<PathBuf>,
    /// A CRM spec file to use instead of the built-in grasping spec.
    #[arg(long, value_name = "FILE")]
    pub spec: Option<PathBuf>,
    /// Turn domain randomization off (it is on by default, as in the paper).
    #[arg(long)]
    pub no_randomization: bool,
    /// Who executes the objective once the grasp is ready (a job's `objective`):
    /// `scripted`, the paper's protocol (the arm, by script), or `learned` (the policy).
    #[arg(long, value_parser = objective_mode(), default_value = "scripted")]
    pub protocol: ObjectiveMode,
    /// How finger actions act: `closing` only (the authors' code, the default), or `signed`
    /// increments that also open the hand.
    #[arg(long, value_enum, default_value_t = FingerMode::Closing)]
    pub finger_actions: FingerMode,
    /// Seconds of steady hold the judge asks of lift, pull, lever, wrap and handle tasks (a
    /// job's `hold_s`; default: the paper's 5 s). A shorter hold simulates less but does not
    /// teach grasps that last 5 s (docs/LEARNING.md); evaluate with the default to report the
    /// paper's test.
    #[arg(long, value_name = "SECONDS", value_parser = parse_hold_s)]
    pub hold_s: Option<f64>,
    /// The runtime's environments of these options, made once.
    #[arg(skip)]
    built: OnceLock<Env>,
}

/// `--hold-s`: seconds within [`crm_api::jobs::HOLD_S_RANGE`].
fn parse_hold_s(text: &str) -> Result<f64, String> {
    let hold: f64 = text
        .parse()
        .map_err(|_| format!("{text:?} is not a number of seconds"))?;
    crm_api::jobs::check_hold_s(Some(hold))?;
    Ok(hold)
}

/// `--algo`: a learner by its name in the API (`crm_api::Algorithm`).
pub fn algorithm() -> impl clap::builder::TypedValueParser<Value = crm_api::Algorithm> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(crm_api::Algorithm::ALL.map(crm_api::Algorithm::name))
        .try_map(|name| crm_api::Algorithm::parse(&name).ok_or("not a learner"))
}

/// `--protocol`: an objective mode by its name in the API.
fn objective_mode() -> impl clap::builder::TypedValueParser<Value = ObjectiveMode> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(ObjectiveMode::ALL.map(ObjectiveMode::name))
        .try_map(|name| ObjectiveMode::parse(&name).ok_or("not an objective mode"))
}

/// `--finger-actions`: see [`grasp_sim::FingerActions`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum FingerMode {
    #[default]
    Closing,
    Signed,
}

impl EnvArgs {
    /// The options as the runtime takes them.
    pub fn spec(&self) -> EnvSpec {
        EnvSpec {
            world: self.world.clone(),
            benchmark: self.benchmark.clone(),
            spec: self.spec.clone(),
            settings: EnvSettings {
                randomization: !self.no_randomization,
                protocol: crm_run::env::protocol(self.protocol),
                finger_actions: match self.finger_actions {
                    FingerMode::Signed => grasp_sim::FingerActions::Signed,
                    FingerMode::Closing => grasp_sim::FingerActions::Closing,
                },
                hold_s: self.hold_s,
                settle_s: None,
            },
        }
    }

    /// The runtime's environments of these options (the world loaded once).
    pub fn env(&self) -> &Env {
        self.built.get_or_init(|| Env::new(self.spec()))
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

/// Writes to standard output; a closed pipe (`crm tasks | head`) ends the output quietly.
pub fn emit(text: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(err) if err.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}
