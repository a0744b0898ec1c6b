//! The grasp-topology network (paper, section III-B) on a benchmark's objects: trained on its
//! (object, objective) -> topologies with feature noise, and the picks a job's `"topology":
//! "auto"` uses (the shipped network, compiled in, unless a model is given).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use crm_learn::{Example, Noise, TopologyNet};
use grasp_sim::Benchmark;
use grasp_sim::benchmark::{OBJECT_FEATURES, Object, Objective, Topology};

use crate::error::{Result, invalid};

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
pub fn probabilities(benchmark: &Benchmark, model: Option<&Path>) -> Result<Vec<Vec<f32>>> {
    let (net, inputs, outputs) = match model {
        Some(path) => TopologyNet::load(path)?,
        None => TopologyNet::from_bytes(SHIPPED, Path::new("models/topology.safetensors"))?,
    };
    if inputs != input_names() {
        return Err(invalid!("the topology network was trained on other inputs"));
    }
    let names: Vec<&str> = Topology::ALL.iter().map(|t| t.name()).collect();
    if outputs != names {
        return Err(invalid!(
            "the topology network has other outputs than the benchmark's topologies"
        ));
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
pub fn picks(benchmark: &Benchmark, model: Option<&Path>) -> Result<Vec<Topology>> {
    Ok(probabilities(benchmark, model)?
        .iter()
        .map(|p| best(p))
        .collect())
}

/// Every task's assigned topology, the network's pick and its probabilities, as JSON.
pub fn table(benchmark: &Benchmark, model: Option<&Path>) -> Result<serde_json::Value> {
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

/// Trains a network on `benchmark`'s (object, objective) pairs, `samples` noisy examples each
/// (a fifth held out), writes it to `out` and reports the accuracies.
pub fn train(
    benchmark: &Benchmark,
    out: &Path,
    seed: u64,
    samples: usize,
) -> Result<serde_json::Value> {
    if samples < 5 {
        return Err(invalid!("--samples must be at least 5, got {samples}"));
    }
    let pairs = labels(benchmark);
    let mut noise = Noise::new(seed);
    let (mut train, mut held_out) = (Vec::new(), Vec::new());
    for ((object, objective), topologies) in &pairs {
        let object = benchmark
            .object(object)
            .ok_or_else(|| invalid!("benchmark object {object:?}"))?;
        let label: Vec<f32> = Topology::ALL
            .iter()
            .map(|t| if topologies.contains(t) { 1.0 } else { 0.0 })
            .collect();
        for k in 0..samples {
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
    let mut net = TopologyNet::new(input_names().len(), 64, Topology::ALL.len(), seed)?;
    let loss = net.train(&train, 600, 1e-2)?;
    let report = serde_json::json!({
        "pairs": pairs.len(),
        "train_examples": train.len(),
        "held_out_examples": held_out.len(),
        "final_loss": loss,
        "train_accuracy": net.accuracy(&train)?,
        "held_out_accuracy": net.accuracy(&held_out)?,
        "model": out.display().to_string(),
    });
    let outputs: Vec<String> = Topology::ALL.iter().map(|t| t.name().to_string()).collect();
    net.save(out, &input_names(), &outputs)?;
    Ok(report)
}

/// The network in `model`'s topology probabilities for `object` under `objective`, beside the
/// topologies the benchmark assigns them.
pub fn predict(
    benchmark: &Benchmark,
    model: &Path,
    object: &str,
    objective: &str,
) -> Result<serde_json::Value> {
    let object = benchmark
        .object(object)
        .ok_or_else(|| invalid!("--object: unknown object {object:?} (see `crm tasks`)"))?;
    let objective = Objective::ALL
        .into_iter()
        .find(|o| o.name() == objective)
        .ok_or_else(|| invalid!("--objective: unknown objective {objective:?}"))?;
    let (net, inputs, outputs) = TopologyNet::load(model)?;
    if inputs != input_names() {
        return Err(invalid!(
            "model {} was trained on other inputs",
            model.display()
        ));
    }
    let probabilities = net.predict(&[input(object, objective, None)])?.remove(0);
    let best = probabilities
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(k, _)| outputs[k].clone())
        .unwrap_or_default();
    let assigned: Vec<&str> = labels(benchmark)
        .get(&(object.name.clone(), objective))
        .map(|set| set.iter().map(|t| t.name()).collect())
        .unwrap_or_default();
    Ok(serde_json::json!({
        "object": object.name,
        "objective": objective.name(),
        "topology": best,
        "probabilities": outputs.iter().cloned().zip(probabilities.iter().copied()).collect::<BTreeMap<_, _>>(),
        "benchmark_topologies": assigned,
    }))
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
