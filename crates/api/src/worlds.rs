//! The worlds a coordinator offers and a worker runs: the built-in one (`crm`) and every
//! folder with a `world.json` directly under a worlds folder (`--worlds DIR`). Read without
//! the simulator: a world's name and its tasks' catalog are enough to validate jobs; workers
//! load the world itself (`grasp_sim::World`) from the folder found here.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::Catalog;

/// The built-in world's name.
pub const BUILTIN: &str = "crm";

/// One world: its name, its folder (none for the built-in one) and its tasks.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldEntry {
    pub name: String,
    pub dir: Option<PathBuf>,
    pub catalog: Catalog,
}

/// What `GET /api/v1/worlds` says of a world.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WorldSummary {
    pub name: String,
    pub builtin: bool,
    pub tasks: usize,
    pub objects: usize,
    pub objectives: Vec<String>,
    pub topologies: Vec<String>,
}

impl WorldEntry {
    pub fn builtin() -> Result<Self, WorldsError> {
        Ok(Self {
            name: BUILTIN.to_string(),
            dir: None,
            catalog: Catalog::builtin().map_err(|e| WorldsError {
                path: "worlds/crm/benchmark.json".into(),
                message: e.to_string(),
            })?,
        })
    }

    pub fn summary(&self) -> WorldSummary {
        WorldSummary {
            name: self.name.clone(),
            builtin: self.dir.is_none(),
            tasks: self.catalog.tasks.len(),
            objects: self.catalog.objects.len(),
            objectives: self.catalog.objectives.clone(),
            topologies: self.catalog.topologies.clone(),
        }
    }
}

/// A world folder that cannot be listed, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct WorldsError {
    pub path: String,
    pub message: String,
}

#[derive(Deserialize)]
struct WorldFile {
    name: String,
    #[serde(default)]
    benchmark: Option<String>,
}

/// `name` relative to `dir`, else in the first `CRM_ASSETS` folder that has it.
fn find(name: &str, dir: &Path) -> Option<PathBuf> {
    let assets = std::env::var("CRM_ASSETS").unwrap_or_default();
    std::iter::once(dir.to_path_buf())
        .chain(
            assets
                .split(':')
                .filter(|s| !s.is_empty())
                .map(PathBuf::from),
        )
        .map(|folder| folder.join(name))
        .find(|p| p.is_file())
}

/// Reads one world folder's name and catalog.
pub fn read(dir: &Path) -> Result<WorldEntry, WorldsError> {
    let path = dir.join("world.json");
    let error = |path: &Path, message: String| WorldsError {
        path: path.display().to_string(),
        message,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| error(&path, e.to_string()))?;
    let file: WorldFile = serde_json::from_str(&text).map_err(|e| error(&path, e.to_string()))?;
    if file.name == BUILTIN {
        return Err(error(
            &path,
            format!("name: {BUILTIN:?} is the built-in world's; choose another"),
        ));
    }
    let catalog = match &file.benchmark {
        Some(name) => {
            let benchmark = find(name, dir)
                .ok_or_else(|| error(&path, format!("benchmark: {name:?} not found")))?;
            let text = std::fs::read_to_string(&benchmark)
                .map_err(|e| error(&benchmark, e.to_string()))?;
            Catalog::parse(&text).map_err(|e| error(&benchmark, e.to_string()))?
        }
        None => Catalog::builtin().map_err(|e| error(&path, e.to_string()))?,
    };
    Ok(WorldEntry {
        name: file.name,
        dir: Some(dir.to_path_buf()),
        catalog,
    })
}

/// The built-in world, then every folder under `worlds` with a `world.json`, by folder
/// name. Two worlds of one name are an error.
pub fn discover(worlds: Option<&Path>) -> Result<Vec<WorldEntry>, WorldsError> {
    let mut found = vec![WorldEntry::builtin()?];
    let Some(root) = worlds else {
        return Ok(found);
    };
    let entries = std::fs::read_dir(root).map_err(|e| WorldsError {
        path: root.display().to_string(),
        message: e.to_string(),
    })?;
    let mut dirs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("world.json").is_file())
        .collect();
    dirs.sort();
    for dir in dirs {
        let world = read(&dir)?;
        if found.iter().any(|w| w.name == world.name) {
            return Err(WorldsError {
                path: dir.join("world.json").display().to_string(),
                message: format!("a second world named {:?}", world.name),
            });
        }
        found.push(world);
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worlds_are_found_by_folder_and_bad_ones_named() {
        let root = std::env::temp_dir().join(format!("crm-api-worlds-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(root.join("mine")).expect("dir");
        std::fs::create_dir_all(root.join("not-a-world")).expect("dir");
        std::fs::write(
            root.join("mine/world.json"),
            r#"{"name": "mine", "hand": "hand.json"}"#,
        )
        .expect("write");
        let worlds = discover(Some(&root)).expect("worlds");
        let names: Vec<&str> = worlds.iter().map(|w| w.name.as_str()).collect();
        assert_eq!(names, ["crm", "mine"]);
        assert_eq!(
            worlds[1].catalog.tasks.len(),
            26,
            "the built-in tasks by default"
        );
        assert!(worlds[0].summary().builtin && !worlds[1].summary().builtin);

        std::fs::write(
            root.join("mine/world.json"),
            r#"{"name": "mine", "hand": "hand.json", "benchmark": "none.json"}"#,
        )
        .expect("write");
        let err = discover(Some(&root))
            .expect_err("a missing benchmark")
            .to_string();
        assert!(
            err.contains("mine/world.json") && err.contains("none.json"),
            "{err}"
        );
        std::fs::remove_dir_all(root).ok();
    }
}
