//! Contact metrics from rapier's contact manifolds: count, summed force and torque, grip and
//! the friction-cone test of the paper's observation (section IV-C).
//!
//! rapier reports per-point impulses over a physics step; dividing by `dt` gives forces. The
//! solver clamps friction to the cone, so a contact that uses all of it is sliding: the
//! cone test asks for sticking contacts with a margin, `|F_t| <= (1 - margin) mu F_n`.

use rapier3d::prelude::*;

/// One active contact on the object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactPoint {
    /// World position on the object's surface side.
    pub position: Vec3,
    /// Force the other body applies to the object (N, world).
    pub force: Vec3,
    /// Normal force magnitude (N).
    pub normal_force: f32,
    /// Friction force magnitude (N).
    pub friction_force: f32,
    /// Friction force on the object (N, world).
    pub friction_vector: Vec3,
    /// Friction coefficient of the pair.
    pub friction: f32,
    /// The body of the other collider (a hand link, or `None` for the table).
    pub other_body: Option<RigidBodyHandle>,
}

/// Summed contact quantities between the object and one group of colliders.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactMetrics {
    pub points: Vec<ContactPoint>,
    /// Vector sum of the forces on the object (N).
    pub force: Vec3,
    /// Vector sum of their torques about the object's centre of mass (N m).
    pub torque: Vec3,
    /// Sum of normal force magnitudes (N): the grip.
    pub grip: f32,
}

impl ContactMetrics {
    /// `n_c`.
    pub fn count(&self) -> usize {
        self.points.len()
    }

    /// The bodies (other than the object) with at least one contact, each once.
    pub fn touching_bodies(&self) -> Vec<RigidBodyHandle> {
        let mut bodies: Vec<RigidBodyHandle> = Vec::new();
        for body in self.points.iter().filter_map(|p| p.other_body) {
            if !bodies.contains(&body) {
                bodies.push(body);
            }
        }
        bodies
    }

    /// `o_cone`: there is contact and every contact sticks inside its friction cone with the
    /// margin. A contact is one body touching the object (a finger link, the palm, the table):
    /// rapier splits such a patch into several points and may saturate friction at a lightly
    /// loaded one while the patch holds, so each patch is tested with its points' forces
    /// added up: `sum |F_t| <= (1 - margin) mu sum F_n`. (Adding the friction vectors instead
    /// would be fooled by the solver's lateral components, which cancel between points.)
    pub fn in_cone(&self, margin: f32) -> bool {
        let mut patches: Vec<(Option<RigidBodyHandle>, f32, f32, f32)> = Vec::new();
        for point in &self.points {
            match patches
                .iter_mut()
                .find(|(body, ..)| *body == point.other_body)
            {
                Some((_, normal, friction, _)) => {
                    *normal += point.normal_force;
                    *friction += point.friction_force;
                }
                None => patches.push((
                    point.other_body,
                    point.normal_force,
                    point.friction_force,
                    point.friction,
                )),
            }
        }
        !patches.is_empty()
            && patches
                .iter()
                .all(|&(_, normal, friction, mu)| friction <= (1.0 - margin) * mu * normal)
    }

    /// Torque of the contact forces about an axis through `pivot` (N m).
    pub fn torque_about(&self, pivot: Vec3, axis: Vec3) -> f32 {
        self.points
            .iter()
            .map(|p| (p.position - pivot).cross(p.force).dot(axis))
            .sum()
    }
}

/// Smallest normal impulse (N s) that counts as touching, to skip speculative contacts.
const MIN_IMPULSE: f32 = 1e-7;

/// Contacts between `object` and the colliders for which `is_other` holds.
pub fn object_contacts(
    world: &PhysicsWorld,
    object: RigidBodyHandle,
    is_other: impl Fn(ColliderHandle, &Collider) -> bool,
) -> ContactMetrics {
    let dt = world.integration_parameters.dt;
    let mut metrics = ContactMetrics::default();
    let Some(body) = world.bodies.get(object) else {
        return metrics;
    };
    let com = body.center_of_mass();
    for pair in world.narrow_phase.contact_pairs() {
        let (Some(c1), Some(c2)) = (
            world.colliders.get(pair.collider1),
            world.colliders.get(pair.collider2),
        ) else {
            continue;
        };
        let object_first = c1.parent() == Some(object);
        let object_second = c2.parent() == Some(object);
        let (other_handle, other) = match (object_first, object_second) {
            (true, false) => (pair.collider2, c2),
            (false, true) => (pair.collider1, c1),
            _ => continue,
        };
        if !is_other(other_handle, other) {
            continue;
        }
        for manifold in pair.solver_manifolds() {
            for point in &manifold.points {
                if point.data.impulse <= MIN_IMPULSE {
                    continue;
                }
                let normal_force = point.data.impulse / dt;
                let friction_force = point.data.tangent_impulse.norm() / dt;
                let friction_dir = point.data.warmstart_tangent_world.normalize_or_zero();
                // Forces on collider 1's body: the normal pushes it back along -n.
                let sign = if object_first { 1.0 } else { -1.0 };
                let friction_vector = sign * friction_dir * friction_force;
                let force = sign * -manifold.data.normal * normal_force + friction_vector;
                let position = c1.position().transform_point(point.local_p1);
                metrics.points.push(ContactPoint {
                    position,
                    force,
                    normal_force,
                    friction_force,
                    friction_vector,
                    friction: manifold.data.friction,
                    other_body: other.parent(),
                });
                metrics.force += force;
                metrics.torque += (position - com).cross(force);
                metrics.grip += normal_force;
            }
        }
    }
    metrics
}

/// Adds `other` into `self`, for averaging over the physics steps of a control step.
impl ContactMetrics {
    pub(crate) fn accumulate(&mut self, other: &ContactMetrics) {
        self.force += other.force;
        self.torque += other.torque;
        self.grip += other.grip;
    }

    pub(crate) fn scale(&mut self, factor: f32) {
        self.force *= factor;
        self.torque *= factor;
        self.grip *= factor;
    }
}
