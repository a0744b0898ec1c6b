//! A training job's imitation stage (`TrainSpec::imitation`): the scripted oracle's
//! demonstrations ([`crate::demos`]), anchor states of the starting policy
//! ([`crate::anchors`]), then behaviour cloning into the trainer's policy.

use crm_api::TrainSpec;

use crate::demos::{DemoSource, oracle_demos_with, shifts_by_task};
use crate::error::{Result, invalid};
use crate::train::Trainer;
use crate::{Env, EnvChoice};

/// The phases of a job's imitation stage, as the coordinator shows them.
pub const PHASE_DEMOS: &str = "demonstrations";
pub const PHASE_ANCHORS: &str = "anchor states";
pub const PHASE_CLONING: &str = "behaviour cloning";

/// Runs a training job's imitation (`spec.imitation`; none: nothing to do) on `trainer`'s
/// policy: behaviour cloning of the oracle's demonstrations. `phase(name, done, total)` hears
/// how far each phase is (episodes, then epochs) and `note` gets a line saying what it gave
/// and how long it took; `false` from either stops it, and `false` is returned (stop the job,
/// as when it was cancelled meanwhile).
pub fn imitate(
    spec: &TrainSpec,
    env: &Env,
    trainer: &mut Trainer,
    mut note: impl FnMut(&str) -> bool,
    mut phase: impl FnMut(&str, u64, u64) -> bool,
) -> Result<bool> {
    let Some(imitation) = &spec.imitation else {
        return Ok(true);
    };
    // Which learners clone, and the imitation's own ranges: the document's rules.
    spec.validate().map_err(|err| invalid!("{err}"))?;
    let started = std::time::Instant::now();
    let benchmark = env.benchmark()?;
    let machine = env.machine()?;
    // The tasks demonstrated: the imitation's own list, else the job's.
    let demonstrated = imitation
        .tasks
        .iter()
        .map(|id| {
            benchmark
                .task_index(id)
                .ok_or_else(|| invalid!("imitation.tasks: unknown task {id:?} (see `crm tasks`)"))
        })
        .collect::<Result<Vec<usize>>>()?;
    let choice = if imitation.tasks.is_empty() {
        EnvChoice::of(&benchmark, &spec.task, &spec.tasks, &spec.topology)?
    } else {
        EnvChoice::of(&benchmark, &None, &imitation.tasks, &spec.topology)?
    };
    let shifts = shifts_by_task(&benchmark, &imitation.shifts)
        .map_err(|e| invalid!("imitation.shifts: {e}"))?;
    let stages = imitation
        .stages
        .iter()
        .map(|name| {
            machine.stage_id(name).ok_or_else(|| {
                let names: Vec<&str> = (0..machine.stage_count())
                    .map(|s| machine.stage_name(s))
                    .collect();
                invalid!(
                    "imitation.stages: unknown stage {name:?} (this world's machine has {})",
                    names.join(", ")
                )
            })
        })
        .collect::<Result<Vec<usize>>>()?;
    let config = env.config_for(spec.objective, spec.hold_s)?;
    let source = DemoSource {
        benchmark: &benchmark,
        config: &config,
        machine: &machine,
        choice: &choice,
        seed: spec.seed.wrapping_mul(7_919).wrapping_add(1 << 32),
        noise: imitation.noise as f32,
        shifts: &shifts,
        stages: &stages,
        skip: &[],
    };
    let total = imitation.episodes;
    let collected = oracle_demos_with(&source, total, |done| phase(PHASE_DEMOS, done, total))?;
    let Some(mut all) = collected else {
        return Ok(false);
    };
    let anchors = imitation.anchor_episodes;
    if anchors > 0 {
        // The starting policy's own episodes on the job's other tasks, labelled with its
        // means: the regression holds it to them while it learns the demonstrated tasks.
        let job_tasks = EnvChoice::of(&benchmark, &spec.task, &spec.tasks, &spec.topology)?;
        let anchor_source = DemoSource {
            choice: &job_tasks,
            seed: source.seed.wrapping_add(1 << 40),
            skip: &demonstrated,
            ..source
        };
        let rows = crate::anchors::policy_anchors(
            &anchor_source,
            anchors,
            |states, stages| trainer.policy_actions(states, stages),
            |done| phase(PHASE_ANCHORS, done, anchors),
        )?;
        let Some(rows) = rows else {
            return Ok(false);
        };
        all.anchors = rows.len();
        all.demos.extend(rows);
    }
    let epochs = imitation.epochs as u64;
    let mut going = phase(PHASE_CLONING, 0, epochs);
    if !going {
        return Ok(false);
    }
    let loss = trainer.imitate(
        &all.demos,
        imitation.epochs,
        imitation.learning_rate,
        |done, _| {
            going = phase(PHASE_CLONING, done as u64, epochs);
            going
        },
    )?;
    if !going {
        return Ok(false);
    }
    let line = format!(
        "behaviour cloning: {} of {} oracle episodes succeeded, {} steps ({} of them anchor states), {} epochs, loss {loss:.4}, {:.0} s",
        all.successes,
        all.episodes,
        all.demos.len(),
        all.anchors,
        imitation.epochs,
        started.elapsed().as_secs_f64()
    );
    Ok(note(&line))
}
