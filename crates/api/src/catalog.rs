//! The benchmark's catalog, read from `worlds/crm/benchmark.json` at build time: task
//! ids with their object, objective and assigned topology, and the objects' names. Lets the
//! coordinator validate jobs and show tasks without linking the simulator.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

const BENCHMARK: &str = include_str!("../../../worlds/crm/benchmark.json");

/// One task as the catalog knows it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskEntry {
    pub id: String,
    pub object: String,
    pub objective: String,
    pub topology: String,
}

#[derive(Deserialize)]
struct File {
    objects: Vec<ObjectName>,
    tasks: Vec<TaskEntry>,
}

#[derive(Deserialize)]
struct ObjectName {
    name: String,
}

/// Tasks, objects, objectives and topologies of the built-in benchmark.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Catalog {
    pub tasks: Vec<TaskEntry>,
    pub objects: Vec<String>,
    pub objectives: Vec<String>,
    pub topologies: Vec<String>,
}

/// How the benchmark file failed to parse.
#[derive(Debug, thiserror::Error)]
#[error("benchmark catalog: {0}")]
pub struct CatalogError(#[from] serde_json::Error);

impl Catalog {
    /// Reads the built-in benchmark.
    pub fn builtin() -> Result<Self, CatalogError> {
        Self::parse(BENCHMARK)
    }

    /// Reads a benchmark file's text.
    pub fn parse(text: &str) -> Result<Self, CatalogError> {
        let file: File = serde_json::from_str(text)?;
        let objectives: BTreeSet<String> = file.tasks.iter().map(|t| t.objective.clone()).collect();
        let topologies: BTreeSet<String> = file.tasks.iter().map(|t| t.topology.clone()).collect();
        Ok(Self {
            objects: file.objects.into_iter().map(|o| o.name).collect(),
            objectives: objectives.into_iter().collect(),
            topologies: topologies.into_iter().collect(),
            tasks: file.tasks,
        })
    }

    pub fn task(&self, id: &str) -> Option<&TaskEntry> {
        self.tasks.iter().find(|t| t.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_catalog_has_the_papers_counts() {
        let catalog = Catalog::builtin().expect("catalog");
        assert_eq!(catalog.tasks.len(), 26);
        assert_eq!(catalog.objects.len(), 20);
        assert_eq!(catalog.objectives.len(), 7);
        assert_eq!(catalog.topologies.len(), 6);
        assert!(catalog.task("mug-wrap").is_some());
        assert!(catalog.task("nope").is_none());
    }
}
