//! A world folder written whole or not at all, for the commands that write one (`crm world
//! import-dexmobile`, `crm world init`): the files go to a hidden sibling of the folder
//! (`.NAME.TAG-PID`), are loaded as every command loads a world, and the sibling is moved into
//! place only then; on any error it is removed and nothing is left behind.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result, invalid_at};
use crate::world::World;

/// Refuses `out` when it exists and is not an empty folder (call it before the work).
pub(crate) fn refuse_occupied(out: &Path) -> Result<()> {
    let occupied = out.exists()
        && std::fs::read_dir(out)
            .map(|mut d| d.next().is_some())
            .unwrap_or(true);
    if occupied {
        return Err(invalid_at(
            out,
            "--out",
            "the folder exists and is not empty; remove it or name another",
        ));
    }
    Ok(())
}

/// Runs `fill` on a fresh staging folder beside `out` (it writes the files and loads the
/// world), then moves the folder to `out`. The world returned names `out` as its folder.
pub(crate) fn write_world(
    out: &Path,
    tag: &str,
    fill: impl FnOnce(&Path) -> Result<World>,
) -> Result<World> {
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let leaf = out.file_name().and_then(|n| n.to_str()).unwrap_or("world");
    let staging: PathBuf = parent.join(format!(".{leaf}.{tag}-{}", std::process::id()));
    let io = |path: &Path, error| Error::Io {
        path: path.display().to_string(),
        error,
    };
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir_all(&staging).map_err(|e| io(&staging, e))?;
    let world = match fill(&staging) {
        Ok(world) => world,
        Err(err) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(err);
        }
    };
    if out.exists() {
        std::fs::remove_dir(out).map_err(|e| io(out, e))?;
    }
    std::fs::rename(&staging, out).map_err(|e| io(out, e))?;
    Ok(World {
        dir: Some(out.to_path_buf()),
        ..world
    })
}

/// Writes `value` as pretty JSON with a final newline.
pub(crate) fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value).unwrap_or_default() + "\n";
    std::fs::write(path, text).map_err(|error| Error::Io {
        path: path.display().to_string(),
        error,
    })
}
