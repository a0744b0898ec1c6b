//! Contact metrics on hand-made scenes: a box resting on the table, a falling box, and a box
//! pushed sideways below its static friction.

use grasp_sim::config::SimConfig;
use grasp_sim::contacts::{ContactMetrics, object_contacts};
use grasp_sim::scene::{TABLE_HALF, integration_parameters};
use rapier3d::prelude::*;

const MASS: f32 = 0.5;
const HALF: f32 = 0.025;

struct BoxScene {
    world: PhysicsWorld,
    body: RigidBodyHandle,
}

fn box_scene(height: f32) -> BoxScene {
    box_scene_ordered(height, false)
}

/// `box_first` inserts the box before the table, which swaps the colliders' order in rapier's
/// contact pairs: the metrics must not depend on it.
/// An empty world with the environment's gravity and solver parameters.
fn world() -> PhysicsWorld {
    let mut world = PhysicsWorld::new();
    world.gravity = Vec3::new(0.0, 0.0, -9.81);
    world.integration_parameters = integration_parameters(&SimConfig::deterministic());
    world
}

fn insert_table(world: &mut PhysicsWorld, friction: f32) {
    world.insert_collider(
        ColliderBuilder::cuboid(TABLE_HALF[0], TABLE_HALF[1], TABLE_HALF[2])
            .translation(Vec3::new(0.0, 0.0, -TABLE_HALF[2]))
            .friction(friction),
        None,
    );
}

fn box_scene_ordered(height: f32, box_first: bool) -> BoxScene {
    let mut world = world();
    let early = if box_first {
        Some(
            world.insert(
                RigidBodyBuilder::dynamic().translation(Vec3::new(0.0, 0.0, height)),
                ColliderBuilder::cuboid(HALF, HALF, HALF)
                    .mass(MASS)
                    .friction(0.6),
            ),
        )
    } else {
        None
    };
    insert_table(&mut world, 0.6);
    let (body, _) = match early {
        Some(handles) => handles,
        None => world.insert(
            RigidBodyBuilder::dynamic().translation(Vec3::new(0.0, 0.0, height)),
            ColliderBuilder::cuboid(HALF, HALF, HALF)
                .mass(MASS)
                .friction(0.6),
        ),
    };
    BoxScene { world, body }
}

fn table_contacts(scene: &BoxScene) -> ContactMetrics {
    object_contacts(&scene.world, scene.body, |_, collider| {
        collider.parent().is_none()
    })
}

#[test]
fn a_resting_box_pushes_its_weight_into_the_table() {
    let mut scene = box_scene(HALF);
    for _ in 0..240 {
        scene.world.step();
    }
    let metrics = table_contacts(&scene);
    let weight = MASS * 9.81;
    assert!(metrics.count() > 0, "no contact reported for a resting box");
    let normal: f32 = metrics.points.iter().map(|p| p.normal_force).sum();
    assert!(
        (normal - weight).abs() < 0.05 * weight,
        "summed normal force {normal} vs m*g {weight}"
    );
    // The table's force on the box points up and balances gravity.
    assert!(
        (metrics.force.z - weight).abs() < 0.05 * weight,
        "net force {:?}",
        metrics.force
    );
    assert!(metrics.force.x.abs() < 0.05 && metrics.force.y.abs() < 0.05);
}

#[test]
fn a_falling_box_has_no_contact() {
    let mut scene = box_scene(0.5);
    for _ in 0..30 {
        scene.world.step();
    }
    let metrics = table_contacts(&scene);
    assert_eq!(metrics.count(), 0);
    assert_eq!(metrics.grip, 0.0);
    assert_eq!(metrics.force, Vec3::ZERO);
}

#[test]
fn friction_opposes_a_sideways_push_below_the_static_limit() {
    for box_first in [false, true] {
        friction_opposes_push(box_first);
    }
}

/// Lets the box settle for 0.5 s, then pushes it along x with `push` newtons for 0.25 s;
/// returns the table's contacts on it at the end.
fn settle_then_push(scene: &mut BoxScene, push: f32) -> ContactMetrics {
    for _ in 0..120 {
        scene.world.step();
    }
    let mut metrics = ContactMetrics::default();
    for _ in 0..60 {
        if let Some(body) = scene.world.bodies.get_mut(scene.body) {
            body.reset_forces(true);
            body.add_force(Vec3::new(push, 0.0, 0.0), true);
        }
        scene.world.step();
        metrics = table_contacts(scene);
    }
    metrics
}

fn friction_opposes_push(box_first: bool) {
    let mut scene = box_scene_ordered(HALF, box_first);
    let push = 1.0;
    let metrics = settle_then_push(&mut scene, push);
    assert!(
        (metrics.force.x + push).abs() < 0.1,
        "friction on the box {:?} should be -{push} N along x",
        metrics.force
    );
    // Well inside the cone: 1 N of friction against mu * m * g = 2.9 N.
    assert!(metrics.in_cone(0.05));
    let moved = scene
        .world
        .bodies
        .get(scene.body)
        .map(|b| b.translation().x)
        .unwrap_or(1.0);
    assert!(moved.abs() < 1e-3, "the box slid {moved} m");
}

#[test]
fn a_sliding_box_is_outside_the_cone() {
    let mut scene = box_scene(HALF);
    let metrics = settle_then_push(&mut scene, 6.0);
    // The solver clamps friction to the cone: a sliding contact sits on its boundary.
    assert!(
        !metrics.in_cone(0.05),
        "a sliding box must fail the friction-cone test"
    );
    assert!(
        metrics.force.x < -2.0,
        "kinetic friction opposes the push: {:?}",
        metrics.force
    );
}

/// Two dynamic bodies take another solver path than a body on the fixed table: the friction
/// direction must come out the same. A box rests on a heavier box and is pushed sideways.
#[test]
fn friction_between_two_dynamic_bodies_opposes_the_push() {
    for top_first in [false, true] {
        let mut world = world();
        let top_body = RigidBodyBuilder::dynamic().translation(Vec3::new(0.0, 0.0, 3.0 * HALF));
        let top_collider = ColliderBuilder::cuboid(HALF, HALF, HALF)
            .mass(MASS)
            .friction(0.6);
        let top = if top_first {
            Some(world.insert(top_body.clone(), top_collider.clone()).0)
        } else {
            None
        };
        insert_table(&mut world, 1.0);
        let (bottom, _) = world.insert(
            RigidBodyBuilder::dynamic().translation(Vec3::new(0.0, 0.0, HALF)),
            ColliderBuilder::cuboid(2.0 * HALF, 2.0 * HALF, HALF)
                .mass(5.0)
                .friction(0.6),
        );
        let top = top.unwrap_or_else(|| world.insert(top_body, top_collider).0);
        for _ in 0..120 {
            world.step();
        }
        let mut metrics = ContactMetrics::default();
        for _ in 0..60 {
            if let Some(body) = world.bodies.get_mut(top) {
                body.reset_forces(true);
                body.add_force(Vec3::new(1.0, 0.0, 0.0), true);
            }
            world.step();
            metrics = object_contacts(&world, top, |_, collider| collider.parent() == Some(bottom));
        }
        let weight = MASS * 9.81;
        assert!(
            (metrics.force.z - weight).abs() < 0.05 * weight,
            "top_first={top_first}: {:?}",
            metrics.force
        );
        assert!(
            (metrics.force.x + 1.0).abs() < 0.1,
            "top_first={top_first}: friction {:?}",
            metrics.force
        );
    }
}
