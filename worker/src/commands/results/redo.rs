//! `crm results --redo ALGO`: training an algorithm's runs of a study again after a fix to
//! it. Its runs leave the study's folder, and its training jobs on the coordinator are set
//! aside in `study.json` (`superseded`; the open ones cancelled), so the study submits them
//! anew. The flag is not recorded in the study's command: running that command again
//! continues the study and redoes nothing.

use std::collections::BTreeSet;
use std::path::Path;

use anyhow::{Context, bail};
use crm_api::Algorithm;
use serde_json::json;

use super::record::{self, StudyFile};
use super::study::study_jobs;
use crate::commands::remote::Rest;

/// The command line of `args` (after the program's name) as the study records it: shell
/// quoted, without `--redo`.
pub fn recorded_command(args: impl Iterator<Item = String>) -> String {
    let mut words = Vec::new();
    let mut value_of_redo = false;
    for arg in args {
        if std::mem::take(&mut value_of_redo) {
            continue;
        }
        if arg == "--redo" {
            value_of_redo = true;
        } else if !arg.starts_with("--redo=") {
            words.push(crm_server::launcher::shell_quote(&arg));
        }
    }
    words.join(" ")
}

/// Sets aside the runs of `algorithms` in the study `file` of folder `dir`: cancels their
/// open jobs on the coordinator, records every training job of theirs (the coordinator's and
/// those the runs on disk name) in `file.superseded` and removes their runs from `dir`.
pub fn set_aside(
    rest: &Rest,
    dir: &Path,
    file: &mut StudyFile,
    algorithms: &[Algorithm],
) -> anyhow::Result<()> {
    // Every name is checked before anything is cancelled or removed.
    if let Some(missing) = algorithms
        .iter()
        .map(|a| a.name())
        .find(|name| !file.algorithms.iter().any(|a| a == name))
    {
        bail!(
            "--redo {missing}: the study {} has no {missing} runs (its algorithms: {})",
            file.name,
            file.algorithms.join(", ")
        );
    }
    let jobs = study_jobs(rest, &file.name)?;
    for algorithm in algorithms {
        let name = algorithm.name();
        let mut ids: BTreeSet<i64> = file
            .superseded
            .get(name)
            .into_iter()
            .flatten()
            .copied()
            .collect();
        for job in jobs.iter().filter(|j| j["algorithm"] == name) {
            let id = job["id"].as_i64().context("a job without id")?;
            if matches!(job["state"].as_str(), Some("queued" | "running")) {
                rest.post_json(&format!("/api/v1/jobs/{id}/cancel"), &json!({}))?;
            }
            if job["kind"] == "train" {
                ids.insert(id);
            }
        }
        // The runs on disk name their training jobs, also those of another coordinator.
        for &seed in &file.seeds {
            let run = record::run_dir(dir, name, seed).join("run.json");
            if run.is_file() {
                let landed: record::RunFile = record::read_json(&run)?;
                ids.insert(landed.train_job);
            }
        }
        let runs = dir.join(name);
        if runs.exists() {
            std::fs::remove_dir_all(&runs)
                .with_context(|| format!("removing {}", runs.display()))?;
        }
        eprintln!(
            "--redo {name}: {} training jobs set aside, its runs removed from {}",
            ids.len(),
            runs.display()
        );
        file.superseded
            .insert(name.to_string(), ids.into_iter().collect());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recorded_command_leaves_out_redo() {
        let args = [
            "results",
            "--redo",
            "ppo",
            "--steps",
            "10",
            "--redo=lppo",
            "--note",
            "a b",
        ];
        assert_eq!(
            recorded_command(args.iter().map(|s| s.to_string())),
            "results --steps 10 --note 'a b'"
        );
    }
}
