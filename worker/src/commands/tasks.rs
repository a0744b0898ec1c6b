//! `crm tasks` and `crm spec`: the benchmark and the machine as data.

use grasp_sim::benchmark::{OBJECT_FEATURES, Objective, Topology};

use std::fmt::Write;

use super::{EnvArgs, emit};

#[derive(clap::Args, Debug)]
pub struct TasksArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct SpecArgs {
    #[command(flatten)]
    pub env: EnvArgs,
}

pub fn run(args: TasksArgs) -> anyhow::Result<()> {
    let benchmark = args.env.env().benchmark()?;
    if args.json {
        let objects: Vec<_> = benchmark
            .objects
            .iter()
            .map(|o| {
                serde_json::json!({
                    "name": o.name,
                    "mass": o.mass,
                    "friction": o.friction,
                    "fragility": o.fragility.name(),
                    "grasp_force_limit": o.fragility.grasp_force_limit(),
                    "dimensions": o.dimensions(),
                    "anchored": o.anchor.is_some(),
                    "features": OBJECT_FEATURES.iter().zip(o.features()).map(|(n, v)| (n.to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
                })
            })
            .collect();
        let out = serde_json::json!({
            "objectives": Objective::ALL.iter().map(|o| o.name()).collect::<Vec<_>>(),
            "topologies": Topology::ALL.iter().map(|t| t.name()).collect::<Vec<_>>(),
            "objects": objects,
            "tasks": benchmark.tasks,
        });
        return emit(&format!("{}\n", serde_json::to_string_pretty(&out)?));
    }
    let mut text = String::new();
    writeln!(
        text,
        "{} objects, {} objectives, {} topologies, {} tasks",
        benchmark.objects.len(),
        Objective::ALL.len(),
        Topology::ALL.len(),
        benchmark.tasks.len()
    )?;
    writeln!(text)?;
    writeln!(
        text,
        "{:<14} {:>7} {:>6} {:<8} {:>22}",
        "object", "mass kg", "mu", "fragile", "size x*y*z cm"
    )?;
    for object in &benchmark.objects {
        let d = object.dimensions();
        writeln!(
            text,
            "{:<14} {:>7.2} {:>6.2} {:<8} {:>22}",
            object.name,
            object.mass,
            object.friction,
            object.fragility.name(),
            format!(
                "{:.1}*{:.1}*{:.1}",
                d[0] * 100.0,
                d[1] * 100.0,
                d[2] * 100.0
            )
        )?;
    }
    writeln!(text)?;
    writeln!(
        text,
        "{:<16} {:<12} {:<13} {:<9} {:>24}",
        "task", "object", "objective", "topology", "grasp offset cm"
    )?;
    for task in &benchmark.tasks {
        let o = task.grasp.offset;
        writeln!(
            text,
            "{:<16} {:<12} {:<13} {:<9} {:>24}",
            task.id,
            task.object,
            task.objective.name(),
            task.topology.name(),
            format!(
                "({:.1}, {:.1}, {:.1})",
                o[0] * 100.0,
                o[1] * 100.0,
                o[2] * 100.0
            )
        )?;
    }
    emit(&text)
}

pub fn run_spec(args: SpecArgs) -> anyhow::Result<()> {
    let machine = args.env.env().machine()?;
    emit(&format!(
        "{}\n",
        serde_json::to_string_pretty(machine.spec())?
    ))
}
