//! Continuing a study: the same command again, or one that adds seeds or algorithms, extends
//! the study on disk; a command asking other settings is refused, naming the first that
//! differs. An algorithm family's settings bind only once the study holds one of its
//! algorithms: a study of the PPO learners can take CRM-SAC on later with its own SAC
//! settings.

use anyhow::{Context, bail};

use super::record::{StudyFile, settings_field};

/// The study `asked` continuing `before` (the same settings; its seeds and algorithms joined
/// to the earlier ones), or an error naming the first setting that differs.
pub fn extend(
    before: &StudyFile,
    asked: StudyFile,
    path: &std::path::Path,
) -> anyhow::Result<StudyFile> {
    let fields = |f: &StudyFile| -> anyhow::Result<serde_json::Map<String, serde_json::Value>> {
        let mut value = serde_json::to_value(f)?;
        let map = value.as_object_mut().context("a study is an object")?;
        for key in [
            "command",
            "seeds",
            "algorithms",
            "budget_note",
            "superseded",
        ] {
            map.remove(key);
        }
        for key in ["ppo", "sac"] {
            if !before.algorithms.iter().any(|a| settings_field(a) == key) {
                map.remove(key);
            }
        }
        Ok(map.clone())
    };
    let (old, new) = (fields(before)?, fields(&asked)?);
    if let Some((key, value)) = old.iter().find(|(k, v)| new.get(*k) != Some(*v)) {
        bail!(
            "{}: the study was run with {key} = {value}; this command asks {}: run it with the \
             study's settings to continue it, or give another --name",
            path.display(),
            new.get(key).cloned().unwrap_or_default()
        );
    }
    let mut seeds = before.seeds.clone();
    seeds.extend(asked.seeds.iter().filter(|s| !before.seeds.contains(s)));
    let mut algorithms = before.algorithms.clone();
    algorithms.extend(
        asked
            .algorithms
            .iter()
            .filter(|a| !before.algorithms.contains(a))
            .cloned(),
    );
    Ok(StudyFile {
        seeds,
        algorithms,
        budget_note: asked.budget_note.clone().or(before.budget_note.clone()),
        superseded: before.superseded.clone(),
        ..asked
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crm_api::{PpoConfig, SacConfig};

    fn study(algorithms: &[&str], sac_updates: f64, ppo_epochs: usize) -> StudyFile {
        StudyFile {
            name: "s".into(),
            command: "results".into(),
            world: "crm".into(),
            steps: 1000,
            envs: 2,
            tasks: vec![],
            episodes: 10,
            eval_seed: 7,
            seeds: vec![0],
            algorithms: algorithms.iter().map(|a| a.to_string()).collect(),
            ppo: PpoConfig {
                update_epochs: ppo_epochs,
                ..PpoConfig::default()
            },
            sac: SacConfig {
                updates_per_step: sac_updates,
                ..SacConfig::default()
            },
            task_objectives: Default::default(),
            settle_s: None,
            budget_note: None,
            superseded: Default::default(),
        }
    }

    #[test]
    fn a_family_not_yet_run_takes_the_settings_asked() {
        let path = std::path::Path::new("study.json");
        let before = study(&["crm-ppo", "lppo"], 1.0, 10);
        let asked = study(&["crm-ppo", "lppo", "crm-sac"], 0.125, 10);
        let joined = extend(&before, asked, path).unwrap();
        assert_eq!(joined.algorithms, ["crm-ppo", "lppo", "crm-sac"]);
        assert_eq!(joined.sac.updates_per_step, 0.125);
    }

    #[test]
    fn a_family_already_run_keeps_its_settings() {
        let path = std::path::Path::new("study.json");
        let before = study(&["crm-ppo", "crm-sac"], 1.0, 10);
        let err = extend(&before, study(&["crm-sac"], 0.125, 10), path).unwrap_err();
        assert!(
            err.to_string().contains("the study was run with sac = "),
            "{err}"
        );
        // PPO's settings bind the flat PPO a study of CRM-PPO adds.
        let before = study(&["crm-ppo"], 1.0, 10);
        let err = extend(&before, study(&["ppo"], 1.0, 4), path).unwrap_err();
        assert!(
            err.to_string().contains("the study was run with ppo = "),
            "{err}"
        );
        // Other settings bind whatever the algorithms.
        let mut asked = study(&["crm-ppo"], 1.0, 10);
        asked.steps = 2000;
        let err = extend(&before, asked, path).unwrap_err();
        assert!(err.to_string().contains("steps = 1000"), "{err}");
    }
}
