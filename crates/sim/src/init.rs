//! `crm world init`: a world folder drafted from a hand's description alone
//! ([`crate::hand::draft`]), loaded back as every command would load it before it is reported.

use std::path::{Path, PathBuf};

use crate::assets::Assets;
use crate::error::{Error, Result, invalid_at as invalid};
use crate::hand::description::Description;
use crate::hand::draft::draft;
use crate::world::World;

/// What `crm world init` wrote: the loaded world and the guesses to confirm.
#[derive(Debug)]
pub struct Drafted {
    pub world: World,
    pub notes: Vec<String>,
}

/// Drafts `world.json` and `hand.json` in `out` (absent or empty) for the description `hand`.
/// The profile names the description relative to the `CRM_ASSETS` folder it lies in, else by
/// its absolute path. Nothing is written when the draft does not load.
pub fn init_world(
    hand: &Path,
    out: &Path,
    name: Option<&str>,
    palm: Option<&str>,
    assets: &Assets,
) -> Result<Drafted> {
    if out.exists()
        && std::fs::read_dir(out)
            .map(|mut d| d.next().is_some())
            .unwrap_or(true)
    {
        return Err(invalid(
            out,
            "--out",
            "the world folder exists and is not empty",
        ));
    }
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
    let world = serde_json::json!({ "name": name, "hand": "hand.json" });
    let profile = serde_json::to_string_pretty(&drafted.profile).unwrap_or_default();
    // A hidden sibling no user folder is named like, moved into place once the draft loads.
    let leaf = out.file_name().and_then(|n| n.to_str()).unwrap_or("world");
    let staging: PathBuf = out.with_file_name(format!(".{leaf}.crm-init-{}", std::process::id()));
    let write = |path: PathBuf, text: String| {
        std::fs::write(&path, text + "\n").map_err(|error| Error::Io {
            path: path.display().to_string(),
            error,
        })
    };
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir_all(&staging).map_err(|error| Error::Io {
        path: staging.display().to_string(),
        error,
    })?;
    write(staging.join("world.json"), world.to_string())?;
    write(staging.join("hand.json"), profile)?;
    let loaded = World::load_with(&staging, assets);
    let loaded = match loaded {
        Ok(world) => world,
        Err(err) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(err);
        }
    };
    let _ = std::fs::remove_dir(out);
    std::fs::rename(&staging, out).map_err(|error| Error::Io {
        path: out.display().to_string(),
        error,
    })?;
    let world = World {
        dir: Some(out.to_path_buf()),
        ..loaded
    };
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
