//! A study on disk: what `crm results` writes as runs finish and what `--report-only` reads
//! back, so the report can be rebuilt without training. One folder per study
//! (`OUT/results/NAME/`):
//!
//! - `study.json`: how the study was asked ([`StudyFile`]: budget, seeds, settings, world,
//!   the command line);
//! - `ALGO/seed-K/run.json`: how the run went ([`RunFile`]: steps, early stop, wall-clock);
//! - `ALGO/seed-K/eval.json` and `eval-deterministic.json`: its final checkpoint's
//!   evaluations, sampled and deterministic (`crm_api::EvalReport`, per task and objective);
//! - `ALGO/seed-K/curve.csv`: its training curve, one line per iteration ([`CURVE_COLUMNS`]);
//! - `ALGO/seed-K/checkpoint.safetensors`: its final checkpoint, lineage in the header.
//!
//! A run counts as finished when its `run.json` exists; the other files are written first.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use crm_api::{EvalReport, Iteration, PpoConfig, SacConfig};
use serde::{Deserialize, Serialize};

/// `study.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudyFile {
    /// The study's folder name (and its sweeps' name on the coordinator).
    pub name: String,
    /// The command line that runs (or continues) it.
    pub command: String,
    /// The world trained and evaluated in (`crm`: the built-in one).
    pub world: String,
    /// Environment steps per run (the budget; runs stop sooner by the early-stop rule).
    pub steps: u64,
    pub envs: usize,
    /// The tasks trained and evaluated (empty: the world's whole benchmark).
    pub tasks: Vec<String>,
    /// Evaluation episodes per checkpoint and their seed.
    pub episodes: u64,
    pub eval_seed: u64,
    pub seeds: Vec<u64>,
    pub algorithms: Vec<String>,
    pub ppo: PpoConfig,
    pub sac: SacConfig,
    /// Each task's objective (from the coordinator's catalog of the world), for the per-objective
    /// figures.
    pub task_objectives: std::collections::BTreeMap<String, String>,
    /// Training's hold shortcut (s), as the jobs ask it.
    #[serde(default)]
    pub settle_s: Option<f64>,
    /// Why the budget is what it is (shown in the report).
    #[serde(default)]
    pub budget_note: Option<String>,
    /// Training jobs set aside by `--redo`, per algorithm: the coordinator's ids of the runs
    /// trained again, which the study no longer counts.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub superseded: std::collections::BTreeMap<String, Vec<i64>>,
}

/// `run.json`: one finished training run and its evaluations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunFile {
    pub algorithm: String,
    pub seed: u64,
    /// Environment steps trained.
    pub steps: u64,
    /// Whether it stopped by the early-stop rule (else it ran its budget).
    pub stopped_early: bool,
    /// Seconds from its first lease to its end, and how many leases it took (more than one:
    /// it was resumed from a checkpoint).
    pub train_wall_s: f64,
    pub leases: u64,
    /// The step its last lease resumed from (its checkpoint's), when it was resumed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resumed_from_steps: Option<u64>,
    /// Seconds of its sampled and its deterministic evaluation.
    pub eval_wall_s: f64,
    pub eval_deterministic_wall_s: f64,
    /// The coordinator's ids of the training job and the final checkpoint.
    pub train_job: i64,
    pub checkpoint_id: i64,
}

/// The columns of `curve.csv`, in order.
pub const CURVE_COLUMNS: [&str; 9] = [
    "iteration",
    "steps",
    "wall_s",
    "episodes",
    "successes",
    "success_rate_last_100",
    "mean_episode_length",
    "mean_return",
    "mean_transition_return",
];

/// One line of `curve.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct CurvePoint {
    pub iteration: u64,
    pub steps: u64,
    pub wall_s: f64,
    pub episodes: u64,
    pub successes: u64,
    pub success_rate_last_100: f64,
    /// NaN where no episode ended in the iteration.
    pub mean_episode_length: f64,
    pub mean_return: f64,
    pub mean_transition_return: f64,
}

impl CurvePoint {
    pub fn of(it: &Iteration) -> Self {
        Self {
            iteration: it.iteration,
            steps: it.steps,
            wall_s: it.wall_s,
            episodes: it.episodes,
            successes: it.successes,
            success_rate_last_100: it.success_rate_last_100,
            mean_episode_length: it.mean_episode_length.unwrap_or(f64::NAN),
            mean_return: it.mean_return.unwrap_or(f64::NAN),
            mean_transition_return: it.mean_transition_return.unwrap_or(f64::NAN),
        }
    }
}

/// A finished run as read back: its record, evaluations and curve.
#[derive(Clone, Debug)]
pub struct Run {
    pub file: RunFile,
    pub eval: EvalReport,
    pub deterministic: EvalReport,
    pub curve: Vec<CurvePoint>,
}

impl Run {
    /// Seconds workers spent training it: the sum over its leases of each lease's wall-clock
    /// (a curve's `wall_s` starts again with each lease, so a drop marks the next), leaving
    /// out the time it waited between leases, which `RunFile::train_wall_s` counts.
    pub fn training_s(&self) -> f64 {
        let mut total = 0.0;
        let mut previous: Option<f64> = None;
        for point in &self.curve {
            if let Some(p) = previous
                && point.wall_s < p
            {
                total += p;
            }
            previous = Some(point.wall_s);
        }
        match previous {
            Some(p) => total + p,
            None => self.file.train_wall_s,
        }
    }

    /// Training episodes ended, how many succeeded, and their mean length (control steps),
    /// over the curve. An iteration redone after a resume (the same `steps` again) counts
    /// once, as its last record.
    pub fn training_episodes(&self) -> (u64, u64, f64) {
        let mut by_steps = std::collections::BTreeMap::new();
        for point in &self.curve {
            by_steps.insert(point.steps, point);
        }
        let (mut episodes, mut successes, mut length) = (0, 0, 0.0);
        for point in by_steps.values() {
            episodes += point.episodes;
            successes += point.successes;
            if point.episodes > 0 && point.mean_episode_length.is_finite() {
                length += point.mean_episode_length * point.episodes as f64;
            }
        }
        let mean = if episodes > 0 {
            length / episodes as f64
        } else {
            f64::NAN
        };
        (episodes, successes, mean)
    }
}

/// A study folder with its finished runs.
#[derive(Clone, Debug)]
pub struct Study {
    pub dir: PathBuf,
    pub file: StudyFile,
    /// Finished runs, by algorithm in the study's order, then seed.
    pub runs: Vec<Run>,
}

/// The field of [`StudyFile`] holding the settings `algorithm` trains with: `sac` for
/// CRM-SAC, `ppo` for the PPO family.
pub fn settings_field(algorithm: &str) -> &'static str {
    if algorithm == crm_api::Algorithm::CrmSac.name() {
        "sac"
    } else {
        "ppo"
    }
}

/// The folder of one run.
pub fn run_dir(study: &Path, algorithm: &str, seed: u64) -> PathBuf {
    study.join(algorithm).join(format!("seed-{seed}"))
}

/// Writes `value` as pretty JSON with a final newline.
pub fn write_json(path: &Path, value: &impl Serialize) -> anyhow::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let text = serde_json::to_string_pretty(value)? + "\n";
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not a valid file", path.display()))
}

/// A number as the CSV holds it: empty for NaN, else Rust's shortest round-trip form.
fn number(v: f64) -> String {
    if v.is_nan() {
        String::new()
    } else {
        format!("{v}")
    }
}

/// The curve as CSV, header first.
pub fn curve_csv(points: &[CurvePoint]) -> String {
    let mut text = CURVE_COLUMNS.join(",") + "\n";
    for p in points {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            p.iteration,
            p.steps,
            number(p.wall_s),
            p.episodes,
            p.successes,
            number(p.success_rate_last_100),
            number(p.mean_episode_length),
            number(p.mean_return),
            number(p.mean_transition_return),
        ));
    }
    text
}

/// Reads `curve.csv` back; a file with other columns or a field that is not a number is an
/// error naming the file, line and column.
pub fn read_curve(path: &Path) -> anyhow::Result<Vec<CurvePoint>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    if header != CURVE_COLUMNS.join(",") {
        bail!(
            "{}: line 1: the header must be {:?}",
            path.display(),
            CURVE_COLUMNS.join(",")
        );
    }
    lines
        .enumerate()
        .map(|(k, line)| {
            let fields: Vec<&str> = line.split(',').collect();
            if fields.len() != CURVE_COLUMNS.len() {
                bail!(
                    "{}: line {}: {} fields, {} expected",
                    path.display(),
                    k + 2,
                    fields.len(),
                    CURVE_COLUMNS.len()
                );
            }
            let float = |i: usize| -> anyhow::Result<f64> {
                if fields[i].is_empty() {
                    return Ok(f64::NAN);
                }
                fields[i].parse().with_context(|| {
                    format!(
                        "{}: line {}: {}: {:?} is not a number",
                        path.display(),
                        k + 2,
                        CURVE_COLUMNS[i],
                        fields[i]
                    )
                })
            };
            let int = |i: usize| -> anyhow::Result<u64> {
                fields[i].parse().with_context(|| {
                    format!(
                        "{}: line {}: {}: {:?} is not a count",
                        path.display(),
                        k + 2,
                        CURVE_COLUMNS[i],
                        fields[i]
                    )
                })
            };
            Ok(CurvePoint {
                iteration: int(0)?,
                steps: int(1)?,
                wall_s: float(2)?,
                episodes: int(3)?,
                successes: int(4)?,
                success_rate_last_100: float(5)?,
                mean_episode_length: float(6)?,
                mean_return: float(7)?,
                mean_transition_return: float(8)?,
            })
        })
        .collect()
}

impl StudyFile {
    /// The objectives of the study's tasks, sorted.
    pub fn objectives(&self) -> Vec<String> {
        self.task_objectives
            .values()
            .cloned()
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect()
    }
}

impl Study {
    /// Reads a study folder and every finished run in it.
    pub fn read(dir: &Path) -> anyhow::Result<Self> {
        let file: StudyFile = read_json(&dir.join("study.json"))?;
        let mut runs = Vec::new();
        for algorithm in &file.algorithms {
            for &seed in &file.seeds {
                let run = run_dir(dir, algorithm, seed);
                if !run.join("run.json").exists() {
                    continue;
                }
                runs.push(Run {
                    file: read_json(&run.join("run.json"))?,
                    eval: read_json(&run.join("eval.json"))?,
                    deterministic: read_json(&run.join("eval-deterministic.json"))?,
                    curve: read_curve(&run.join("curve.csv"))?,
                });
            }
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            file,
            runs,
        })
    }

    /// The finished runs of `algorithm`, by seed.
    pub fn runs_of<'a>(&'a self, algorithm: &'a str) -> impl Iterator<Item = &'a Run> + 'a {
        self.runs
            .iter()
            .filter(move |r| r.file.algorithm == algorithm)
    }

    /// Whether `algorithm`'s run of `seed` has finished.
    pub fn finished(&self, algorithm: &str, seed: u64) -> bool {
        self.runs
            .iter()
            .any(|r| r.file.algorithm == algorithm && r.file.seed == seed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_curve_reads_back_as_written_and_a_bad_field_is_named() {
        let points = vec![
            CurvePoint {
                iteration: 1,
                steps: 8192,
                wall_s: 3.25,
                episodes: 0,
                successes: 0,
                success_rate_last_100: 0.0,
                mean_episode_length: f64::NAN,
                mean_return: f64::NAN,
                mean_transition_return: f64::NAN,
            },
            CurvePoint {
                iteration: 2,
                steps: 16384,
                wall_s: 6.5,
                episodes: 12,
                successes: 5,
                success_rate_last_100: 5.0 / 12.0,
                mean_episode_length: 41.0 / 3.0,
                mean_return: -0.1,
                mean_transition_return: 1e-17,
            },
        ];
        let dir = std::env::temp_dir().join(format!("crm-curve-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("curve.csv");
        std::fs::write(&path, curve_csv(&points)).expect("write");
        let back = read_curve(&path).expect("read");
        assert_eq!(back.len(), 2);
        assert!(back[0].mean_return.is_nan());
        assert_eq!(back[1], points[1], "every value round-trips exactly");
        std::fs::write(&path, curve_csv(&points).replace("6.5", "six")).expect("write");
        let err = read_curve(&path).expect_err("a bad number").to_string();
        assert!(err.contains("line 3") && err.contains("wall_s"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_resumed_runs_training_time_sums_its_leases_and_leaves_out_the_wait() {
        // The committed study: IPPO seed 0 trained in two leases, hours apart.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results/builtin");
        let study = Study::read(&dir).expect("the committed study");
        let run = study
            .runs_of("ippo")
            .find(|r| r.file.seed == 0)
            .expect("ippo seed 0");
        assert_eq!(run.file.leases, 2);
        let drop = run
            .curve
            .windows(2)
            .position(|w| w[1].wall_s < w[0].wall_s)
            .expect("the second lease starts its clock again");
        let expected = run.curve[drop].wall_s + run.curve.last().expect("points").wall_s;
        assert!((run.training_s() - expected).abs() < 1e-9);
        assert!(run.training_s() < run.file.train_wall_s);
        // One lease: its curve's last wall-clock.
        let one = study
            .runs_of("crm-ppo")
            .find(|r| r.file.leases == 1)
            .expect("a one-lease run");
        assert_eq!(one.training_s(), one.curve.last().expect("points").wall_s);
    }

    #[test]
    fn a_redone_iteration_counts_once_in_the_training_episodes() {
        // The committed study: IPPO seed 3 never succeeded, every episode at the time limit.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results/builtin");
        let study = Study::read(&dir).expect("the committed study");
        let mut run = study
            .runs_of("ippo")
            .find(|r| r.file.seed == 3)
            .expect("ippo seed 3")
            .clone();
        let (episodes, successes, length) = run.training_episodes();
        assert_eq!(successes, 0);
        assert_eq!(episodes, run.curve.iter().map(|p| p.episodes).sum::<u64>());
        assert!((length - 600.0).abs() < 1.0, "{length}");
        // A resumed run redoes the iterations after its checkpoint: the same steps recorded
        // again, after the lease that was lost. The later record counts, once.
        let mut redone = run.curve[10].clone();
        redone.episodes += 5;
        redone.successes += 2;
        run.curve.push(redone);
        let (again, succeeded, _) = run.training_episodes();
        assert_eq!((again, succeeded), (episodes + 5, 2));
    }
}
