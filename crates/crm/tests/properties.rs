//! Property tests of the machine's contract (paper, section III-A).

mod common;

use common::toy_machine;
use proptest::prelude::*;

fn step_input() -> impl Strategy<Value = (Vec<f32>, Vec<usize>)> {
    (
        prop::collection::vec(-3.0f32..3.0, 3),
        prop::collection::vec(0usize..4, 0..3),
    )
}

proptest! {
    /// The episode return equals the sum of intra-stage rewards plus the rewards of the
    /// edges in the transition history `H`.
    #[test]
    fn return_is_intra_plus_history(inputs in prop::collection::vec(step_input(), 1..60)) {
        let machine = toy_machine();
        let mut episode = crm::Episode::new(&machine);
        let mut intra_sum = 0.0f64;
        let mut per_step_sum = 0.0f64;
        for (observation, fired) in &inputs {
            if machine.is_terminal(episode.stage()) {
                break;
            }
            let outcome = episode.advance(&machine, observation, fired).unwrap();
            intra_sum += f64::from(outcome.intra_reward);
            per_step_sum += f64::from(outcome.intra_reward) + f64::from(outcome.transition_reward);
        }
        let history_sum: f64 = episode.history().iter().map(|t| f64::from(t.reward)).sum();
        prop_assert!((episode.total_return() - (intra_sum + history_sum)).abs() < 1e-6);
        prop_assert!((episode.total_return() - per_step_sum).abs() < 1e-6);
        // Every recorded edge exists in the spec with that reward (plus at most the bonus).
        for t in episode.history() {
            let base = machine.edge_reward(t.from, t.event).unwrap();
            prop_assert!(t.reward == base || t.reward == base + 5.0);
        }
    }

    /// A terminal stage ends the episode: `done` is set, and no further step is accepted.
    #[test]
    fn terminal_stage_ends_episode(inputs in prop::collection::vec(step_input(), 1..60)) {
        let machine = toy_machine();
        let mut episode = crm::Episode::new(&machine);
        for (observation, fired) in &inputs {
            if machine.is_terminal(episode.stage()) {
                let err = episode.advance(&machine, observation, fired).unwrap_err();
                prop_assert!(matches!(err, crm::Error::EpisodeOver(_)));
                return Ok(());
            }
            let outcome = episode.advance(&machine, observation, fired).unwrap();
            prop_assert_eq!(outcome.done, machine.is_terminal(outcome.next));
            // At most one edge per step.
            prop_assert!(outcome.event.is_some() || outcome.next == outcome.from);
        }
    }

    /// A reward mode only hides parts; `crm` = `dense` + `sparse`.
    #[test]
    fn modes_partition_the_reward(intra in -100.0f32..100.0, transition in -100.0f32..100.0) {
        let (ci, ct) = crm::RewardMode::Crm.apply(intra, transition);
        let (di, dt) = crm::RewardMode::Dense.apply(intra, transition);
        let (si, st) = crm::RewardMode::Sparse.apply(intra, transition);
        prop_assert_eq!(ci + ct, (di + dt) + (si + st));
    }
}

#[test]
fn first_event_in_priority_order_wins() {
    let machine = toy_machine();
    let approach = machine.initial();
    // Both arrive and oor fire: arrive comes first in the spec's event list.
    let arrive = machine.event_id("arrive").unwrap();
    let oor = machine.event_id("oor").unwrap();
    let outcome = machine
        .step(approach, &[0.0, 0.0, 0.0], &[oor, arrive])
        .unwrap();
    assert_eq!(machine.stage_name(outcome.next), "grasp");
    assert_eq!(outcome.transition_reward, 10.0);
    // The abstract state is the next stage's: grasp sees three features.
    assert_eq!(outcome.abstract_state.len(), 3);
    // The intra reward is the approach stage's: -e^0 - 0.5 * 0.
    assert_eq!(outcome.intra_reward, -1.0);
}

#[test]
fn an_event_without_edge_keeps_the_stage() {
    let machine = toy_machine();
    let succ = machine.event_id("succ").unwrap();
    let outcome = machine
        .step(machine.initial(), &[0.5, 1.0, 0.0], &[succ])
        .unwrap();
    assert_eq!(outcome.next, machine.initial());
    assert_eq!(outcome.transition_reward, 0.0);
    assert!(!outcome.done);
}

#[test]
fn success_bonus_needs_the_cone_feature() {
    let machine = toy_machine();
    let grasp = machine.stage_id("grasp").unwrap();
    let succ = machine.event_id("succ").unwrap();
    let without = machine.step(grasp, &[0.0, 3.0, 0.0], &[succ]).unwrap();
    let with = machine.step(grasp, &[0.0, 3.0, 1.0], &[succ]).unwrap();
    assert_eq!(without.transition_reward, 100.0);
    assert_eq!(with.transition_reward, 105.0);
    assert!(with.done);
}

#[test]
fn actions_are_masked_scaled_clipped_and_checked() {
    let machine = toy_machine();
    let approach = machine.initial();
    let grasp = machine.stage_id("grasp").unwrap();
    assert_eq!(machine.action_mask(approach), vec![1.0, 0.0]);
    let (action, clipped) = machine.expand_action(approach, &[2.0]).unwrap();
    assert_eq!((action, clipped), (vec![0.01, 0.0], 1));
    // A full union-space vector: the masked grip value is ignored.
    let (action, clipped) = machine.expand_action(approach, &[0.5, f32::NAN]).unwrap();
    assert_eq!((action, clipped), (vec![0.005, 0.0], 0));
    let err = machine
        .expand_action(grasp, &[0.0, f32::INFINITY])
        .unwrap_err();
    assert!(
        err.to_string().contains("action dimension 1 (grip)"),
        "{err}"
    );
    let err = machine.expand_action(grasp, &[0.0, 0.0, 0.0]).unwrap_err();
    assert!(matches!(err, crm::Error::ActionLength { .. }), "{err}");
}

/// An environment that fires an event the machine does not declare, then `arrive`.
struct Chatty {
    steps: usize,
}

impl crm::Environment for Chatty {
    fn reset(&mut self, _seed: u64) -> Result<Vec<f32>, String> {
        self.steps = 0;
        Ok(vec![1.0, 0.0, 0.0])
    }

    fn set_stage(&mut self, _stage: &str) {}

    fn step(&mut self, _action: &[f32]) -> Result<crm::EnvStep, String> {
        self.steps += 1;
        let events = if self.steps == 1 {
            vec!["sneeze"]
        } else {
            vec!["sneeze", "arrive"]
        };
        Ok(crm::EnvStep {
            observation: vec![0.5, 0.0, 0.0],
            events,
            truncated: false,
        })
    }
}

#[test]
fn events_the_machine_does_not_declare_are_ignored() {
    let mut env = crm::CrmEnv::new(toy_machine(), Chatty { steps: 0 }, crm::RewardMode::Crm);
    env.reset(0).unwrap();
    let first = env.step(&[0.0]).unwrap();
    assert_eq!(first.event, None);
    let second = env.step(&[0.0]).unwrap();
    assert_eq!(second.event.as_deref(), Some("arrive"));
    assert_eq!(env.machine().stage_name(second.stage), "grasp");
}
