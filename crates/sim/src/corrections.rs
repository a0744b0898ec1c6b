//! A world's corrections to its tasks' grasp locations (`world.json` `"corrections":
//! "corrections.json"`): per task, an offset (m, object frame) added to the grasp location the
//! task file gives, found by a search anyone can rerun (`crm world fit-grasps`), with the box it
//! searched, the seeds it judged on and rechecked on, the oracle's success before and after,
//! and the command. Data, not code: the task files stay as their source wrote them, and the
//! world's hash covers the corrections, so a corrected world is a world of its own.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::benchmark::Benchmark;
use crate::error::{Error, Result};

/// `corrections.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Corrections {
    /// The command that found them.
    pub command: String,
    /// Half-widths of the box of offsets searched (m, object frame).
    pub bounds: [f32; 3],
    /// A task whose oracle success on the search seeds was under this was searched.
    pub threshold: f64,
    /// The seeds every candidate was judged on: `[first, count]`.
    pub search_seeds: [u64; 2],
    /// The seeds the best offset was rechecked on, which the search did not use.
    pub check_seeds: [u64; 2],
    /// The tasks corrected, by id.
    pub tasks: BTreeMap<String, TaskCorrection>,
}

/// One task's correction and the oracle's success around it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskCorrection {
    /// Added to the task's grasp location (m, object frame).
    pub offset: [f32; 3],
    /// Oracle success on the search seeds, without and with the offset.
    pub before: f64,
    pub after: f64,
    /// The same on the check seeds.
    pub before_check: f64,
    pub after_check: f64,
    /// Offsets the search judged.
    pub evaluated: usize,
}

impl Corrections {
    /// Adds each task's offset to its grasp location in `benchmark`; `path` names errors.
    pub fn apply(&self, benchmark: &mut Benchmark, path: &Path) -> Result<()> {
        let invalid = |at: String, message: String| Error::Invalid {
            path: path.display().to_string(),
            at,
            message,
        };
        for (id, correction) in &self.tasks {
            let at = format!("tasks.{id}.offset");
            let task = benchmark
                .tasks
                .iter_mut()
                .find(|t| &t.id == id)
                .ok_or_else(|| {
                    invalid(format!("tasks.{id}"), "the world has no such task".into())
                })?;
            for (k, v) in correction.offset.iter().enumerate() {
                if !v.is_finite() || v.abs() > self.bounds[k].abs() + 1e-6 {
                    return Err(invalid(
                        at,
                        format!("{v} is not a finite offset within the searched bounds"),
                    ));
                }
            }
            for (g, v) in task.grasp.offset.iter_mut().zip(correction.offset) {
                *g += v;
            }
        }
        Ok(())
    }

    /// Each corrected task's offset (to the micrometre), for a world's summary.
    pub fn offsets(&self) -> BTreeMap<&str, [f64; 3]> {
        self.tasks
            .iter()
            .map(|(id, c)| {
                let offset = c.offset.map(|v| (f64::from(v) * 1e6).round() / 1e6);
                (id.as_str(), offset)
            })
            .collect()
    }
}
