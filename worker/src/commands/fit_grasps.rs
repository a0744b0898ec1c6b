//! `crm world fit-grasps WORLD --out DIR`: fit a world's grasp locations to its hand
//! ([`crm_run::fit`]) and write the corrected world as a world of its own: the source
//! folder's files, its `world.json` naming `corrections.json` (the offsets, the box, the
//! seeds, the oracle's success before and after, this command) and the source folder among
//! its `assets` (relative to the new folder), so descriptions and meshes resolve as before.
//! The source stays as it is.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use crm_run::fit::FitOptions;
use grasp_sim::corrections::Corrections;
use grasp_sim::{EnvSettings, World};

use super::emit;

#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// The world folder to fit (with `world.json`).
    pub world: PathBuf,
    /// The corrected world's folder; it must not exist, or be empty.
    #[arg(long)]
    pub out: PathBuf,
    /// The corrected world's name (default: the source's with `-fitted`).
    #[arg(long)]
    pub name: Option<String>,
    /// Search the tasks whose oracle success on the search seeds is under this.
    #[arg(long, default_value_t = FitOptions::default().threshold)]
    pub threshold: f64,
    /// Half-width of the box of offsets searched, per axis (m, object frame).
    #[arg(long, default_value_t = FitOptions::default().bounds[0])]
    pub bounds: f32,
    /// The search's first step and its finest (m).
    #[arg(long, default_value_t = FitOptions::default().step)]
    pub step: f32,
    #[arg(long, default_value_t = FitOptions::default().min_step)]
    pub min_step: f32,
    /// Seeds judging each candidate: the first and how many.
    #[arg(long, default_value_t = FitOptions::default().search_seeds[0])]
    pub seed: u64,
    #[arg(long, default_value_t = FitOptions::default().search_seeds[1])]
    pub seeds: u64,
    /// Seeds rechecking the best offset, which the search does not use: the first and how
    /// many.
    #[arg(long, default_value_t = FitOptions::default().check_seeds[0])]
    pub check_seed: u64,
    #[arg(long, default_value_t = FitOptions::default().check_seeds[1])]
    pub check_seeds: u64,
    /// Only this task (repeat for more); every task when absent.
    #[arg(long = "task")]
    pub tasks: Vec<String>,
}

/// The files of the source folder (not its subfolders), and its `world.json` rewritten.
fn write_world(
    source: &Path,
    out: &Path,
    name: &str,
    corrections: &Corrections,
) -> anyhow::Result<()> {
    if out.exists()
        && std::fs::read_dir(out)
            .with_context(|| format!("--out: {}", out.display()))?
            .next()
            .is_some()
    {
        bail!("--out: {} is not empty", out.display());
    }
    let text = std::fs::read_to_string(source.join("world.json"))
        .with_context(|| format!("reading {}", source.join("world.json").display()))?;
    let mut world: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}", source.join("world.json").display()))?;
    let absolute =
        std::fs::canonicalize(source).with_context(|| format!("{}", source.display()))?;
    std::fs::create_dir_all(out).with_context(|| format!("--out: {}", out.display()))?;
    let out_absolute =
        std::fs::canonicalize(out).with_context(|| format!("--out: {}", out.display()))?;
    // Earlier asset folders, then the source folder itself, each relative to the new folder
    // (so the two can move together), as `world.json` allows.
    let mut assets: Vec<serde_json::Value> = world["assets"]
        .as_array()
        .cloned()
        .unwrap_or_default()
        .into_iter()
        .filter_map(|a| {
            a.as_str()
                .map(|a| relative(&absolute.join(a), &out_absolute).into())
        })
        .collect();
    assets.push(relative(&absolute, &out_absolute).into());
    world["assets"] = serde_json::Value::Array(assets);
    world["name"] = name.into();
    world["corrections"] = "corrections.json".into();
    for entry in std::fs::read_dir(source)? {
        let entry = entry?;
        if entry.file_type()?.is_file() && entry.file_name() != "world.json" {
            std::fs::copy(entry.path(), out.join(entry.file_name()))?;
        }
    }
    std::fs::write(
        out.join("corrections.json"),
        serde_json::to_string_pretty(corrections)? + "\n",
    )?;
    std::fs::write(
        out.join("world.json"),
        serde_json::to_string_pretty(&world)? + "\n",
    )?;
    Ok(())
}

/// `path` from folder `from` (both absolute): `../../worlds/x`.
fn relative(path: &Path, from: &Path) -> String {
    let path: Vec<_> = path.components().collect();
    let from: Vec<_> = from.components().collect();
    let common = path.iter().zip(&from).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..from.len() {
        out.push("..");
    }
    for part in &path[common..] {
        out.push(part);
    }
    if out.as_os_str().is_empty() {
        ".".into()
    } else {
        out.display().to_string()
    }
}

pub fn run(args: FitArgs) -> anyhow::Result<()> {
    let world = World::load(&args.world)?;
    if world.corrections.is_some() {
        bail!(
            "{}: the world already corrects its grasp locations; fit the world it was made from",
            args.world.display()
        );
    }
    for (flag, v) in [
        ("--bounds", args.bounds),
        ("--step", args.step),
        ("--min-step", args.min_step),
    ] {
        if !(v.is_finite() && v > 0.0 && v <= 0.1) {
            bail!("{flag}: {v} is not a length in (0, 0.1] m");
        }
    }
    if args.seeds == 0 || args.check_seeds == 0 {
        bail!("--seeds and --check-seeds: at least 1");
    }
    let options = FitOptions {
        threshold: args.threshold,
        bounds: [args.bounds; 3],
        step: args.step,
        min_step: args.min_step.min(args.step),
        search_seeds: [args.seed, args.seeds],
        check_seeds: [args.check_seed, args.check_seeds],
        tasks: args.tasks.clone(),
    };
    let config = world.sim_config(&EnvSettings::default());
    let machine = world.machine()?;
    let fits = crm_run::fit::fit(&world.benchmark, &config, &machine, &options, |line| {
        eprintln!("{line}")
    })?;
    let command = std::iter::once("crm".to_string())
        .chain(std::env::args().skip(1))
        .map(|a| crm_server::launcher::shell_quote(&a))
        .collect::<Vec<_>>()
        .join(" ");
    let corrections = Corrections {
        command,
        bounds: options.bounds,
        threshold: options.threshold,
        search_seeds: options.search_seeds,
        check_seeds: options.check_seeds,
        tasks: fits
            .iter()
            .filter(|(_, f)| f.after > f.before)
            .cloned()
            .collect(),
    };
    let name = args
        .name
        .clone()
        .unwrap_or_else(|| format!("{}-fitted", world.name));
    write_world(&args.world, &args.out, &name, &corrections)?;
    let fitted = World::load(&args.out)
        .with_context(|| format!("the corrected world {} does not load", args.out.display()))?;
    let mut text = String::from(
        "| task | offset (m, object frame) | search seeds, before | after | check seeds, before | after |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for (task, f) in &fits {
        let kept = if f.after > f.before {
            ""
        } else {
            " (not improved: not written)"
        };
        text.push_str(&format!(
            "| {} | {:?}{kept} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
            task, f.offset, f.before, f.after, f.before_check, f.after_check
        ));
    }
    eprint!("{text}");
    emit(&format!("{}\n", fitted.summary()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_is_named_from_another_by_the_shortest_relative_path() {
        let at = |p: &str| PathBuf::from(p);
        assert_eq!(relative(&at("/a/worlds/x"), &at("/a/worlds/y")), "../x");
        assert_eq!(relative(&at("/a/b"), &at("/a/b")), ".");
        assert_eq!(
            relative(&at("/root/dex"), &at("/tmp/w/fit")),
            "../../../root/dex"
        );
        assert_eq!(relative(&at("/a/b/c"), &at("/a")), "b/c");
    }
}
