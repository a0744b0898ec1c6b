//! `crm_grasp._native`: the grasping world for Python. `NativeBatch` holds N environments
//! (`batch.rs`) and steps them on Rust threads with the GIL released; arrays cross through
//! the buffer protocol (the caller's numpy arrays are read and filled in place), so the
//! extension needs no crate beyond pyo3. The Gymnasium classes are Python
//! (`crm_grasp/env.py`): this module only moves numbers.

mod batch;

use std::sync::{Mutex, MutexGuard};

use batch::{Batch, Options, Start, Step};
use crm::RewardMode;
use grasp_sim::Protocol;
use grasp_sim::observation::{ACTIONS, FEATURES};
use pyo3::buffer::PyBuffer;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

/// N environments of the built-in world (`crm_grasp.CrmGraspEnv` and `CrmGraspVectorEnv`
/// wrap it; see their docs for the arguments).
#[pyclass(module = "crm_grasp._native")]
struct NativeBatch {
    batch: Mutex<Batch>,
}

/// What a reset returns besides the observation: the stage's index and the task id.
type StartInfo = (usize, String);

/// One environment's step besides the observation: stage index, intra-stage and transition
/// reward, the event that moved the machine, the events that held, terminated, truncated,
/// the outcome label (at an episode's end), the task, and the next episode's start when the
/// step autoreset the environment.
type StepInfo = (
    usize,
    f32,
    f32,
    Option<String>,
    Vec<&'static str>,
    bool,
    bool,
    Option<String>,
    String,
    Option<StartInfo>,
);

fn value_error(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// Copies `values` into a writable float32 buffer of exactly that many values.
fn fill(py: Python<'_>, out: &Bound<'_, PyAny>, values: &[f32], what: &str) -> PyResult<()> {
    let buffer = PyBuffer::<f32>::get(out)
        .map_err(|e| value_error(format!("{what}: a float32 array is needed ({e})")))?;
    if buffer.item_count() != values.len() {
        return Err(value_error(format!(
            "{what}: room for {} values, {} given",
            buffer.item_count(),
            values.len()
        )));
    }
    buffer.copy_from_slice(py, values)
}

impl NativeBatch {
    fn lock(&self) -> PyResult<MutexGuard<'_, Batch>> {
        self.batch
            .lock()
            .map_err(|_| PyRuntimeError::new_err("the environment panicked earlier"))
    }
}

#[pymethods]
impl NativeBatch {
    /// `objective`: "scripted" (the paper's protocol: the arm executes the objective once the
    /// grasp is ready) or "learned"; `reward_mode`: "crm", "dense" (intra-stage rewards
    /// only, LPPO) or "sparse" (transition rewards only, IPPO).
    #[new]
    #[pyo3(signature = (num_envs, tasks, objective, randomize, reward_mode, hold_s=None, world=None))]
    fn new(
        num_envs: usize,
        tasks: Vec<String>,
        objective: &str,
        randomize: bool,
        reward_mode: &str,
        hold_s: Option<f64>,
        world: Option<std::path::PathBuf>,
    ) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(value_error("num_envs: at least 1"));
        }
        let protocol = match objective {
            "scripted" => Protocol::Scripted,
            "learned" => Protocol::Learned,
            other => {
                return Err(value_error(format!(
                    "objective: {other:?} is not one of \"scripted\", \"learned\""
                )));
            }
        };
        let reward_mode = match reward_mode {
            "crm" => RewardMode::Crm,
            "dense" => RewardMode::Dense,
            "sparse" => RewardMode::Sparse,
            other => {
                return Err(value_error(format!(
                    "reward_mode: {other:?} is not one of \"crm\", \"dense\", \"sparse\""
                )));
            }
        };
        if let Some(hold) = hold_s
            && !(0.1..=8.0).contains(&hold)
        {
            return Err(value_error(format!(
                "hold_s: {hold} is outside 0.1-8 seconds"
            )));
        }
        let options = Options {
            world,
            tasks,
            protocol,
            randomize,
            reward_mode,
            hold_s,
        };
        let batch = Batch::new(num_envs, &options).map_err(value_error)?;
        Ok(Self {
            batch: Mutex::new(batch),
        })
    }

    fn __len__(&self) -> PyResult<usize> {
        Ok(self.lock()?.len())
    }

    /// The action mask of every stage (`len(STAGES) x 8`, 1 where the stage acts).
    fn action_masks(&self) -> PyResult<Vec<Vec<f32>>> {
        let batch = self.lock()?;
        let machine = batch.machine();
        Ok((0..machine.stage_count())
            .map(|s| machine.action_mask(s))
            .collect())
    }

    /// Resets environment `k` with `seed`, writes its observation into `obs` (38 float32).
    fn reset(
        &self,
        py: Python<'_>,
        k: usize,
        seed: u64,
        obs: &Bound<'_, PyAny>,
    ) -> PyResult<StartInfo> {
        let start = self.lock()?.reset(k, seed).map_err(value_error)?;
        fill(py, obs, &start.observation, "obs")?;
        Ok((start.stage, start.task))
    }

    /// Draws environment `k`'s scene into `out` (uint8, `height x width x 3`, RGB): the
    /// software renderer of `crm record --video`, the GIL released.
    fn render(
        &self,
        py: Python<'_>,
        k: usize,
        width: u32,
        height: u32,
        out: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        if !(16..=4096).contains(&width) || !(16..=4096).contains(&height) {
            return Err(value_error(format!(
                "render size: {width}x{height} (width and height are 16 to 4096 pixels)"
            )));
        }
        let buffer = PyBuffer::<u8>::get(out)
            .map_err(|e| value_error(format!("out: a uint8 array is needed ({e})")))?;
        let guard = self.lock()?;
        let batch: &Batch = &guard;
        let frame = py
            .detach(|| batch.render(k, width, height))
            .map_err(value_error)?;
        drop(guard);
        if buffer.item_count() != frame.rgb.len() {
            return Err(value_error(format!(
                "out: room for {} bytes, {} given",
                buffer.item_count(),
                frame.rgb.len()
            )));
        }
        buffer.copy_from_slice(py, &frame.rgb)
    }

    /// Steps every environment with its row of `actions` (float32, `len x 8`, finite), the
    /// GIL released; writes the observations into `obs` (`len x 38`; the next episode's first
    /// one where a step ended an episode and `autoreset` is on) and, where an episode ended,
    /// its last observation into `final_obs` (zeros elsewhere). A refused action changes
    /// nothing.
    fn step(
        &self,
        py: Python<'_>,
        actions: &Bound<'_, PyAny>,
        obs: &Bound<'_, PyAny>,
        final_obs: &Bound<'_, PyAny>,
        autoreset: bool,
    ) -> PyResult<Vec<StepInfo>> {
        let actions = PyBuffer::<f32>::get(actions)
            .map_err(|e| value_error(format!("action: a float32 array is needed ({e})")))?
            .to_vec(py)?;
        if let Some(bad) = actions.iter().position(|v| !v.is_finite()) {
            return Err(value_error(format!(
                "action: value {bad} is {} (actions must be finite)",
                actions[bad]
            )));
        }
        let mut guard = self.lock()?;
        let batch: &mut Batch = &mut guard;
        let steps = py
            .detach(|| batch.step(&actions, autoreset))
            .map_err(value_error)?;
        drop(guard);
        let width = FEATURES.len();
        let mut next = vec![0.0f32; steps.len() * width];
        let mut last = vec![0.0f32; steps.len() * width];
        for (k, step) in steps.iter().enumerate() {
            let row = k * width..(k + 1) * width;
            let start = step
                .reset
                .as_ref()
                .map_or(&step.observation, |s| &s.observation);
            next[row.clone()].copy_from_slice(start);
            // Rows of episodes still running stay zero.
            if step.terminated || step.truncated {
                last[row].copy_from_slice(&step.observation);
            }
        }
        fill(py, obs, &next, "obs")?;
        fill(py, final_obs, &last, "final_obs")?;
        Ok(steps.into_iter().map(step_info).collect())
    }
}

fn step_info(step: Step) -> StepInfo {
    (
        step.stage,
        step.intra,
        step.transition,
        step.event,
        step.events,
        step.terminated,
        step.truncated,
        step.outcome,
        step.task,
        step.reset.map(|Start { stage, task, .. }| (stage, task)),
    )
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let machine = grasp_sim::spec::grasping_machine();
    let benchmark = grasp_sim::Benchmark::builtin();
    m.add_class::<NativeBatch>()?;
    m.add("FEATURES", FEATURES.to_vec())?;
    m.add("ACTIONS", ACTIONS.to_vec())?;
    m.add(
        "STAGES",
        (0..machine.stage_count())
            .map(|s| machine.stage_name(s).to_string())
            .collect::<Vec<_>>(),
    )?;
    m.add(
        "TASKS",
        benchmark
            .tasks
            .iter()
            .map(|t| t.id.clone())
            .collect::<Vec<_>>(),
    )?;
    m.add("INITIAL_STAGE", machine.initial())?;
    m.add("ENV_VERSION", grasp_sim::ENV_VERSION)?;
    Ok(())
}
