//! A scripted grasping controller with privileged state (no learning): it proves the physics
//! can grasp. It moves to the task's grasp location from above, closes to the topology's
//! shape while regulating the grip under the object's force limit, then performs the
//! objective: lift (or lift along the task's motion), twist along the tangent, or press down.

use crate::benchmark::Objective;
use crate::env::GraspEnv;
use crate::observation::ACTIONS;

/// Approach and grasp step scales of the grasping spec (m per unit action, rad per unit).
const APPROACH_SCALE: f32 = 0.01;
const GRASP_SCALE: f32 = 0.003;
/// Height (m) above the grasp location at which the hand travels before descending.
const CLEARANCE: f32 = 0.06;
/// Fraction of the grasp step used to move a held object (slower swings less).
const LIFT_SPEED: f32 = 0.6;
/// Height (m) above the success test's lift height to which a held object is raised.
const LIFT_MARGIN: f32 = 0.02;

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
}

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
            let horizontal = (rel[0] * rel[0] + rel[1] * rel[1]).sqrt();
            let z_goal = if horizontal > 0.01 {
                rel[2] + CLEARANCE
            } else {
                rel[2]
            };
            action[0] = unit(rel[0], APPROACH_SCALE);
            action[1] = unit(rel[1], APPROACH_SCALE);
            action[2] = unit(z_goal, APPROACH_SCALE);
            return action;
        }
        if stage != "grasp" {
            return action;
        }
        self.phase_steps += 1;
        let task = env.task();
        let object = env.benchmark().object_of(task);
        let shape = task.topology.shape();
        let limit = object.fragility.grasp_force_limit();
        let grip = parts.grip * limit;
        let friction = 0.5 * (1.0 + object.friction);
        let weight = object.mass * 9.81;
        let wanted_grip = (3.0 * weight / friction).clamp(6.0, 0.55 * limit);
        match self.phase {
            Phase::Align => {
                action[0] = unit(rel[0], GRASP_SCALE);
                action[1] = unit(rel[1], GRASP_SCALE);
                action[2] = unit(rel[2], GRASP_SCALE);
                let close_enough = rel.iter().all(|r| r.abs() < 0.003);
                if close_enough || self.phase_steps > 10 {
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
            Phase::Act => {
                // Keep the grip between the wanted value and the fragility limit.
                for finger in 0..5 {
                    if shape[finger].active && task.objective != Objective::Press {
                        action[3 + finger] = if grip > 0.8 * limit {
                            -0.3
                        } else if grip < 0.8 * wanted_grip {
                            0.3
                        } else {
                            0.0
                        };
                    }
                }
                let start_yaw = env
                    .scene()
                    .map(|s| s.object_start.rotation)
                    .unwrap_or_default();
                let motion =
                    start_yaw * rapier3d::prelude::Vec3::from(task.motion).normalize_or_zero();
                match task.objective {
                    Objective::Press => {
                        let required = task.required.unwrap_or(0.0).abs();
                        let press = -parts.force[2];
                        let dz = if press > 0.7 * limit {
                            0.5
                        } else if press < 1.3 * required {
                            -0.5
                        } else {
                            0.0
                        };
                        action[2] = dz;
                    }
                    Objective::Twist => {
                        for axis in 0..3 {
                            action[axis] = 0.5 * motion[axis];
                        }
                    }
                    _ => {
                        // Lift (along the task's motion) until the object stands clear of the
                        // success height: a rule on an observed quantity (the object's
                        // displacement), not on a step count, so a policy cloned from the
                        // oracle can tell from its observation when to stop.
                        if parts.object[2] < env.config().lift_height + LIFT_MARGIN {
                            for axis in 0..3 {
                                action[axis] = LIFT_SPEED * motion[axis];
                            }
                        }
                    }
                }
            }
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
    /// Control steps until the episode ended.
    pub steps: usize,
    /// The terminal stage reached, or `truncated`.
    pub outcome: String,
    /// Why the grasp failed, when it did.
    pub fail_cause: Option<crate::events::FailCause>,
}

/// Runs one oracle episode of `task` with `seed` through the grasping machine.
pub fn run_episode(
    env: GraspEnv,
    machine: crm::Machine,
    task: usize,
    seed: u64,
) -> crate::Result<(OracleEpisode, GraspEnv)> {
    let mut env = env;
    env.set_task_choice(crate::TaskChoice::Fixed(task))?;
    let mut crm_env = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
    let (mut stage, _) = crm_env.reset(seed)?;
    let mut oracle = Oracle::new();
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
        fail_cause: if outcome == "failure" {
            crm_env.env().last_fail()
        } else {
            None
        },
        outcome,
    };
    let (_, env) = crm_env.into_parts();
    Ok((episode, env))
}
