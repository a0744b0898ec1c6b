//! Job specifications and reports, as the REST API, the gRPC protocol (as JSON) and the CLI
//! see them.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::algorithm::Algorithm;
use crate::config::{PpoConfig, SacConfig};
use crate::imitation::ImitationSpec;
use crate::record::RecordSpec;

/// Who executes the task's objective once the grasp is ready (DESIGN.md, "The paper's grasp
/// protocol").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectiveMode {
    /// The paper's protocol: the policy approaches and closes the hand; once the grasp is
    /// ready the arm executes the objective by script and the judge grades it.
    #[default]
    Scripted,
    /// The policy must also lift, pull, twist or press by itself (harder, beyond the paper).
    Learned,
}

impl ObjectiveMode {
    pub const ALL: [ObjectiveMode; 2] = [ObjectiveMode::Scripted, ObjectiveMode::Learned];

    /// The mode named `name`, as in the API.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    pub fn name(self) -> &'static str {
        match self {
            ObjectiveMode::Scripted => "scripted",
            ObjectiveMode::Learned => "learned",
        }
    }
}

/// The task ids a job names (`task` then `tasks`); empty means random tasks.
pub fn task_list(task: &Option<String>, tasks: &[String]) -> Vec<String> {
    task.iter().chain(tasks).cloned().collect()
}

/// A training job's parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainSpec {
    pub algorithm: Algorithm,
    /// The world to train in, by name (`GET /api/v1/worlds`); absent: the built-in `crm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world: Option<String>,
    /// Environment steps to train for in total.
    pub steps: u64,
    #[serde(default)]
    pub seed: u64,
    /// One task id, or random tasks over the benchmark.
    #[serde(default)]
    pub task: Option<String>,
    /// Several task ids: episodes draw among them (with `task`, if given).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tasks: Vec<String>,
    /// The grasp topology: absent or `"task"` for each task's assigned one, `"auto"` for the
    /// selection network's pick (paper, section II-B), or a topology name forced on every
    /// task.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology: Option<String>,
    /// Environments stepped in parallel (default: one per core of the worker). Results
    /// depend on this number and the seed, not on the thread count.
    #[serde(default)]
    pub envs: Option<usize>,
    /// PPO settings (crm-ppo, ippo, lppo, ppo); defaults cite the paper.
    #[serde(default)]
    pub config: PpoConfig,
    /// SAC settings (crm-sac).
    #[serde(default, skip_serializing_if = "is_default_sac")]
    pub sac: SacConfig,
    /// Recording for the rerun viewer; off when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<RecordSpec>,
    /// Behaviour cloning of the scripted oracle before PPO; off when absent.
    /// PPO learners of the grasping machine only (crm-ppo, ippo, lppo).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imitation: Option<ImitationSpec>,
    /// Start from this stored checkpoint's weights and observation statistics (its id, of
    /// the same algorithm, from this world or another with the same machine and observation
    /// layout), counting steps from 0, as `crm train --fine-tune` does; absent: fresh weights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fine_tune: Option<i64>,
    /// The older name of `config.init_log_std`, still taken from clients that send it (give
    /// one of the two; see [`check_start_log_std`]). [`TrainSpec::start_log_std`] reads
    /// either.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_log_std: Option<f64>,
    /// `scripted` (default, the paper's protocol) or `learned`.
    #[serde(default)]
    pub objective: ObjectiveMode,
    /// Draw the episodes' tasks more often where the policy fails (weight `0.2 + 1 -
    /// success` over each task's last 50 training episodes; after Prioritized Level Replay).
    /// Off by default: the paper draws tasks uniformly.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub curriculum: bool,
    /// Seconds of steady hold the judge asks of lift, pull, lever, wrap and handle tasks while
    /// training (see [`check_hold_s`]); absent: the paper's 5 s (section V-B-2). A shorter
    /// hold simulates less (the arm's scripted hold is most of the physics once the policy
    /// grasps) but does not teach grasps that last 5 s: a first phase, not a recipe
    /// (docs/LEARNING.md). Evaluations ask 5 s unless they say otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_s: Option<f64>,
    /// Training's shortcut through the hold (see [`check_settle_s`]): a hold-task grasp whose
    /// object has rested in the palm (within 1 mm and 0.01 rad) for this many seconds of the
    /// steady hold passes then, instead of after the full hold. Absent: off. Outcomes agree
    /// with the full hold in at least 99.5% of episodes at 0.5 s (docs/BENCHMARKS.md, `crm
    /// bench hold`); evaluations always run the full hold.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle_s: Option<f64>,
}

impl TrainSpec {
    /// Every log standard deviation of the policy at the run's start, if the job sets it
    /// (`config.init_log_std`, or `start_log_std`, its older name).
    pub fn start_log_std(&self) -> Option<f64> {
        self.config.init_log_std.or(self.start_log_std)
    }
}

/// Shortest and longest rest (s) a job's `settle_s` may ask: a few control steps, and less
/// than the paper's 5 s hold.
pub const SETTLE_S_RANGE: (f64, f64) = (0.1, 5.0);

/// Checks a job's `settle_s`: absent, or seconds within [`SETTLE_S_RANGE`].
pub fn check_settle_s(settle_s: Option<f64>) -> Result<(), String> {
    check_seconds(settle_s, SETTLE_S_RANGE, "0.5 s agrees with the full hold")
}

/// Shortest and longest steady hold (s) a job may ask: at least a few control steps, and room
/// for the arm's lift inside its 10 s execution.
pub const HOLD_S_RANGE: (f64, f64) = (0.1, 8.0);

/// Checks a job's `hold_s`: absent, or seconds within [`HOLD_S_RANGE`].
pub fn check_hold_s(hold_s: Option<f64>) -> Result<(), String> {
    check_seconds(hold_s, HOLD_S_RANGE, "the paper's test holds 5 s")
}

/// Absent, or seconds within `(low, high)`; the refusal names the range and `note`.
fn check_seconds(value: Option<f64>, (low, high): (f64, f64), note: &str) -> Result<(), String> {
    match value {
        Some(s) if !(low..=high).contains(&s) => {
            Err(format!("must be between {low} and {high} seconds ({note})"))
        }
        _ => Ok(()),
    }
}

/// Checks a job's `start_log_std` (the older name of `config.init_log_std`): absent, or a
/// value within [`crate::config::LOG_STD_RANGE`] for a PPO learner (SAC's standard deviation
/// is an output of its actor), and not beside `config.init_log_std`.
pub fn check_start_log_std(
    algorithm: Algorithm,
    value: Option<f64>,
    init_log_std: Option<f64>,
) -> Result<(), String> {
    let Some(value) = value else {
        return Ok(());
    };
    if algorithm == Algorithm::CrmSac {
        return Err(format!(
            "is for the PPO learners (crm-ppo, ippo, lppo, ppo), not {}",
            algorithm.name()
        ));
    }
    if init_log_std.is_some() {
        return Err("is the older name of config.init_log_std: give one of the two".to_string());
    }
    if !crate::config::in_log_std_range(value) {
        let (low, high) = crate::config::LOG_STD_RANGE;
        return Err(format!(
            "must be in [{low}, {high}] (a log standard deviation)"
        ));
    }
    Ok(())
}

pub(crate) fn is_default_sac(config: &SacConfig) -> bool {
    *config == SacConfig::default()
}

/// An evaluation job's parameters (the checkpoint is given beside them).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvalSpec {
    /// The world to evaluate in, by name; absent: the built-in `crm`. The checkpoint must
    /// come from a world with the same hand profile, spec and sensors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world: Option<String>,
    /// Episodes, each on a task drawn with the seed. Paper: 1,000.
    #[serde(default = "default_episodes")]
    pub episodes: u64,
    #[serde(default)]
    pub seed: u64,
    /// One task id, or random tasks over the benchmark.
    #[serde(default)]
    pub task: Option<String>,
    /// Several task ids: episodes draw among them (with `task`, if given).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tasks: Vec<String>,
    /// The grasp topology: absent or `"task"` for each task's assigned one, `"auto"` for the
    /// selection network's pick (paper, section II-B), or a topology name forced on every
    /// task.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology: Option<String>,
    /// Recording of evaluated episodes for the rerun viewer; off when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<RecordSpec>,
    /// A video of the first episodes (GIF), stored with the job; off when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<crate::VideoSpec>,
    /// `scripted` (default, the paper's protocol) or `learned`.
    #[serde(default)]
    pub objective: ObjectiveMode,
    /// Act with the policy's deterministic action (its mean; on a dimension the environment
    /// takes the magnitude of, the sampled action's mean magnitude: `docs/LEARNING.md`).
    /// Default: sample the policy's actions, seeded by `seed`, as the paper's evaluation does
    /// (the authors' `crm_ppo/evaluate.py` calls Stable-Baselines3's `model.predict(obs)`,
    /// whose default is `deterministic=False`; CleanRL's evaluations sample too).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub deterministic: bool,
    /// Seconds of steady hold the judge asks of hold tasks (see [`check_hold_s`]); absent:
    /// the paper's 5 s (section V-B-2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_s: Option<f64>,
}

pub(crate) fn default_episodes() -> u64 {
    1000
}

impl Default for EvalSpec {
    fn default() -> Self {
        Self {
            world: None,
            episodes: default_episodes(),
            seed: 0,
            task: None,
            tasks: Vec::new(),
            topology: None,
            record: None,
            video: None,
            objective: ObjectiveMode::default(),
            deterministic: false,
            hold_s: None,
        }
    }
}

/// What one training iteration (a rollout and an update) reports.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Iteration {
    pub iteration: u64,
    /// Environment steps trained so far, over the whole run.
    pub steps: u64,
    pub wall_s: f64,
    pub steps_per_s: f64,
    /// Episodes that ended in this iteration, and how many of them succeeded.
    pub episodes: u64,
    pub successes: u64,
    /// Success over the last 100 training episodes, whatever the early-stop window.
    pub success_rate_last_100: f64,
    /// Means over the episodes that ended in this iteration: the return, its split into
    /// intra-stage and transition rewards, and the length in control steps; `None` (JSON
    /// null) when none ended.
    pub mean_return: Option<f64>,
    pub mean_intra_return: Option<f64>,
    pub mean_transition_return: Option<f64>,
    pub mean_episode_length: Option<f64>,
    /// Share of this iteration's steps taken in each stage.
    pub stage_mix: BTreeMap<String, f64>,
    pub policy_loss: f64,
    pub value_loss: f64,
    pub entropy: f64,
    pub approx_kl: f64,
    pub clipfrac: f64,
    pub learning_rate: f64,
    /// Each task's success rate over its last 50 training episodes (tasks not drawn yet are
    /// left out), by task id: which tasks a run has learned and which it is stuck on.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub task_success: BTreeMap<String, f64>,
}

/// The `count` tasks of an iteration's `task_success` with the lowest success, lowest first
/// (ties by task id): what `crm train` prints and the run page charts.
pub fn weakest_tasks(task_success: &BTreeMap<String, f64>, count: usize) -> Vec<(&str, f64)> {
    let mut tasks: Vec<(&str, f64)> = task_success
        .iter()
        .map(|(task, success)| (task.as_str(), *success))
        .collect();
    tasks.sort_by(|a, b| a.1.total_cmp(&b.1).then_with(|| a.0.cmp(b.0)));
    tasks.truncate(count);
    tasks
}

/// One row of Table I.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub success_rate: f64,
    /// Mean control steps the policy took.
    pub mean_episode_length: f64,
    pub episodes: u64,
    /// Mean simulated seconds, the arm's scripted execution included.
    #[serde(default)]
    pub mean_sim_seconds: f64,
    /// How this row's episodes ended, as [`EvalReport::outcomes`] (empty where a report
    /// does not say).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub outcomes: BTreeMap<String, u64>,
    /// The share of these episodes the authors' judge (DexMobile: a rise within 1,000 physics
    /// steps once the grasp is ready, no hold; a press, a contact) would have passed, beside
    /// ours (a 5 s steady hold), where the report gives it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub authors_judge: Option<f64>,
}

impl Row {
    /// The row's episodes that did not succeed, by outcome (`dropped 3, out_of_reach 1`),
    /// or `-` when every episode succeeded or the report has no outcomes.
    pub fn failures(&self) -> String {
        failure_summary(&self.outcomes)
    }
}

/// Episodes that did not succeed, by outcome, in one line: `failure (x)` is shortened to `x`
/// and other labels (`out_of_reach (tipped over)`) are kept whole; `-` when there are none.
/// `crm eval`'s task table and `crm oracle` print it (the run page's list shortens the same
/// way in `web/`).
pub fn failure_summary<N: std::fmt::Display>(outcomes: &BTreeMap<String, N>) -> String {
    let failures: Vec<String> = outcomes
        .iter()
        .filter(|(outcome, _)| outcome.as_str() != "success")
        .map(|(outcome, n)| {
            let short = outcome
                .strip_prefix("failure (")
                .and_then(|o| o.strip_suffix(')'))
                .unwrap_or(outcome);
            format!("{short} {n}")
        })
        .collect();
    if failures.is_empty() {
        "-".to_string()
    } else {
        failures.join(", ")
    }
}

/// The whole table for one checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub algorithm: String,
    pub trained_steps: u64,
    pub episodes: u64,
    pub seed: u64,
    pub success_rate: f64,
    pub mean_episode_length: f64,
    /// Mean simulated seconds per episode, the arm's scripted execution included.
    #[serde(default)]
    pub mean_sim_seconds: f64,
    /// Who executed the objective (`scripted` or `learned`).
    #[serde(default)]
    pub objective: ObjectiveMode,
    /// Whether the policy took its deterministic action (`false`: sampled, the paper's way).
    #[serde(default)]
    pub deterministic: bool,
    pub per_objective: BTreeMap<String, Row>,
    /// The same per task (by id).
    #[serde(default)]
    pub per_task: BTreeMap<String, Row>,
    /// How the episodes ended: the terminal stage reached (a failure with its cause:
    /// `failure (dropped)`, `failure (crushed)`, `failure (timeout)`), or `truncated` at the
    /// time limit.
    #[serde(default)]
    pub outcomes: BTreeMap<String, u64>,
    /// The steady hold (s) the judge asked when the evaluation set one; absent: the
    /// paper's 5 s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_s: Option<f64>,
    /// The share the authors' judge would have passed ([`Row::authors_judge`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub authors_judge: Option<f64>,
}

impl EvalReport {
    /// The report as a Markdown table.
    pub fn markdown(&self) -> String {
        let mut text = format!(
            "{} ({} steps, {} objective, {} actions{}): success {:.3}, mean length {:.1} control steps ({:.1} s simulated) over {} episodes (seed {})\n\n| objective | success | episode length | simulated s |\n| --- | --- | --- | --- |\n",
            self.algorithm,
            self.trained_steps,
            self.objective.name(),
            if self.deterministic {
                "mean"
            } else {
                "sampled"
            },
            self.hold_s
                .map(|h| format!(", {h} s hold"))
                .unwrap_or_default(),
            self.success_rate,
            self.mean_episode_length,
            self.mean_sim_seconds,
            self.episodes,
            self.seed
        );
        for (name, r) in &self.per_objective {
            text.push_str(&format!(
                "| {name} | {:.2} | {:.1} | {:.1} |\n",
                r.success_rate, r.mean_episode_length, r.mean_sim_seconds
            ));
        }
        text.push_str(&format!(
            "| overall | {:.2} | {:.1} | {:.1} |\n",
            self.success_rate, self.mean_episode_length, self.mean_sim_seconds
        ));
        if let Some(share) = self.authors_judge {
            text.push_str(&format!(
                "\nThe authors' judge (a rise within 1,000 physics steps once ready, no hold) would pass {share:.3}.\n"
            ));
        }
        if self.per_task.len() > 1 {
            text.push_str("\n| task | success | episodes | episode length | simulated s | failures |\n| --- | --- | --- | --- | --- | --- |\n");
            for (task, r) in &self.per_task {
                text.push_str(&format!(
                    "| {task} | {:.2} | {} | {:.1} | {:.1} | {} |\n",
                    r.success_rate,
                    r.episodes,
                    r.mean_episode_length,
                    r.mean_sim_seconds,
                    r.failures()
                ));
            }
        }
        if !self.outcomes.is_empty() {
            let outcomes: Vec<String> = self
                .outcomes
                .iter()
                .map(|(outcome, n)| format!("{outcome}: {n}"))
                .collect();
            text.push_str(&format!("\nOutcomes: {}.\n", outcomes.join(", ")));
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn algorithms_round_trip_by_name() {
        for algorithm in Algorithm::ALL {
            assert_eq!(Algorithm::parse(algorithm.name()), Some(algorithm));
            let json = serde_json::to_string(&algorithm).expect("json");
            assert_eq!(json, format!("\"{}\"", algorithm.name()));
        }
        assert_eq!(Algorithm::parse("dqn"), None);
    }

    #[test]
    fn specs_take_defaults_and_refuse_unknown_fields() {
        let spec: TrainSpec =
            serde_json::from_str(r#"{"algorithm": "lppo", "steps": 10}"#).expect("spec");
        assert_eq!(spec.config, PpoConfig::default());
        assert!(
            serde_json::from_str::<TrainSpec>(r#"{"algorithm":"lppo","steps":1,"x":1}"#).is_err()
        );
        let eval: EvalSpec = serde_json::from_str("{}").expect("eval");
        assert_eq!(eval.episodes, 1000);
        // The paper's evaluation samples the policy; the mean action is asked for.
        assert!(!eval.deterministic);
        let mean: EvalSpec = serde_json::from_str(r#"{"deterministic": true}"#).expect("eval");
        assert!(mean.deterministic);
        assert!(serde_json::from_str::<EvalSpec>(r#"{"deterministic": "yes"}"#).is_err());
        // The weakest tasks, lowest first, ties by id.
        let tasks: BTreeMap<String, f64> = [("a", 0.9), ("b", 0.1), ("c", 1.0), ("d", 0.1)]
            .into_iter()
            .map(|(t, s)| (t.to_string(), s))
            .collect();
        assert_eq!(
            weakest_tasks(&tasks, 3),
            [("b", 0.1), ("d", 0.1), ("a", 0.9)]
        );
        assert_eq!(weakest_tasks(&tasks, 9).len(), 4);
        // The steady hold: the paper's 5 s unless asked, within range.
        assert_eq!(eval.hold_s, None);
        assert!(check_hold_s(None).is_ok());
        assert!(check_hold_s(Some(1.0)).is_ok());
        for bad in [
            0.0,
            0.05,
            8.5,
            8.000000000000002,
            0.09999999999999999,
            f64::NAN,
            -1.0,
        ] {
            assert!(check_hold_s(Some(bad)).is_err(), "{bad}");
        }
        // The starting log standard deviation's older name: PPO learners, within range, and
        // not beside `config.init_log_std`; either name reads the same.
        assert!(check_start_log_std(Algorithm::CrmSac, None, None).is_ok());
        for algorithm in [
            Algorithm::CrmPpo,
            Algorithm::Ippo,
            Algorithm::Lppo,
            Algorithm::Ppo,
        ] {
            assert!(check_start_log_std(algorithm, Some(-2.3), None).is_ok());
            assert!(check_start_log_std(algorithm, Some(-2.3), Some(-2.3)).is_err());
            for bad in [-5.01, 2.01, f64::NAN, f64::INFINITY] {
                assert!(
                    check_start_log_std(algorithm, Some(bad), None).is_err(),
                    "{bad}"
                );
            }
        }
        assert!(check_start_log_std(Algorithm::CrmSac, Some(-2.3), None).is_err());
        let old: TrainSpec =
            serde_json::from_str(r#"{"algorithm":"crm-ppo","steps":1,"start_log_std":-2.3}"#)
                .expect("train");
        let new: TrainSpec = serde_json::from_str(
            r#"{"algorithm":"crm-ppo","steps":1,"config":{"init_log_std":-2.3}}"#,
        )
        .expect("train");
        assert_eq!(old.start_log_std(), Some(-2.3));
        assert_eq!(new.start_log_std(), Some(-2.3));
        let fresh: TrainSpec =
            serde_json::from_str(r#"{"algorithm":"crm-ppo","steps":1}"#).expect("train");
        assert_eq!(fresh.start_log_std(), None);
        // Curriculum: off unless asked, and not written out when off.
        let spec: TrainSpec =
            serde_json::from_str(r#"{"algorithm":"crm-ppo","steps":1}"#).expect("train");
        assert!(!spec.curriculum);
        assert!(
            !serde_json::to_string(&spec)
                .expect("json")
                .contains("curriculum")
        );
    }

    #[test]
    fn markdown_lists_each_tasks_failures_by_cause() {
        let row = |outcomes: &[(&str, u64)]| Row {
            success_rate: 0.5,
            mean_episode_length: 30.0,
            episodes: outcomes.iter().map(|(_, n)| n).sum(),
            mean_sim_seconds: 5.0,
            outcomes: outcomes.iter().map(|(o, n)| (o.to_string(), *n)).collect(),
            authors_judge: None,
        };
        let bowl = row(&[
            ("success", 2),
            ("failure (dropped)", 1),
            ("out_of_reach", 1),
        ]);
        assert_eq!(bowl.failures(), "dropped 1, out_of_reach 1");
        let box_lift = row(&[("success", 3)]);
        assert_eq!(box_lift.failures(), "-");
        let report = EvalReport {
            algorithm: "crm-ppo".into(),
            trained_steps: 1,
            episodes: 7,
            seed: 0,
            success_rate: 5.0 / 7.0,
            mean_episode_length: 30.0,
            mean_sim_seconds: 5.0,
            objective: ObjectiveMode::default(),
            deterministic: false,
            hold_s: None,
            authors_judge: None,
            per_objective: BTreeMap::from([("lift".to_string(), row(&[("success", 5)]))]),
            per_task: BTreeMap::from([
                ("bowl-lift".to_string(), bowl.clone()),
                ("box-lift".to_string(), box_lift),
            ]),
            outcomes: BTreeMap::new(),
        };
        let text = report.markdown();
        assert!(text.contains("| bowl-lift | 0.50 | 4 | 30.0 | 5.0 | dropped 1, out_of_reach 1 |"));
        assert!(text.contains("| box-lift | 0.50 | 3 | 30.0 | 5.0 | - |"));
        // Rows of older reports have no outcomes; they read back and are not written out.
        let old: Row = serde_json::from_str(
            r#"{"success_rate": 1.0, "mean_episode_length": 2.0, "episodes": 1}"#,
        )
        .expect("old row");
        assert!(old.outcomes.is_empty());
        assert!(
            !serde_json::to_string(&old)
                .expect("json")
                .contains("outcomes")
        );
        let json = serde_json::to_string(&bowl).expect("json");
        assert_eq!(serde_json::from_str::<Row>(&json).expect("row"), bowl);
    }
}
