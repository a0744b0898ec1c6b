//! The events `arrive, aor, gor, fail, succ` and the per-objective success tests (paper,
//! sections IV-A and V-B-2).

use crate::benchmark::{Objective, Task};
use crate::config::{SETTLE_ANGLE, SETTLE_DISTANCE, SimConfig};

/// What the judge looks at after a control step.
#[derive(Clone, Debug, Default)]
pub struct Snapshot {
    /// Grasp point minus grasp location, per axis (m).
    pub arrive_error: [f32; 3],
    /// Angle between the hand's orientation and the task's (rad).
    pub arrive_angle: f32,
    /// Object displacement from its start (m).
    pub displacement: [f32; 3],
    /// Object linear speed (m/s).
    pub speed: f32,
    /// Angle between the object's up axis and the world's (rad).
    pub tilt: f32,
    pub contacts: usize,
    /// Summed normal force from the hand (N).
    pub grip: f32,
    /// Torque of the hand's contacts about the object's twist axis (N m).
    pub twist_torque: f32,
    /// Hand force on the object along the press direction, straight down (N).
    pub press_force: f32,
    /// The object's position (m) and orientation (quaternion `x, y, z, w`) in the palm's frame.
    pub in_palm: ([f32; 3], [f32; 4]),
}

/// Tracks timers across control steps and decides which events hold.
#[derive(Clone, Debug)]
pub struct Judge {
    objective: Objective,
    required: f32,
    force_limit: f32,
    anchored: bool,
    control_dt: f32,
    hold_s: f32,
    /// [`SimConfig::settle_s`]: 0 is off.
    settle_s: f32,
    sustain_s: f32,
    lift_height: f32,
    drop_height: f32,
    arrive_tolerance: f32,
    arrive_angle: f32,
    workspace_radius: f32,
    grasp_timeout_s: f32,
    crush_steps: usize,
    in_grasp: bool,
    /// Whether the success test may pass ([`Judge::set_graded`]).
    graded: bool,
    grasp_steps: usize,
    held_steps: usize,
    /// Steps clear of the table with the object at rest in the palm since `settle_from`.
    settled_steps: usize,
    settle_from: Option<([f32; 3], [f32; 4])>,
    sustained_steps: usize,
    over_limit_steps: usize,
    lifted_once: bool,
    progress: f32,
    reach_cause: Option<ReachCause>,
}

/// Why a `fail` fired (for logs and the oracle's report).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FailCause {
    Timeout,
    Dropped,
    Crushed,
}

impl FailCause {
    /// The cause's name in reports (`failure (dropped)`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Timeout => "timeout",
            Self::Dropped => "dropped",
            Self::Crushed => "crushed",
        }
    }
}

/// Why the object left the workspace (`aor` or `gor`), for reports. Labels only: the events,
/// the machine's transitions and their rewards do not depend on the cause.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReachCause {
    /// Moved more than the workspace radius across the table.
    PushedAway,
    /// More than 5 cm below its start: off the table.
    OffTable,
    /// Tipped past 60 degrees with no hand contact, never lifted.
    TippedOver,
    /// Tipped past 60 degrees with no hand contact after it had been lifted: it turned out of
    /// the hand during the arm's lift or hold and is on its way down (a drop the drop test
    /// has not seen yet).
    TippedInAir,
}

impl ReachCause {
    /// The cause's name in reports (`out_of_reach (tipped in the air)`).
    pub fn name(self) -> &'static str {
        match self {
            Self::PushedAway => "pushed away",
            Self::OffTable => "off the table",
            Self::TippedOver => "tipped over",
            Self::TippedInAir => "tipped in the air",
        }
    }
}

/// How an episode ended, as reports count it: the terminal stage (or `truncated`), a failure
/// with its cause (`failure (dropped)`), an object out of reach with its cause
/// (`out_of_reach (pushed away)`).
pub fn outcome_label(end: &str, fail: Option<FailCause>, reach: Option<ReachCause>) -> String {
    match (end, fail, reach) {
        ("failure", Some(cause), _) => format!("{end} ({})", cause.name()),
        ("out_of_reach", _, Some(cause)) => format!("{end} ({})", cause.name()),
        _ => end.to_string(),
    }
}

/// Whether two poses in the palm's frame are within [`SETTLE_DISTANCE`] and [`SETTLE_ANGLE`]
/// of each other.
fn at_rest(a: ([f32; 3], [f32; 4]), b: ([f32; 3], [f32; 4])) -> bool {
    let distance =
        a.0.iter()
            .zip(&b.0)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f32>()
            .sqrt();
    let dot = a.1.iter().zip(&b.1).map(|(x, y)| x * y).sum::<f32>().abs();
    let angle = 2.0 * dot.min(1.0).acos();
    distance <= SETTLE_DISTANCE && angle <= SETTLE_ANGLE
}

impl Judge {
    pub fn new(task: &Task, force_limit: f32, anchored: bool, config: &SimConfig) -> Self {
        Self {
            objective: task.objective,
            required: task.required.unwrap_or(0.0),
            force_limit,
            anchored,
            control_dt: config.control_dt(),
            hold_s: config.hold_s,
            settle_s: config.settle_s,
            sustain_s: config.sustain_s,
            lift_height: config.lift_height,
            drop_height: config.drop_height,
            arrive_tolerance: config.arrive_tolerance,
            arrive_angle: config.arrive_angle,
            workspace_radius: config.workspace_radius,
            grasp_timeout_s: config.grasp_timeout_s,
            crush_steps: config.crush_steps,
            in_grasp: false,
            graded: true,
            grasp_steps: 0,
            held_steps: 0,
            settled_steps: 0,
            settle_from: None,
            sustained_steps: 0,
            over_limit_steps: 0,
            lifted_once: false,
            progress: 0.0,
            reach_cause: None,
        }
    }

    /// The machine entered a stage; grasp-stage timers (time-out, drop, crush, success) run
    /// in every stage but `approach`, so a flat machine's single stage has them too.
    pub fn set_stage(&mut self, stage: &str) {
        self.in_grasp = stage != "approach";
    }

    /// Whether this step's success test may pass (the default). Under the scripted protocol
    /// the environment grades only the arm's execution: the paper's policy approaches and
    /// closes the hand and the arm performs the objective, so what the policy does to the
    /// object before its grasp is ready (a twist forced by pushing the palm, a lift of its
    /// own) is not the objective done, and the hold and sustain timers start with the arm.
    /// Failures are judged either way.
    pub fn set_graded(&mut self, graded: bool) {
        self.graded = graded;
    }

    /// Why the object first left the workspace in this episode, if it did.
    pub fn reach_cause(&self) -> Option<ReachCause> {
        self.reach_cause
    }

    /// Progress of the success test in `[0, 1]`.
    pub fn progress(&self) -> f32 {
        self.progress
    }

    fn seconds(&self, steps: usize) -> f32 {
        steps as f32 * self.control_dt
    }

    /// Counts the steps, clear of the table in a steady grasp (`clear`), in which the object
    /// has stayed where it was in the palm's frame when the count began (within
    /// [`SETTLE_DISTANCE`] and [`SETTLE_ANGLE`]); a step that moved it, or one that is not
    /// clear, starts the count again. Returns the count.
    fn settle(&mut self, clear: bool, in_palm: ([f32; 3], [f32; 4])) -> usize {
        if !clear || self.settle_s <= 0.0 {
            self.settle_from = None;
            self.settled_steps = 0;
            return 0;
        }
        match self.settle_from {
            Some(from) if at_rest(from, in_palm) => self.settled_steps += 1,
            _ => {
                self.settle_from = Some(in_palm);
                self.settled_steps = 0;
            }
        }
        self.settled_steps
    }

    /// The events that hold after this control step and, for `fail`, why.
    pub fn judge(&mut self, s: &Snapshot) -> (Vec<&'static str>, Option<FailCause>) {
        let mut events = Vec::new();
        if s.arrive_error
            .iter()
            .all(|e| e.abs() <= self.arrive_tolerance)
            && s.arrive_angle <= self.arrive_angle
        {
            events.push("arrive");
        }
        let horizontal = (s.displacement[0].powi(2) + s.displacement[1].powi(2)).sqrt();
        let knocked_over = !self.anchored && s.contacts == 0 && s.tilt > 60f32.to_radians();
        let reach_cause = if horizontal > self.workspace_radius {
            Some(ReachCause::PushedAway)
        } else if s.displacement[2] < -0.05 {
            Some(ReachCause::OffTable)
        } else if knocked_over && self.lifted_once {
            Some(ReachCause::TippedInAir)
        } else if knocked_over {
            Some(ReachCause::TippedOver)
        } else {
            None
        };
        if let Some(cause) = reach_cause {
            // The object left the workspace; the machine takes `aor` from approach, `gor` from grasp.
            self.reach_cause.get_or_insert(cause);
            events.push("aor");
            events.push("gor");
        }

        if s.grip > self.force_limit {
            self.over_limit_steps += 1;
        } else {
            self.over_limit_steps = 0;
        }
        let lifted = s.displacement[2] >= self.lift_height;
        self.lifted_once |= lifted;

        let passed = if self.objective.is_hold() {
            let steady = self.graded && lifted && s.contacts >= 2 && s.speed < 0.3;
            self.held_steps = if steady { self.held_steps + 1 } else { 0 };
            let lift_part = (s.displacement[2] / self.lift_height).clamp(0.0, 1.0);
            let hold_part = (self.seconds(self.held_steps) / self.hold_s).clamp(0.0, 1.0);
            self.progress = 0.5 * lift_part + 0.5 * hold_part;
            // The shortcut's rest counts from when the object is clear of the table (above
            // the drop test's height) in a steady grasp, so it can run during the lift; it
            // passes only once the object is lifted as well.
            let clear = self.graded
                && s.displacement[2] >= self.drop_height
                && s.contacts >= 2
                && s.speed < 0.3;
            let settled = self.settle(clear, s.in_palm);
            self.seconds(self.held_steps) >= self.hold_s - 1e-6
                || (steady && self.settle_s > 0.0 && self.seconds(settled) >= self.settle_s - 1e-6)
        } else {
            let measure = match self.objective {
                Objective::Twist => s.twist_torque * self.required.signum(),
                _ => s.press_force,
            };
            let target = self.required.abs();
            self.sustained_steps = if self.graded && measure >= target {
                self.sustained_steps + 1
            } else {
                0
            };
            self.progress = (measure / target).clamp(0.0, 1.0);
            self.seconds(self.sustained_steps) >= self.sustain_s - 1e-6
        };
        let done = self.graded && passed;

        let mut cause = None;
        if self.in_grasp {
            self.grasp_steps += 1;
            if self.over_limit_steps >= self.crush_steps {
                cause = Some(FailCause::Crushed);
            } else if self.lifted_once && s.displacement[2] < self.drop_height && s.contacts == 0 {
                cause = Some(FailCause::Dropped);
            } else if self.seconds(self.grasp_steps) > self.grasp_timeout_s + 1e-4 {
                cause = Some(FailCause::Timeout);
            }
            // A crushed object fails even if the test passed in the same step.
            if done && cause != Some(FailCause::Crushed) {
                events.push("succ");
            }
            if cause.is_some() {
                events.push("fail");
            }
        }
        (events, cause)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::benchmark::{GraspLocation, Topology};

    fn task(objective: Objective, required: Option<f32>) -> Task {
        Task {
            id: "t".into(),
            object: "o".into(),
            objective,
            topology: Topology::PoPmAb25,
            grasp: GraspLocation {
                offset: [0.0; 3],
                yaw: 0.0,
                orientation: None,
            },
            motion: [0.0, 0.0, 1.0],
            start: None,
            required,
        }
    }

    fn grasping_judge(objective: Objective, required: Option<f32>) -> (Judge, SimConfig) {
        let config = SimConfig::deterministic();
        let mut judge = Judge::new(&task(objective, required), 20.0, false, &config);
        judge.set_stage("grasp");
        (judge, config)
    }

    fn held() -> Snapshot {
        Snapshot {
            displacement: [0.0, 0.0, 0.08],
            contacts: 6,
            grip: 10.0,
            ..Snapshot::default()
        }
    }

    #[test]
    fn outcomes_name_the_cause_of_a_failure_and_of_an_object_out_of_reach() {
        assert_eq!(
            outcome_label("failure", Some(FailCause::Dropped), None),
            "failure (dropped)"
        );
        assert_eq!(outcome_label("failure", None, None), "failure");
        assert_eq!(
            outcome_label("out_of_reach", None, Some(ReachCause::PushedAway)),
            "out_of_reach (pushed away)"
        );
        assert_eq!(outcome_label("out_of_reach", None, None), "out_of_reach");
        // A cause left from an earlier step does not relabel another ending.
        assert_eq!(
            outcome_label("success", Some(FailCause::Crushed), None),
            "success"
        );
        assert_eq!(
            outcome_label("truncated", Some(FailCause::Timeout), None),
            "truncated"
        );
        assert_eq!(
            outcome_label(
                "failure",
                Some(FailCause::Dropped),
                Some(ReachCause::TippedOver)
            ),
            "failure (dropped)"
        );
    }

    #[test]
    fn an_object_out_of_reach_is_told_pushed_off_tipped_or_tipped_in_the_air() {
        let tipped = Snapshot {
            tilt: 1.5,
            displacement: [0.0, 0.0, 0.03],
            ..Snapshot::default()
        };
        let cases = [
            (
                false,
                Snapshot {
                    displacement: [0.2, 0.0, 0.0],
                    ..Snapshot::default()
                },
                ReachCause::PushedAway,
            ),
            (
                false,
                Snapshot {
                    displacement: [0.0, 0.0, -0.1],
                    ..Snapshot::default()
                },
                ReachCause::OffTable,
            ),
            (false, tipped.clone(), ReachCause::TippedOver),
            // Lifted, then turned out of the hand: still in the air, no contact.
            (true, tipped, ReachCause::TippedInAir),
        ];
        for (lift_first, snapshot, cause) in cases {
            let (mut judge, _) = grasping_judge(Objective::Lift, None);
            assert_eq!(judge.reach_cause(), None);
            if lift_first {
                judge.judge(&held());
            }
            let (events, _) = judge.judge(&snapshot);
            assert!(events.contains(&"gor"), "{cause:?}");
            assert_eq!(judge.reach_cause(), Some(cause));
            // The first cause stays.
            judge.judge(&Snapshot {
                displacement: [0.3, 0.0, 0.0],
                ..Snapshot::default()
            });
            assert_eq!(judge.reach_cause(), Some(cause));
        }
        // A tipped object the hand still touches is not out of reach.
        let (mut judge, _) = grasping_judge(Objective::Lift, None);
        let touched = Snapshot {
            tilt: 1.5,
            contacts: 2,
            ..Snapshot::default()
        };
        assert!(!judge.judge(&touched).0.contains(&"gor"));
        assert_eq!(judge.reach_cause(), None);
    }

    #[test]
    fn a_lift_succeeds_after_five_seconds_of_steady_hold_and_not_before() {
        let (mut judge, config) = grasping_judge(Objective::Lift, None);
        let steps = (config.hold_s / config.control_dt()).round() as usize;
        for _ in 0..steps - 1 {
            let (events, _) = judge.judge(&held());
            assert!(!events.contains(&"succ"));
        }
        let (events, _) = judge.judge(&held());
        assert!(events.contains(&"succ"));
    }

    #[test]
    fn a_shaking_or_lowered_object_restarts_the_hold_timer() {
        let (mut judge, config) = grasping_judge(Objective::HandleGrasp, None);
        let steps = (config.hold_s / config.control_dt()).round() as usize;
        for _ in 0..steps / 2 {
            judge.judge(&held());
        }
        judge.judge(&Snapshot {
            speed: 1.0,
            ..held()
        });
        for _ in 0..steps - 1 {
            let (events, _) = judge.judge(&held());
            assert!(!events.contains(&"succ"));
        }
        assert!(judge.judge(&held()).0.contains(&"succ"));
    }

    #[test]
    fn with_settle_s_an_object_at_rest_in_the_palm_passes_early_and_a_creeping_one_does_not() {
        let config = SimConfig {
            settle_s: 0.5,
            ..SimConfig::deterministic()
        };
        let judge = || {
            let mut judge = Judge::new(&task(Objective::Lift, None), 20.0, false, &config);
            judge.set_stage("grasp");
            judge
        };
        let at = |x: f32| Snapshot {
            in_palm: ([x, 0.02, 0.05], [0.0, 0.0, 0.0, 1.0]),
            ..held()
        };
        let settle = (config.settle_s / config.control_dt()).round() as usize;
        let hold = (config.hold_s / config.control_dt()).round() as usize;
        // At rest: the first steady step sets the reference, `settle` more pass.
        let mut resting = judge();
        for step in 0..settle {
            assert!(!resting.judge(&at(0.0)).0.contains(&"succ"), "step {step}");
        }
        assert!(resting.judge(&at(0.0)).0.contains(&"succ"));
        // The rest counts from when the object clears the table (the drop test's height),
        // during the arm's lift; it passes at the first lifted step after.
        let mut rising = judge();
        let rise = |z: f32| Snapshot {
            displacement: [0.0, 0.0, z],
            ..at(0.0)
        };
        for step in 0..=settle {
            let z = config.drop_height + 1e-3;
            assert!(!rising.judge(&rise(z)).0.contains(&"succ"), "step {step}");
        }
        assert!(rising.judge(&rise(config.lift_height)).0.contains(&"succ"));
        // Under the drop test's height it does not count.
        let mut low = judge();
        for _ in 0..=settle {
            low.judge(&rise(config.drop_height - 1e-3));
        }
        assert!(!low.judge(&rise(config.lift_height)).0.contains(&"succ"));
        // Creeping 0.4 mm a step, 2 mm in five: the count starts again, the full hold decides.
        let mut creeping = judge();
        for step in 0..hold - 1 {
            let x = 4e-4 * step as f32;
            assert!(!creeping.judge(&at(x)).0.contains(&"succ"), "step {step}");
        }
        assert!(creeping.judge(&at(4e-4 * hold as f32)).0.contains(&"succ"));
        // Off (the default): only the full hold passes.
        let (mut full, _) = grasping_judge(Objective::Lift, None);
        for _ in 0..hold - 1 {
            assert!(!full.judge(&at(0.0)).0.contains(&"succ"));
        }
        assert!(full.judge(&at(0.0)).0.contains(&"succ"));
    }

    #[test]
    fn twist_needs_the_torque_in_the_task_direction_for_the_sustain_time() {
        let (mut judge, config) = grasping_judge(Objective::Twist, Some(-0.2));
        let steps = (config.sustain_s / config.control_dt()).ceil() as usize;
        let wrong_way = Snapshot {
            twist_torque: 0.5,
            contacts: 2,
            ..Snapshot::default()
        };
        for _ in 0..3 * steps {
            assert!(!judge.judge(&wrong_way).0.contains(&"succ"));
        }
        let right_way = Snapshot {
            twist_torque: -0.25,
            contacts: 2,
            ..Snapshot::default()
        };
        let fired = succ_per_step(&mut judge, &right_way, steps);
        assert!(only_the_last(&fired), "{fired:?}");
    }

    /// Judges `s` for `steps` control steps; whether `succ` fired in each.
    fn succ_per_step(judge: &mut Judge, s: &Snapshot, steps: usize) -> Vec<bool> {
        (0..steps)
            .map(|_| judge.judge(s).0.contains(&"succ"))
            .collect()
    }

    /// Whether `succ` fired in the last step and in none before it.
    fn only_the_last(fired: &[bool]) -> bool {
        fired
            .split_last()
            .is_some_and(|(last, before)| *last && before.iter().all(|f| !f))
    }

    #[test]
    fn an_ungraded_step_passes_no_test_and_the_timers_start_with_grading() {
        for (objective, required, passing) in [
            (
                Objective::Twist,
                Some(-0.2),
                Snapshot {
                    twist_torque: -0.25,
                    contacts: 2,
                    ..Snapshot::default()
                },
            ),
            (Objective::Lift, None, held()),
        ] {
            let (mut judge, config) = grasping_judge(objective, required);
            // Counted as the tests above count a hold and a sustain.
            let steps = if objective.is_hold() {
                (config.hold_s / config.control_dt()).round() as usize
            } else {
                (config.sustain_s / config.control_dt()).ceil() as usize
            };
            judge.set_graded(false);
            for _ in 0..3 * steps {
                assert!(!judge.judge(&passing).0.contains(&"succ"), "{objective:?}");
            }
            judge.set_graded(true);
            let fired = succ_per_step(&mut judge, &passing, steps);
            assert!(only_the_last(&fired), "{objective:?}: {fired:?}");
        }
        // Failures are judged whether or not the step is graded.
        let (mut judge, config) = grasping_judge(Objective::Lift, None);
        judge.set_graded(false);
        let crush = Snapshot {
            grip: 25.0,
            ..held()
        };
        let failed = (0..config.crush_steps).any(|_| judge.judge(&crush).0.contains(&"fail"));
        assert!(failed);
    }

    #[test]
    fn press_needs_the_force_along_the_press_direction() {
        let (mut judge, config) = grasping_judge(Objective::Press, Some(6.0));
        let steps = (config.sustain_s / config.control_dt()).ceil() as usize;
        let weak = Snapshot {
            press_force: 5.0,
            contacts: 3,
            grip: 5.0,
            ..Snapshot::default()
        };
        for _ in 0..3 * steps {
            assert!(!judge.judge(&weak).0.contains(&"succ"));
        }
        let firm = Snapshot {
            press_force: 7.0,
            contacts: 3,
            grip: 7.0,
            ..Snapshot::default()
        };
        let succeeded = (0..steps).any(|_| judge.judge(&firm).0.contains(&"succ"));
        assert!(succeeded);
        assert!((judge.progress() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn squeezing_above_the_fragility_limit_fails_the_grasp() {
        let (mut judge, config) = grasping_judge(Objective::Lift, None);
        let crush = Snapshot {
            grip: 25.0,
            ..held()
        };
        for _ in 0..config.crush_steps - 1 {
            assert!(!judge.judge(&crush).0.contains(&"fail"));
        }
        let (events, cause) = judge.judge(&crush);
        assert!(events.contains(&"fail") && !events.contains(&"succ"));
        assert_eq!(cause, Some(FailCause::Crushed));
    }

    #[test]
    fn dropping_a_lifted_object_fails_and_a_grasp_times_out() {
        let (mut judge, _) = grasping_judge(Objective::Lift, None);
        judge.judge(&held());
        let (events, cause) = judge.judge(&Snapshot::default());
        assert!(events.contains(&"fail"));
        assert_eq!(cause, Some(FailCause::Dropped));

        let (mut judge, config) = grasping_judge(Objective::Pull, None);
        let limit = (config.grasp_timeout_s / config.control_dt()).round() as usize;
        let idle = Snapshot {
            contacts: 1,
            ..Snapshot::default()
        };
        for _ in 0..limit {
            assert!(!judge.judge(&idle).0.contains(&"fail"));
        }
        assert_eq!(judge.judge(&idle).1, Some(FailCause::Timeout));
    }

    #[test]
    fn grasp_stage_events_do_not_fire_in_approach_but_arrive_and_out_of_reach_do() {
        let config = SimConfig::deterministic();
        let mut judge = Judge::new(&task(Objective::Lift, None), 20.0, false, &config);
        judge.set_stage("approach");
        let (events, _) = judge.judge(&Snapshot {
            grip: 100.0,
            ..held()
        });
        assert!(events.contains(&"arrive"));
        assert!(!events.contains(&"fail") && !events.contains(&"succ"));
        let (events, _) = judge.judge(&Snapshot {
            displacement: [0.2, 0.0, 0.0],
            arrive_error: [0.1; 3],
            ..Snapshot::default()
        });
        assert_eq!(events, vec!["aor", "gor"]);
    }

    #[test]
    fn a_hand_turned_away_from_the_tasks_orientation_has_not_arrived() {
        let config = SimConfig::deterministic();
        let mut judge = Judge::new(&task(Objective::Lift, None), 20.0, false, &config);
        judge.set_stage("approach");
        let at = |angle: f32| Snapshot {
            arrive_angle: angle,
            ..Snapshot::default()
        };
        assert!(
            judge
                .judge(&at(0.5 * config.arrive_angle))
                .0
                .contains(&"arrive")
        );
        assert!(
            !judge
                .judge(&at(2.0 * config.arrive_angle))
                .0
                .contains(&"arrive")
        );
    }
}
