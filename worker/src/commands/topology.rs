//! `crm topology train|predict`: the grasp-topology network on the benchmark's objects.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use anyhow::Context;
use crm_learn::{Example, Noise, TopologyNet};
use grasp_sim::Benchmark;
use grasp_sim::benchmark::{OBJECT_FEATURES, Object, Objective, Topology};

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

/// Network input: object features (sizes in decimetres) and a one-hot objective.
fn input(object: &Object, objective: Objective, noise: Option<&mut Noise>) -> Vec<f32> {
    let mut features = object.features();
    for size in &mut features[..3] {
        *size *= 10.0;
    }
    if let Some(noise) = noise {
        // Sizes and mass, as a depth camera would misjudge them.
        for value in &mut features[..4] {
            *value *= 1.0 + 0.1 * noise.normal();
        }
        features[4] += 0.05 * noise.normal();
    }
    let mut out = features.to_vec();
    out.extend(
        Objective::ALL
            .iter()
            .map(|&o| if o == objective { 1.0 } else { 0.0 }),
    );
    out
}

fn input_names() -> Vec<String> {
    OBJECT_FEATURES
        .iter()
        .map(|f| f.to_string())
        .chain(
            Objective::ALL
                .iter()
                .map(|o| format!("objective_{}", o.name())),
        )
        .collect()
}

fn labels(benchmark: &Benchmark) -> BTreeMap<(String, Objective), BTreeSet<Topology>> {
    let mut pairs: BTreeMap<(String, Objective), BTreeSet<Topology>> = BTreeMap::new();
    for task in &benchmark.tasks {
        pairs
            .entry((task.object.clone(), task.objective))
            .or_default()
            .insert(task.topology);
    }
    pairs
}

/// The shipped selection network (`models/topology.safetensors`, made by
/// `crm topology train --seed 0`), compiled in so every worker has it.
const SHIPPED: &[u8] = include_bytes!("../../../models/topology.safetensors");

/// The network's probabilities (in `Topology::ALL` order) for every task of the benchmark
/// (its object and objective), from `model` or the shipped network.
pub fn probabilities(
    benchmark: &Benchmark,
    model: Option<&std::path::Path>,
) -> anyhow::Result<Vec<Vec<f32>>> {
    let (net, inputs, outputs) = match model {
        Some(path) => TopologyNet::load(path)?,
        None => {
            TopologyNet::from_bytes(SHIPPED, std::path::Path::new("models/topology.safetensors"))?
        }
    };
    if inputs != input_names() {
        anyhow::bail!("the topology network was trained on other inputs");
    }
    let names: Vec<&str> = Topology::ALL.iter().map(|t| t.name()).collect();
    if outputs != names {
        anyhow::bail!("the topology network has other outputs than the benchmark's topologies");
    }
    let rows: Vec<Vec<f32>> = benchmark
        .tasks
        .iter()
        .map(|task| input(benchmark.object_of(task), task.objective, None))
        .collect();
    Ok(net.predict(&rows)?)
}

/// The highest-probability topology of one row of `probabilities`.
fn best(probabilities: &[f32]) -> Topology {
    let k = probabilities
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(k, _)| k);
    Topology::ALL[k.min(Topology::ALL.len() - 1)]
}

/// The network's highest-probability topology for every task of the benchmark.
pub fn picks(
    benchmark: &Benchmark,
    model: Option<&std::path::Path>,
) -> anyhow::Result<Vec<Topology>> {
    Ok(probabilities(benchmark, model)?
        .iter()
        .map(|p| best(p))
        .collect())
}

/// Every task's assigned topology, the network's pick and its probabilities, as JSON.
pub fn table(
    benchmark: &Benchmark,
    model: Option<&std::path::Path>,
) -> anyhow::Result<serde_json::Value> {
    let probabilities = probabilities(benchmark, model)?;
    let tasks: Vec<serde_json::Value> = benchmark
        .tasks
        .iter()
        .zip(&probabilities)
        .map(|(task, p)| {
            serde_json::json!({
                "task": task.id,
                "object": task.object,
                "objective": task.objective.name(),
                "assigned": task.topology.name(),
                "picked": best(p).name(),
                "probabilities": Topology::ALL.iter().zip(p)
                    .map(|(t, &v)| (t.name().to_string(), (f64::from(v) * 1e4).round() / 1e4))
                    .collect::<BTreeMap<_, _>>(),
            })
        })
        .collect();
    Ok(serde_json::json!({
        "model": model.map_or("models/topology.safetensors".to_string(), |m| m.display().to_string()),
        "topologies": Topology::ALL.iter().map(|t| t.name()).collect::<Vec<_>>(),
        "tasks": tasks,
    }))
}

pub fn run(command: TopologyCommand) -> anyhow::Result<()> {
    match command {
        TopologyCommand::Train(args) => train(args),
        TopologyCommand::Predict(args) => predict(args),
        TopologyCommand::Table(args) => {
            let benchmark = args.env.benchmark()?;
            let table = table(&benchmark, args.model.as_deref())?;
            emit(&format!("{}\n", serde_json::to_string_pretty(&table)?))
        }
    }
}

fn train(args: TrainArgs) -> anyhow::Result<()> {
    if args.samples < 5 {
        anyhow::bail!("--samples must be at least 5, got {}", args.samples);
    }
    let benchmark = args.env.benchmark()?;
    let pairs = labels(&benchmark);
    let mut noise = Noise::new(args.seed);
    let (mut train, mut held_out) = (Vec::new(), Vec::new());
    for ((object, objective), topologies) in &pairs {
        let object = benchmark.object(object).context("benchmark object")?;
        let label: Vec<f32> = Topology::ALL
            .iter()
            .map(|t| if topologies.contains(t) { 1.0 } else { 0.0 })
            .collect();
        for k in 0..args.samples {
            let example = Example {
                input: input(object, *objective, Some(&mut noise)),
                label: label.clone(),
            };
            if k % 5 == 4 {
                held_out.push(example)
            } else {
                train.push(example)
            }
        }
    }
    let mut net = TopologyNet::new(input_names().len(), 64, Topology::ALL.len(), args.seed)?;
    let loss = net.train(&train, 600, 1e-2)?;
    let report = serde_json::json!({
        "pairs": pairs.len(),
        "train_examples": train.len(),
        "held_out_examples": held_out.len(),
        "final_loss": loss,
        "train_accuracy": net.accuracy(&train)?,
        "held_out_accuracy": net.accuracy(&held_out)?,
        "model": args.out.display().to_string(),
    });
    let outputs: Vec<String> = Topology::ALL.iter().map(|t| t.name().to_string()).collect();
    net.save(&args.out, &input_names(), &outputs)?;
    if args.json {
        emit(&format!("{report}\n"))
    } else {
        emit(&format!("{}\n", serde_json::to_string_pretty(&report)?))
    }
}

fn predict(args: PredictArgs) -> anyhow::Result<()> {
    let benchmark = args.env.benchmark()?;
    let object = benchmark.object(&args.object).with_context(|| {
        format!(
            "--object: unknown object {:?} (see `crm tasks`)",
            args.object
        )
    })?;
    let objective = Objective::ALL
        .into_iter()
        .find(|o| o.name() == args.objective)
        .with_context(|| format!("--objective: unknown objective {:?}", args.objective))?;
    let (net, inputs, outputs) = TopologyNet::load(&args.model)?;
    if inputs != input_names() {
        anyhow::bail!("model {} was trained on other inputs", args.model.display());
    }
    let probabilities = net.predict(&[input(object, objective, None)])?.remove(0);
    let best = probabilities
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(k, _)| outputs[k].clone())
        .unwrap_or_default();
    let assigned: Vec<&str> = labels(&benchmark)
        .get(&(object.name.clone(), objective))
        .map(|set| set.iter().map(|t| t.name()).collect())
        .unwrap_or_default();
    let report = serde_json::json!({
        "object": object.name,
        "objective": objective.name(),
        "topology": best,
        "probabilities": outputs.iter().cloned().zip(probabilities.iter().copied()).collect::<BTreeMap<_, _>>(),
        "benchmark_topologies": assigned,
    });
    emit(&format!(
        "{}\n",
        if args.json {
            report.to_string()
        } else {
            serde_json::to_string_pretty(&report)?
        }
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_network_picks_the_assigned_topology_for_most_tasks() {
        let benchmark = Benchmark::builtin();
        let picks = picks(&benchmark, None).expect("picks");
        assert_eq!(picks.len(), benchmark.tasks.len());
        // Where an (object, objective) pair has several assigned topologies, any is right.
        let labels = labels(&benchmark);
        let right = benchmark
            .tasks
            .iter()
            .zip(&picks)
            .filter(|(task, pick)| labels[&(task.object.clone(), task.objective)].contains(pick))
            .count();
        assert!(
            right * 10 >= benchmark.tasks.len() * 9,
            "{right} of {}",
            benchmark.tasks.len()
        );
    }

    #[test]
    fn the_checked_in_picks_are_the_shipped_networks() {
        // `models/topology-picks.json` feeds the dashboard; it must not drift from the network.
        let shipped: serde_json::Value =
            serde_json::from_str(include_str!("../../../models/topology-picks.json"))
                .expect("models/topology-picks.json parses");
        let fresh = table(&Benchmark::builtin(), None).expect("table");
        assert_eq!(
            shipped["tasks"], fresh["tasks"],
            "regenerate with `crm topology table > models/topology-picks.json`"
        );
    }
}
