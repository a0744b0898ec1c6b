//! The paper's "ready" test (the authors' `pickup()`): the grasp is ready for the arm to
//! execute the objective when the topology's parts touch the object and the grip can carry
//! it without crushing it.
//!
//! Per topology: the thumb opposes at least one other finger of the topology, both touching
//! (a finger touches when its links' normal forces add up to `ready_finger_force`; a
//! topology that moves only the thumb, as the SVH's InSiAd2 does, presses it against a
//! finger it holds still, which then counts: the authors ask InSiAd2 for any two parts), and the
//! three- and five-finger topologies touch with at least three parts (a part is a finger link
//! or the palm). The authors' code asks pPdAb2 for thumb and index, pPdAb23 for thumb, index
//! and three parts, pPdAb25 and poPmAb25 for four parts and InSiAd2 for two; four parts
//! left the oracle's twists and handle grasps, which hold with thumb, index and palm or
//! middle, never ready (docs/LEARNING.md). The summed grip must be at least what the object
//! needs (three times its weight through friction, `3 m g / mu`, between 6 N and 55% of the
//! fragility limit; 1 N for an anchored object, which carries no weight) and under the
//! fragility limit. A press (the platform topology's palm, or a finger) needs no grasp: the
//! environment starts it as soon as the hand has arrived, as the authors' code does.

use rapier3d::prelude::RigidBodyHandle;

use crate::benchmark::{FingerShape, Object, Topology};
use crate::contacts::ContactMetrics;
use crate::hand::Hand;

/// The grip an anchored object (a valve, a drawer) needs before the arm moves: it carries no
/// weight, so only a firm touch (N).
const ANCHORED_GRIP: f32 = 1.0;
/// Safety factor on the grip that carries the weight through friction: the arm accelerates
/// the object and keeps the grip it is handed.
const SAFETY: f32 = 3.0;
/// The least grip (N) asked of a free object.
const MIN_GRIP: f32 = 6.0;

/// How the hand touches the object in one control step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Touch {
    /// Each finger's summed normal force (N), thumb first.
    pub fingers: [f32; 5],
    /// Hand bodies (finger links and the palm) touching with at least the part force.
    pub parts: usize,
    /// Summed normal force of the whole hand (N).
    pub grip: f32,
}

/// The ready test of one episode's object and topology.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadyTest {
    pub topology: Topology,
    /// The topology's fingers on this hand (thumb first).
    pub active: [bool; 5],
    /// Smallest summed normal force (N) that carries the object.
    pub need: f32,
    /// The object's fragility limit (N): a grip at or above it is not ready.
    pub limit: f32,
    /// Smallest normal force (N) with which a finger or a part counts as touching.
    pub part_force: f32,
}

/// The grip (N) that carries a free object: three times what its weight needs through
/// friction, at least 6 N, at most 55% of its fragility limit. The ready test asks for it and
/// the oracle closes to it.
pub fn carrying_grip(object: &Object) -> f32 {
    // rapier averages the two friction coefficients (the hand's is 1).
    let friction = 0.5 * (1.0 + object.friction);
    let limit = object.fragility.grasp_force_limit();
    (SAFETY * object.mass * 9.81 / friction).clamp(MIN_GRIP, 0.55 * limit)
}

impl ReadyTest {
    /// The test for `object` grasped with `topology`.
    pub fn for_object(
        topology: Topology,
        shape: &[FingerShape; 5],
        object: &Object,
        part_force: f32,
    ) -> Self {
        let need = if object.anchor.is_some() {
            ANCHORED_GRIP
        } else {
            carrying_grip(object)
        };
        Self {
            topology,
            active: std::array::from_fn(|f| shape[f].active),
            need,
            limit: object.fragility.grasp_force_limit(),
            part_force,
        }
    }

    /// Whether the grasp is ready.
    pub fn is_ready(&self, touch: &Touch) -> bool {
        if self.topology == Topology::Platform {
            return true;
        }
        if touch.grip < self.need || touch.grip >= self.limit {
            return false;
        }
        // A topology that moves the thumb alone (the SVH's InSiAd2: the thumb closes on the
        // side of the preshaped index) opposes it with a finger it holds still.
        let side = self.active[0] && !self.active[1..].iter().any(|&a| a);
        let touching = |f: usize| touch.fingers[f] >= self.part_force;
        let opposed = self.active[0]
            && touching(0)
            && (1..5).any(|f| (self.active[f] || side) && touching(f));
        let parts = match self.topology {
            Topology::PPdAb23 | Topology::PPdAb25 | Topology::PoPmAb25 => 3,
            _ => 2,
        };
        opposed && touch.parts >= parts
    }
}

/// How `hand` touches the object in `contacts`, counting parts from `part_force` (N).
pub fn touch(contacts: &ContactMetrics, hand: &Hand, part_force: f32) -> Touch {
    let mut fingers = [0.0; 5];
    let mut bodies: Vec<(RigidBodyHandle, f32)> = Vec::new();
    for point in &contacts.points {
        let Some(body) = point.other_body else {
            continue;
        };
        if let Some((finger, _)) = hand.link_of(body) {
            fingers[finger] += point.normal_force;
        } else if !hand.is_palm(body) {
            continue;
        }
        match bodies.iter_mut().find(|(b, _)| *b == body) {
            Some((_, force)) => *force += point.normal_force,
            None => bodies.push((body, point.normal_force)),
        }
    }
    Touch {
        fingers,
        parts: bodies.iter().filter(|(_, f)| *f >= part_force).count(),
        grip: contacts.grip,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::benchmark::Benchmark;

    fn test_for(topology: Topology, object: &str) -> ReadyTest {
        let benchmark = Benchmark::builtin();
        let object = benchmark
            .objects
            .iter()
            .find(|o| o.name == object)
            .expect("object");
        let shape = crate::hand::builtin::model().shape(topology);
        ReadyTest::for_object(topology, &shape, object, 0.3)
    }

    /// A touch by the listed fingers (thumb first), one link each, sharing `grip`.
    fn pinch(fingers: &[usize], grip: f32) -> Touch {
        let mut touch = Touch {
            grip,
            parts: fingers.len(),
            ..Touch::default()
        };
        for &f in fingers {
            touch.fingers[f] = grip / fingers.len() as f32;
        }
        touch
    }

    #[test]
    fn a_pinch_of_thumb_and_index_with_enough_grip_is_ready() {
        let test = test_for(Topology::PPdAb2, "mug");
        assert!(test.is_ready(&pinch(&[0, 1], test.need + 1.0)));
    }

    #[test]
    fn one_finger_alone_is_not_ready() {
        let test = test_for(Topology::PPdAb2, "mug");
        let grip = test.need + 1.0;
        assert!(!test.is_ready(&pinch(&[0], grip)));
        assert!(!test.is_ready(&pinch(&[1], grip)));
        // A finger outside the topology does not count.
        assert!(!test.is_ready(&pinch(&[0, 2], grip)));
        // Five-finger topologies need three parts, the thumb opposing one of them.
        let wide = test_for(Topology::PPdAb25, "mug");
        let grip = wide.need + 1.0;
        assert!(!wide.is_ready(&pinch(&[0, 1], grip)));
        assert!(!wide.is_ready(&pinch(&[1, 2, 3], grip)));
        assert!(wide.is_ready(&pinch(&[0, 1, 2], grip)));
    }

    #[test]
    fn a_thumb_alone_closes_on_a_finger_held_still() {
        // The SVH's InSiAd2 moves only the thumb; the index is preshaped and held.
        let mut test = test_for(Topology::InSiAd2, "mug");
        test.active = [true, false, false, false, false];
        let grip = test.need + 1.0;
        assert!(test.is_ready(&pinch(&[0, 1], grip)));
        assert!(!test.is_ready(&pinch(&[0], grip)));
        assert!(!test.is_ready(&pinch(&[1, 2], grip)));
        // A thumb held still opposes nothing.
        test.active = [false, true, false, false, false];
        assert!(!test.is_ready(&pinch(&[0, 1], grip)));
    }

    #[test]
    fn too_weak_or_crushing_grips_are_not_ready() {
        let test = test_for(Topology::PPdAb2, "mug");
        assert!(!test.is_ready(&pinch(&[0, 1], 0.9 * test.need)));
        assert!(!test.is_ready(&pinch(&[0, 1], test.limit + 1.0)));
        // The grip asked of a free object stays under its fragility limit.
        let cup = test_for(Topology::PPdAb25, "paper_cup");
        assert!(cup.need < cup.limit);
    }

    #[test]
    fn the_platform_presses_once_arrived() {
        let test = test_for(Topology::Platform, "mouse");
        assert!(test.is_ready(&Touch::default()));
    }
}
