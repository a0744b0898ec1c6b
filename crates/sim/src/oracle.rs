//! A scripted grasping controller with privileged state (no learning): it proves the physics
//! can grasp. It moves to the task's grasp location along the hand's approach axis (from
//! above for a palm that faces down), closes to the topology's shape while regulating the
//! grip under the object's force limit, then performs the objective with the arm's
//! controllers of `env/script.rs`. An oracle given a palm shift ([`Oracle::with_shift`]) first
//! moves the palm that far from the grasp location in the grasp stage, for a task whose
//! grasp holds only off the point it arrives at (docs/WORLDS.md, "The handle bottle of
//! `t07`"). Under the paper's protocol the
//! environment runs those controllers itself once the grasp is ready, inside the step that
//! made it ready.

use rapier3d::math::Vec3;

use crate::benchmark::Objective;
use crate::env::GraspEnv;
use crate::env::script::GRASP_SCALE;
use crate::observation::ACTIONS;

/// Approach step scale of the grasping spec (m per unit action).
const APPROACH_SCALE: f32 = 0.01;
/// Distance (m) back from the grasp location, against the hand's approach axis, at which the
/// hand travels until it is lined up (above it, for a palm that faces down); more for a hand
/// that reaches further ahead of its grasp point (2 cm beyond its reach).
const CLEARANCE: f32 = 0.06;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Align,
    Close,
    Act,
}

/// The oracle's per-episode state.
#[derive(Clone, Debug)]
pub struct Oracle {
    phase: Phase,
    phase_steps: usize,
    settled: usize,
    /// Whether the hand has lined up with the grasp location in the approach (it then goes
    /// straight in, and does not back off again).
    lined_up: bool,
    /// Where the palm goes in the grasp stage before closing, from the grasp location (m,
    /// world frame).
    shift: Vec3,
}

/// Largest palm shift an oracle takes (m per axis), as the job API bounds it
/// (`crm_api::imitation::MAX_SHIFT`): a shift corrects a grasp location by a few centimetres
/// (`t07`'s is 6 cm in all), not a new grasp.
pub const MAX_SHIFT: f32 = 0.1;

impl Default for Oracle {
    fn default() -> Self {
        Self::new()
    }
}

fn unit(value: f32, scale: f32) -> f32 {
    (value / scale).clamp(-1.0, 1.0)
}

impl Oracle {
    pub fn new() -> Self {
        Self {
            phase: Phase::Align,
            phase_steps: 0,
            settled: 0,
            lined_up: false,
            shift: Vec3::ZERO,
        }
    }

    /// An oracle that moves the palm by `shift` (m, world frame, each axis within
    /// [`MAX_SHIFT`]) from the grasp location once it has arrived, before it closes.
    pub fn with_shift(shift: [f32; 3]) -> Self {
        Self {
            shift: Vec3::from(shift).clamp(Vec3::splat(-MAX_SHIFT), Vec3::splat(MAX_SHIFT)),
            ..Self::new()
        }
    }

    fn enter(&mut self, phase: Phase) {
        self.phase = phase;
        self.phase_steps = 0;
        self.settled = 0;
    }

    /// The next action in the union space, in the spec's units (`[-1, 1]` before scaling).
    pub fn act(&mut self, env: &GraspEnv, stage: &str) -> Vec<f32> {
        let mut action = vec![0.0; ACTIONS.len()];
        let parts = env.observation_parts();
        let rel = parts.relative;
        if stage == "approach" {
            let rel = Vec3::from(rel);
            let along = env.approach_direction();
            let lateral = rel - rel.dot(along) * along;
            let reach = env.scene().map_or(0.0, |s| s.hand.reach);
            let clearance = CLEARANCE.max(reach + 0.02);
            self.lined_up |= lateral.length() <= 0.01;
            let goal = if !self.lined_up {
                rel - clearance * along
            } else {
                rel
            };
            action[0] = unit(goal.x, APPROACH_SCALE);
            action[1] = unit(goal.y, APPROACH_SCALE);
            action[2] = unit(goal.z, APPROACH_SCALE);
            return action;
        }
        if stage != "grasp" {
            return action;
        }
        self.phase_steps += 1;
        let task = env.task();
        let object = env.benchmark().object_of(task);
        let shape = env.hand_shape();
        let limit = object.fragility.grasp_force_limit();
        let grip = parts.grip * limit;
        let wanted_grip = crate::env::script::wanted_grip(env);
        match self.phase {
            Phase::Align => {
                // `rel` is the grasp location minus the palm: the palm heads for the grasp
                // location plus the shift, at most one grasp step per axis and control step.
                let goal = Vec3::from(rel) + self.shift;
                action[0] = unit(goal.x, GRASP_SCALE);
                action[1] = unit(goal.y, GRASP_SCALE);
                action[2] = unit(goal.z, GRASP_SCALE);
                let close_enough = goal.abs().max_element() < 0.003;
                // Ten steps to settle, and the steps a shift takes at full speed.
                let allowed = 10 + (self.shift.abs().max_element() / GRASP_SCALE).ceil() as usize;
                if close_enough || self.phase_steps > allowed {
                    self.enter(if task.objective == Objective::Press {
                        Phase::Act
                    } else {
                        Phase::Close
                    });
                }
            }
            Phase::Close => {
                let mut all_closed = true;
                for finger in 0..5 {
                    if !shape[finger].active {
                        continue;
                    }
                    if parts.commands[finger] < shape[finger].closed - 1e-3 {
                        all_closed = false;
                    }
                    // Close fast until the first touch, then slowly so the grip does not
                    // overshoot.
                    action[3 + finger] = if grip >= wanted_grip {
                        0.0
                    } else if parts.n_c == 0 {
                        1.0
                    } else {
                        0.3
                    };
                }
                if grip >= wanted_grip || all_closed {
                    self.settled += 1;
                } else {
                    self.settled = 0;
                }
                if self.settled >= 4 || self.phase_steps > 40 {
                    self.enter(Phase::Act);
                }
            }
            Phase::Act => return crate::env::script::objective_action(env, wanted_grip),
        }
        action
    }
}

/// Result of one oracle episode.
#[derive(Clone, Debug, PartialEq)]
pub struct OracleEpisode {
    pub task: usize,
    pub seed: u64,
    pub success: bool,
    /// Control steps of the controller until the episode ended (under the scripted protocol
    /// the arm's execution runs inside one of them).
    pub steps: usize,
    /// Simulated seconds of the episode, the arm's scripted execution included.
    pub sim_seconds: f32,
    /// The terminal stage reached, or `truncated`.
    pub outcome: String,
    /// How the episode ended as reports count it, with the cause of a failure or of an object
    /// out of reach (`failure (dropped)`, `out_of_reach (pushed away)`; see
    /// [`crate::events::outcome_label`]).
    pub label: String,
}

/// Runs one oracle episode of `task` with `seed` through the grasping machine.
pub fn run_episode(
    env: GraspEnv,
    machine: crm::Machine,
    task: usize,
    seed: u64,
) -> crate::Result<(OracleEpisode, GraspEnv)> {
    run_shifted_episode(env, machine, task, seed, [0.0; 3])
}

/// [`run_episode`] with the palm shifted by `shift` before the grasp ([`Oracle::with_shift`]).
pub fn run_shifted_episode(
    env: GraspEnv,
    machine: crm::Machine,
    task: usize,
    seed: u64,
    shift: [f32; 3],
) -> crate::Result<(OracleEpisode, GraspEnv)> {
    let mut env = env;
    env.set_task_choice(crate::TaskChoice::Fixed(task))?;
    let mut crm_env = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
    let (mut stage, _) = crm_env.reset(seed)?;
    let mut oracle = Oracle::with_shift(shift);
    let mut steps = 0;
    let outcome = loop {
        let name = crm_env.machine().stage_name(stage).to_string();
        let action = oracle.act(crm_env.env(), &name);
        let step = crm_env.step(&action)?;
        steps += 1;
        stage = step.stage;
        if step.done {
            break crm_env.machine().stage_name(stage).to_string();
        }
        if step.truncated {
            break "truncated".to_string();
        }
    };
    let episode = OracleEpisode {
        task,
        seed,
        success: outcome == "success",
        steps,
        sim_seconds: crm_env.env().sim_seconds(),
        label: crm_env.env().outcome_label(&outcome),
        outcome,
    };
    let (_, env) = crm_env.into_parts();
    Ok((episode, env))
}
