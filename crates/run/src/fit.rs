//! Fitting a world's grasp locations to its hand (`crm world fit-grasps`): for each task whose
//! scripted oracle succeeds less often than a threshold on the search seeds, a search over
//! offsets of its grasp location (object frame) within a box, each candidate judged by the
//! oracle on the same seeds; the best is rechecked on seeds the search did not use. Datasets
//! give grasp locations for the hand they were recorded with; this moves them to where this
//! hand's grasp holds, as data ([`grasp_sim::corrections`]), never as code for one task.
//!
//! The search: a pattern search from the uncorrected location steps along each axis (both
//! signs) while one improves the success, halving the step when none does, down to the
//! finest step. Where the task fails on every search seed, or that climb finds nothing
//! better, a coarse grid over the box (its centre and the half-way and edge points per axis)
//! finds ground to climb from instead. Ties keep the smaller offset. Deterministic: the same
//! world, options and seeds give the same offsets.

use std::collections::BTreeMap;
use std::sync::Arc;

use grasp_sim::benchmark::Benchmark;
use grasp_sim::corrections::TaskCorrection;
use grasp_sim::{GraspEnv, SimConfig};
use rayon::prelude::*;

use crate::Result;

/// How the search goes.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Tasks under this oracle success on the search seeds are searched.
    pub threshold: f64,
    /// Half-widths of the box of offsets (m, object frame).
    pub bounds: [f32; 3],
    /// The pattern search's first and finest step (m).
    pub step: f32,
    pub min_step: f32,
    /// `[first, count]` seeds judging every candidate, and those rechecking the best.
    pub search_seeds: [u64; 2],
    pub check_seeds: [u64; 2],
    /// Only these tasks (ids); all when empty.
    pub tasks: Vec<String>,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            // Issue #58's bar for a hand world's oracle (>= 0.80 over 26 tasks x 10 seeds).
            threshold: 0.8,
            // `t07`'s handle holds with the palm 4-8 cm further in (docs/WORLDS.md); the
            // oracle's shifts are bounded at 10 cm.
            bounds: [0.06, 0.06, 0.06],
            step: 0.02,
            min_step: 0.005,
            search_seeds: [0, 10],
            // The seeds the oracle figures of docs/WORLDS.md recheck on (100-109).
            check_seeds: [100, 10],
            tasks: Vec::new(),
        }
    }
}

/// One task's outcome: its id and the offset found, with the oracle's success around it
/// (a [`TaskCorrection`], written as one where it improves on the uncorrected location).
pub type TaskFit = (String, TaskCorrection);

/// The oracle's success on `task` with its grasp location moved by `offset`, over `seeds`.
fn success(
    benchmark: &Benchmark,
    config: &SimConfig,
    machine: &crm::Machine,
    task: usize,
    offset: [f32; 3],
    seeds: [u64; 2],
) -> Result<f64> {
    let mut moved = benchmark.clone();
    for (g, v) in moved.tasks[task].grasp.offset.iter_mut().zip(offset) {
        *g += v;
    }
    let moved = Arc::new(moved);
    let wins = (seeds[0]..seeds[0] + seeds[1])
        .into_par_iter()
        .map(|seed| {
            let env = GraspEnv::new(moved.clone(), config.clone());
            grasp_sim::oracle::run_episode(env, machine.clone(), task, seed)
                .map(|(episode, _)| usize::from(episode.success))
        })
        .collect::<std::result::Result<Vec<_>, _>>()?
        .into_iter()
        .sum::<usize>();
    Ok(wins as f64 / seeds[1].max(1) as f64)
}

/// Whether success `s` at offset `o` beats `best` at `at`: higher, or as high and smaller.
fn better(s: f64, o: [f32; 3], best: f64, at: [f32; 3]) -> bool {
    s > best + 1e-12 || ((s - best).abs() <= 1e-12 && norm(o) < norm(at) - 1e-12)
}

/// The best offset and its success, from the uncorrected location's success `before`: a
/// climb from there; where the task fails on every seed, or that climb finds nothing
/// better, the coarse grid finds ground to climb from instead.
fn search(
    judge: &mut impl FnMut([f32; 3]) -> Result<f64>,
    options: &FitOptions,
    before: f64,
) -> Result<(f64, [f32; 3])> {
    let mut found = (before, [0.0f32; 3]);
    if before > 0.0 {
        found = climb(judge, options, found)?;
    }
    if found.0 <= before {
        let start = grid(judge, options, found)?;
        found = climb(judge, options, start)?;
    }
    Ok(found)
}

/// The best of `from` and a coarse grid over the box: its centre and the half-way and edge
/// points per axis (125 offsets).
fn grid(
    judge: &mut impl FnMut([f32; 3]) -> Result<f64>,
    options: &FitOptions,
    from: (f64, [f32; 3]),
) -> Result<(f64, [f32; 3])> {
    let (mut best, mut at) = from;
    let points = |b: f32| [-b, -b / 2.0, 0.0, b / 2.0, b];
    for x in points(options.bounds[0]) {
        for y in points(options.bounds[1]) {
            for z in points(options.bounds[2]) {
                let o = [x, y, z];
                let s = judge(o)?;
                if better(s, o, best, at) && s > 0.0 {
                    (best, at) = (s, o);
                }
            }
        }
    }
    Ok((best, at))
}

/// The pattern search from `from`: a step along each axis (both signs) while one improves
/// the success, the step halved when none does, down to the finest.
fn climb(
    judge: &mut impl FnMut([f32; 3]) -> Result<f64>,
    options: &FitOptions,
    from: (f64, [f32; 3]),
) -> Result<(f64, [f32; 3])> {
    let (mut best, mut at) = from;
    let mut step = options.step;
    while step >= options.min_step - 1e-9 && best < 1.0 {
        let mut moved = false;
        for axis in 0..3 {
            for sign in [1.0f32, -1.0] {
                let mut o = at;
                o[axis] += sign * step;
                if o[axis].abs() > options.bounds[axis] + 1e-6 {
                    continue;
                }
                let s = judge(o)?;
                if s > best + 1e-12 {
                    (best, at) = (s, o);
                    moved = true;
                }
            }
        }
        if !moved {
            step /= 2.0;
        }
    }
    Ok((best, at))
}

fn key(offset: [f32; 3]) -> [i64; 3] {
    offset.map(|v| (v * 1e5).round() as i64)
}

fn norm(offset: [f32; 3]) -> f32 {
    offset.iter().map(|v| v * v).sum::<f32>()
}

/// Searches the tasks of `benchmark` under the threshold; `progress` hears of each task.
pub fn fit(
    benchmark: &Benchmark,
    config: &SimConfig,
    machine: &crm::Machine,
    options: &FitOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<TaskFit>> {
    let selected: Vec<usize> = if options.tasks.is_empty() {
        (0..benchmark.tasks.len()).collect()
    } else {
        options
            .tasks
            .iter()
            .map(|id| crate::choice::task_index(benchmark, id))
            .collect::<Result<_>>()?
    };
    let mut fits = Vec::new();
    for task in selected {
        let id = benchmark.tasks[task].id.clone();
        let before = success(
            benchmark,
            config,
            machine,
            task,
            [0.0; 3],
            options.search_seeds,
        )?;
        if before >= options.threshold {
            progress(&format!("{id}: {before:.2} on the search seeds, kept"));
            continue;
        }
        let mut seen: BTreeMap<[i64; 3], f64> = BTreeMap::new();
        seen.insert(key([0.0; 3]), before);
        let mut judge = |offset: [f32; 3]| -> Result<f64> {
            if let Some(&s) = seen.get(&key(offset)) {
                return Ok(s);
            }
            let s = success(
                benchmark,
                config,
                machine,
                task,
                offset,
                options.search_seeds,
            )?;
            seen.insert(key(offset), s);
            Ok(s)
        };
        let (best, at) = search(&mut judge, options, before)?;
        let at = at.map(|v| (v * 1e4).round() / 1e4);
        let before_check = success(
            benchmark,
            config,
            machine,
            task,
            [0.0; 3],
            options.check_seeds,
        )?;
        let after_check = success(benchmark, config, machine, task, at, options.check_seeds)?;
        progress(&format!(
            "{id}: {before:.2} -> {best:.2} on the search seeds, {before_check:.2} -> \
             {after_check:.2} on the check seeds, offset {at:?} ({} offsets judged)",
            seen.len()
        ));
        fits.push((
            id,
            TaskCorrection {
                offset: at,
                before,
                after: best,
                before_check,
                after_check,
                evaluated: seen.len(),
            },
        ));
    }
    Ok(fits)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
        norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]).sqrt()
    }

    /// A task whose uncorrected location passes 0.4, every nearby offset less, and whose
    /// hold lies on the grid at (3, -3, 0) cm: the climb alone stays put, the grid finds it.
    fn island(o: [f32; 3]) -> Result<f64> {
        let d = distance(o, [0.03, -0.03, 0.0]);
        Ok(if d < 0.012 {
            1.0
        } else if norm(o) < 1e-12 {
            0.4
        } else {
            0.1
        })
    }

    #[test]
    fn a_climb_that_finds_nothing_restarts_from_the_grid() {
        let options = FitOptions::default();
        let mut judged = 0;
        let mut judge = |o: [f32; 3]| {
            judged += 1;
            island(o)
        };
        let (best, at) = search(&mut judge, &options, 0.4).expect("search");
        assert_eq!(best, 1.0);
        assert!(distance(at, [0.03, -0.03, 0.0]) < 0.012, "{at:?}");
        // The climb's 6 neighbours at each of 3 steps, then the 125 grid points.
        assert!(judged >= 125, "{judged}");
    }

    #[test]
    fn a_climb_that_improves_skips_the_grid() {
        let options = FitOptions::default();
        let mut judged = 0;
        // Success rises toward (2, 0, 0) cm from 0.5 at the uncorrected location.
        let mut judge = |o: [f32; 3]| {
            judged += 1;
            Ok(f64::from(1.0 - 10.0 * distance(o, [0.02, 0.0, 0.0])).max(0.0))
        };
        let (best, at) = search(&mut judge, &options, 0.8).expect("search");
        assert!((best - 1.0).abs() < 1e-6 && distance(at, [0.02, 0.0, 0.0]) < 1e-6);
        assert!(judged < 20, "{judged}");
    }
}
