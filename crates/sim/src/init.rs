//! `crm world init`: a world folder drafted from a hand's description alone
//! ([`crate::hand::draft`]), loaded back as every command would load it before it is reported.

use std::path::Path;

use crate::assets::Assets;
use crate::error::{Error, Result, invalid_at as invalid};
use crate::hand::description::Description;
use crate::hand::draft::draft;
use crate::staging::{refuse_occupied, write_json, write_world};
use crate::world::World;

/// What `crm world init` wrote: the loaded world and the guesses to confirm.
#[derive(Debug)]
pub struct Drafted {
    pub world: World,
    pub notes: Vec<String>,
}

/// Drafts `world.json` and `hand.json` in `out` (absent or empty) for the description `hand`,
/// whole or not at all ([`crate::staging`]). The profile names the description relative to
/// the `CRM_ASSETS` folder it lies in, else by its absolute path.
pub fn init_world(
    hand: &Path,
    out: &Path,
    name: Option<&str>,
    palm: Option<&str>,
    assets: &Assets,
) -> Result<Drafted> {
    refuse_occupied(out)?;
    let description = Description::load(hand, assets)?;
    let absolute = std::path::absolute(hand).map_err(|error| Error::Io {
        path: hand.display().to_string(),
        error,
    })?;
    let file = assets
        .folders
        .iter()
        .filter_map(|folder| std::path::absolute(folder).ok())
        .find_map(|folder| absolute.strip_prefix(&folder).ok().map(Path::to_path_buf))
        .unwrap_or_else(|| absolute.clone());
    let drafted = draft(&description, &file.display().to_string(), palm)
        .map_err(|message| invalid(hand, "description", message))?;
    let name = match name {
        Some(name) => name.to_string(),
        None => stem_name(hand),
    };
    let world = write_world(out, "crm-init", |staging| {
        write_json(
            &staging.join("world.json"),
            &serde_json::json!({ "name": name, "hand": "hand.json" }),
        )?;
        write_json(&staging.join("hand.json"), &drafted.profile)?;
        World::load_with(staging, assets)
    })?;
    Ok(Drafted {
        world,
        notes: drafted.notes,
    })
}

/// A world name from a file name: letters, digits, `-`, `_` and `.` kept, others as `-`.
fn stem_name(path: &Path) -> String {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("hand");
    stem.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '-'
            }
        })
        .collect()
}
