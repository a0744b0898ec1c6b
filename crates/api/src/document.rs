//! The experiment document: a job in three parts, what it runs in (`env`, shared by training
//! and evaluation), what learns (`algorithm`, with its own settings) and how the run goes
//! (`run`). `POST /api/v1/jobs` and `crm train --job FILE` take it beside the flat form
//! ([`TrainSpec`], [`EvalSpec`]) that earlier clients send and that the coordinator stores; a
//! body with an `env` or `run` member is a document ([`is_document`]). Each document converts
//! to its flat spec and back without loss, and [`document_path`] names a flat spec's field
//! where the document holds it, so that every refusal names what the client wrote.

use serde::{Deserialize, Serialize};

use crate::config::{PpoConfig, SacConfig};
use crate::fields::field_names;
use crate::imitation::ImitationSpec;
use crate::jobs::{EvalSpec, ObjectiveMode, TrainSpec, default_episodes, is_default_sac};
use crate::{Algorithm, RecordSpec};

/// Where a job runs: the world, its tasks and topology, who executes the objective, and the
/// judge's hold. The fields mean what [`TrainSpec`]'s of the same names do.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task: Option<String>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tasks: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology: Option<String>,
    #[serde(default)]
    pub objective: ObjectiveMode,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_s: Option<f64>,
}

/// What learns: the learner and its settings (`config` for the PPO learners, `sac` for
/// crm-sac; defaults cite the paper and the anchors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlgorithmSpec {
    pub name: Algorithm,
    #[serde(default)]
    pub config: PpoConfig,
    #[serde(default, skip_serializing_if = "is_default_sac")]
    pub sac: SacConfig,
}

/// How a training run goes: its length and seed, parallel environments, where it starts from
/// (`fine_tune`, `imitation`), task drawing, training's hold shortcut and recording.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    pub steps: u64,
    #[serde(default)]
    pub seed: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub envs: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fine_tune: Option<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imitation: Option<ImitationSpec>,
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub curriculum: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<RecordSpec>,
}

/// A training job as one document.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainDocument {
    #[serde(default)]
    pub env: EnvSpec,
    pub algorithm: AlgorithmSpec,
    pub run: RunSpec,
}

/// How an evaluation goes: episodes, seed, the action taken, recording, video.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvalRunSpec {
    #[serde(default = "default_episodes")]
    pub episodes: u64,
    #[serde(default)]
    pub seed: u64,
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub deterministic: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<RecordSpec>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<crate::VideoSpec>,
}

impl Default for EvalRunSpec {
    fn default() -> Self {
        Self {
            episodes: default_episodes(),
            seed: 0,
            deterministic: false,
            record: None,
            video: None,
        }
    }
}

/// An evaluation job as one document (the checkpoint is given beside it). `run` is required,
/// `{}` for every default, so that a document and the flat form never read alike.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvalDocument {
    #[serde(default)]
    pub env: EnvSpec,
    pub run: EvalRunSpec,
}

/// Whether a job's body (its members) is a document rather than the flat form: it has an
/// `env` or a `run` member.
pub fn is_document(fields: &serde_json::Map<String, serde_json::Value>) -> bool {
    fields.contains_key("env") || fields.contains_key("run")
}

/// Where a document holds the flat spec's field `path` (`config.minibatch_size` ->
/// `algorithm.config.minibatch_size`, `steps` -> `run.steps`, `task` -> `env.task`).
pub fn document_path(path: &str) -> String {
    let (head, rest) = path.split_once('.').map_or((path, ""), |(h, r)| (h, r));
    // `tasks[2]` is the field `tasks`.
    let name = head.split('[').next().unwrap_or(head);
    let part = if name == "algorithm" {
        // The flat spec's learner; a document's own `algorithm.…` paths stay.
        return if rest.is_empty() {
            "algorithm.name".to_string()
        } else {
            path.to_string()
        };
    } else if field_names::<AlgorithmSpec>().contains(&name) {
        "algorithm"
    } else if field_names::<EnvSpec>().contains(&name) {
        "env"
    } else if field_names::<RunSpec>().contains(&name)
        || field_names::<EvalRunSpec>().contains(&name)
    {
        "run"
    } else {
        return path.to_string();
    };
    match rest {
        "" => format!("{part}.{head}"),
        rest => format!("{part}.{head}.{rest}"),
    }
}

impl From<TrainDocument> for TrainSpec {
    fn from(doc: TrainDocument) -> Self {
        let TrainDocument {
            env,
            algorithm,
            run,
        } = doc;
        TrainSpec {
            algorithm: algorithm.name,
            world: env.world,
            steps: run.steps,
            seed: run.seed,
            task: env.task,
            tasks: env.tasks,
            topology: env.topology,
            envs: run.envs,
            config: algorithm.config,
            sac: algorithm.sac,
            record: run.record,
            imitation: run.imitation,
            fine_tune: run.fine_tune,
            start_log_std: None,
            objective: env.objective,
            curriculum: run.curriculum,
            hold_s: env.hold_s,
            settle_s: run.settle_s,
        }
    }
}

impl From<TrainSpec> for TrainDocument {
    /// The document of a flat spec; its `start_log_std`, the older name, becomes
    /// `algorithm.config.init_log_std`.
    fn from(spec: TrainSpec) -> Self {
        let mut config = spec.config;
        config.init_log_std = config.init_log_std.or(spec.start_log_std);
        TrainDocument {
            env: EnvSpec {
                world: spec.world,
                task: spec.task,
                tasks: spec.tasks,
                topology: spec.topology,
                objective: spec.objective,
                hold_s: spec.hold_s,
            },
            algorithm: AlgorithmSpec {
                name: spec.algorithm,
                config,
                sac: spec.sac,
            },
            run: RunSpec {
                steps: spec.steps,
                seed: spec.seed,
                envs: spec.envs,
                fine_tune: spec.fine_tune,
                imitation: spec.imitation,
                curriculum: spec.curriculum,
                settle_s: spec.settle_s,
                record: spec.record,
            },
        }
    }
}

impl From<EvalDocument> for EvalSpec {
    fn from(doc: EvalDocument) -> Self {
        let EvalDocument { env, run } = doc;
        EvalSpec {
            world: env.world,
            episodes: run.episodes,
            seed: run.seed,
            task: env.task,
            tasks: env.tasks,
            topology: env.topology,
            record: run.record,
            video: run.video,
            objective: env.objective,
            deterministic: run.deterministic,
            hold_s: env.hold_s,
        }
    }
}

impl From<EvalSpec> for EvalDocument {
    fn from(spec: EvalSpec) -> Self {
        EvalDocument {
            env: EnvSpec {
                world: spec.world,
                task: spec.task,
                tasks: spec.tasks,
                topology: spec.topology,
                objective: spec.objective,
                hold_s: spec.hold_s,
            },
            run: EvalRunSpec {
                episodes: spec.episodes,
                seed: spec.seed,
                deterministic: spec.deterministic,
                record: spec.record,
                video: spec.video,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every field of the flat specs has one place in the documents, so a field added to a
    /// flat spec and forgotten here fails.
    #[test]
    fn every_flat_field_has_one_place_in_the_documents() {
        let parts = [
            field_names::<EnvSpec>(),
            field_names::<AlgorithmSpec>(),
            field_names::<RunSpec>(),
        ];
        for field in field_names::<TrainSpec>() {
            let places = parts.iter().filter(|p| p.contains(field)).count()
                + usize::from(*field == "algorithm");
            let older_name = *field == "start_log_std";
            assert!(places == 1 || older_name, "{field} has {places} places");
        }
        for field in field_names::<EvalSpec>() {
            let env = field_names::<EnvSpec>().contains(field);
            let run = field_names::<EvalRunSpec>().contains(field);
            assert!(env != run, "{field}");
        }
        assert_eq!(
            document_path("config.minibatch_size"),
            "algorithm.config.minibatch_size"
        );
        assert_eq!(document_path("algorithm"), "algorithm.name");
        assert_eq!(document_path("steps"), "run.steps");
        assert_eq!(
            document_path("imitation.shifts.t07"),
            "run.imitation.shifts.t07"
        );
        assert_eq!(document_path("task"), "env.task");
        assert_eq!(document_path("episodes"), "run.episodes");
        assert_eq!(document_path("body"), "body");
        assert_eq!(document_path("tasks[2]"), "env.tasks[2]");
        // A document's own paths are left as they are.
        for path in [
            "run.steps",
            "env.task",
            "algorithm.name",
            "algorithm.config.clip_coef",
        ] {
            assert_eq!(document_path(path), path);
        }
    }

    #[test]
    fn a_document_and_its_flat_spec_convert_both_ways() {
        let flat: TrainSpec = serde_json::from_value(serde_json::json!({
            "algorithm": "crm-ppo", "world": "allegro", "steps": 1000, "seed": 3,
            "tasks": ["mug-wrap", "box-lift"], "topology": "auto", "envs": 4,
            "config": {"minibatch_size": 64, "init_log_std": -1.0}, "curriculum": true,
            "hold_s": 2.0, "settle_s": 0.5, "fine_tune": 7,
            "imitation": {"episodes": 10, "tasks": ["box-lift"]},
        }))
        .expect("flat");
        let doc = TrainDocument::from(flat.clone());
        let text = serde_json::to_value(&doc).expect("json");
        assert_eq!(text["env"]["world"], "allegro");
        assert_eq!(text["algorithm"]["config"]["minibatch_size"], 64);
        assert_eq!(text["run"]["steps"], 1000);
        let back: TrainDocument = serde_json::from_value(text).expect("document");
        assert_eq!(TrainSpec::from(back), flat);

        // The older name lands on the one knob.
        let old: TrainSpec = serde_json::from_value(serde_json::json!({
            "algorithm": "crm-ppo", "steps": 1, "start_log_std": -2.3,
        }))
        .expect("flat");
        let doc = TrainDocument::from(old.clone());
        assert_eq!(doc.algorithm.config.init_log_std, Some(-2.3));
        assert_eq!(TrainSpec::from(doc).start_log_std(), old.start_log_std());

        let eval: EvalSpec = serde_json::from_value(serde_json::json!({
            "world": "leap", "episodes": 200, "seed": 1, "task": "mug-wrap",
            "deterministic": true, "hold_s": 5.0,
        }))
        .expect("eval");
        let doc = EvalDocument::from(eval.clone());
        assert_eq!(doc.env.world.as_deref(), Some("leap"));
        assert_eq!(EvalSpec::from(doc), eval);
        let empty: EvalDocument = serde_json::from_str(r#"{"run": {}}"#).expect("defaults");
        assert_eq!(EvalSpec::from(empty), EvalSpec::default());

        let fields = |value: serde_json::Value| value.as_object().cloned().unwrap_or_default();
        assert!(is_document(&fields(
            serde_json::json!({"run": {"steps": 1}})
        )));
        assert!(!is_document(&fields(serde_json::json!({"steps": 1}))));
        // A flat field inside a document is refused by name.
        let err = serde_json::from_value::<TrainDocument>(serde_json::json!({
            "algorithm": {"name": "crm-ppo"}, "run": {"steps": 1}, "steps": 2,
        }))
        .expect_err("mixed");
        assert!(err.to_string().contains("steps"), "{err}");
    }
}
