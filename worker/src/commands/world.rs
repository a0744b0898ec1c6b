//! `crm world check DIR`: load a world folder as every command would and print what it holds.
//! `crm world import-dexmobile PATH --out DIR`: write the paper's own world from a copy of the
//! authors' repository (`grasp_sim::import::dexmobile`), pointing at its files.
//! `crm world init --hand FILE --out DIR`: draft a world for a hand from its description alone
//! (`grasp_sim::init`) and print the guesses to confirm.
//! `crm world fit-grasps WORLD --out DIR`: the world with its grasp locations fitted to its hand
//! (`fit_grasps.rs`).

use std::path::PathBuf;

use anyhow::bail;

use super::emit;

#[derive(clap::Subcommand, Debug)]
pub enum WorldCommand {
    /// Load a world folder (hand description and profile, objects and meshes, tasks, spec,
    /// sensors) and print one JSON line; exits 2 naming the file and field that is wrong.
    Check(CheckArgs),
    /// Write a world folder from a copy of github.com/hhelium/DexMobile (the right SVH hand,
    /// the AffordPose objects, the 27 tasks of crm_ppo/topo/pos_all.csv). Nothing is copied:
    /// the world names PATH in its `assets`. Exits 2 naming the file (and the CSV's line and
    /// column) that is wrong, with nothing written.
    ImportDexmobile(ImportArgs),
    /// Draft a world folder for a hand from its URDF or MJCF description alone: the palm, the
    /// finger chains and their command joints, couplings, ranges, axes and a grasp point,
    /// loaded back as `crm world check` loads it. Prints the world's line, then each guess
    /// to confirm. Nothing is written when the draft does not load.
    Init(InitArgs),
    /// Fit the grasp locations of the tasks the scripted oracle fails to the hand: search an
    /// offset per task within a box, judged by the oracle, rechecked on other seeds, and write
    /// the corrected world (its `corrections.json`, a hash of its own) to `--out`. Prints the
    /// table to stderr and the corrected world's line.
    FitGrasps(super::fit_grasps::FitArgs),
}

#[derive(clap::Args, Debug)]
pub struct InitArgs {
    /// The hand's description (`.urdf`, or an MJCF `.xml` scene); its meshes and includes are
    /// found beside it or through `CRM_ASSETS`.
    #[arg(long)]
    pub hand: PathBuf,
    /// The world folder to write; it must not exist, or be empty.
    #[arg(long)]
    pub out: PathBuf,
    /// The world's name (default: the description's file name).
    #[arg(long)]
    pub name: Option<String>,
    /// The palm link, where the rules would pick another (the first link where three or more
    /// moving chains branch).
    #[arg(long)]
    pub palm: Option<String>,
}

#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The world folder (with `world.json`).
    pub dir: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// The authors' repository (a clone or an unpacked archive).
    pub path: PathBuf,
    /// The world folder to write; it must not exist, or be empty.
    #[arg(long)]
    pub out: PathBuf,
    /// The world's name.
    #[arg(long, default_value = "dexmobile")]
    pub name: String,
    /// Sensors the robot lacks (features or the paper's groups, e.g. `o_force`); repeat or
    /// separate with commas. The paper's real SVH: `--without o_force,o_torque,o_cone`.
    #[arg(long, value_delimiter = ',')]
    pub without: Vec<String>,
    /// The approach geometry: `authors` (their arm's slowed, clamped steps: the paper's
    /// setting, docs/WORLDS.md) or `free` (the default). A world of its own hash.
    #[arg(long, value_parser = ["free", "authors"])]
    pub approach: Option<String>,
    /// Grasp-location corrections to apply (a `corrections.json` of `crm world fit-grasps`,
    /// e.g. the project's `worlds/dexmobile-corrections.json`): the import is then a world of
    /// its own hash, its task files still the authors'.
    #[arg(long, value_name = "FILE")]
    pub corrections: Option<PathBuf>,
}

/// The profile file a world folder names (`world.json`'s `hand`), for messages.
fn world_hand_file(dir: &std::path::Path) -> String {
    std::fs::read_to_string(dir.join("world.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["hand"].as_str().map(String::from))
        .unwrap_or_else(|| "hand.json".into())
}

pub fn run(command: WorldCommand) -> anyhow::Result<()> {
    match command {
        WorldCommand::FitGrasps(args) => super::fit_grasps::run(args),
        WorldCommand::Check(args) => {
            let world = grasp_sim::World::load(&args.dir)?;
            let (conflicts, needless) = world.coupling_conflicts();
            let profile = args.dir.join(world_hand_file(&args.dir));
            if !conflicts.is_empty() {
                bail!(
                    "{}: the profile contradicts the hand's description:\n  {}\nfollow the \
                     description, or name each joint in `description_overrides` to keep the \
                     profile's coupling on purpose",
                    profile.display(),
                    conflicts.join("\n  ")
                );
            }
            if !needless.is_empty() {
                bail!(
                    "{}: description_overrides names {} without a conflicting coupling: take \
                     them out",
                    profile.display(),
                    needless.join(", ")
                );
            }
            emit(&format!("{}\n", world.summary()))
        }
        WorldCommand::ImportDexmobile(args) => {
            let corrections = match &args.corrections {
                Some(path) => {
                    let text = std::fs::read_to_string(path)
                        .map_err(|e| anyhow::anyhow!("--corrections: {}: {e}", path.display()))?;
                    serde_json::from_str::<grasp_sim::corrections::Corrections>(&text)
                        .map_err(|e| anyhow::anyhow!("--corrections: {}: {e}", path.display()))?;
                    Some(text)
                }
                None => None,
            };
            let options = grasp_sim::import::dexmobile::Options {
                name: args.name,
                without: args.without,
                corrections,
                approach: match args.approach.as_deref() {
                    Some("authors") => Some(grasp_sim::Approach::Authors),
                    Some(_) => Some(grasp_sim::Approach::Free),
                    None => None,
                },
            };
            let imported = grasp_sim::import::dexmobile::import(&args.path, &args.out, &options)?;
            let line = serde_json::json!({
                "world": imported.dir,
                "objects": imported.objects,
                "tasks": imported.tasks,
                "hash": imported.hash,
            });
            emit(&format!("{line}\n"))
        }
        WorldCommand::Init(args) => {
            let assets = grasp_sim::assets::Assets::from_env();
            let drafted = grasp_sim::init::init_world(
                &args.hand,
                &args.out,
                args.name.as_deref(),
                args.palm.as_deref(),
                &assets,
            )?;
            let mut text = format!(
                "{}\nconfirm in {}:\n",
                drafted.world.summary(),
                args.out.join("hand.json").display()
            );
            for note in &drafted.notes {
                text.push_str(&format!("- {note}\n"));
            }
            emit(&text)
        }
    }
}
