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
    /// The object's centre of mass about which `torque` is taken (m, world; the last
    /// physics step's when the metrics are a control step's mean).
    pub centre: Vec3,
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

    /// Torque of the contact forces about an axis through `pivot` (N m), from the summed
    /// `force` and `torque`: so it is the control step's mean wherever those are (the
    /// contact points are the last physics step's alone, and a twist read from them jumps
    /// with the solver between 0 and twice its mean).
    pub fn torque_about(&self, pivot: Vec3, axis: Vec3) -> f32 {
        (self.torque + (self.centre - pivot).cross(self.force)).dot(axis)
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
    metrics.centre = com;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Metrics of contact points as `object_contacts` sums them, about `centre`.
    fn metrics_of(centre: Vec3, points: &[(Vec3, Vec3)]) -> ContactMetrics {
        let mut metrics = ContactMetrics {
            centre,
            ..ContactMetrics::default()
        };
        for &(position, force) in points {
            metrics.points.push(ContactPoint {
                position,
                force,
                normal_force: force.length(),
                friction_force: 0.0,
                friction_vector: Vec3::ZERO,
                friction: 1.0,
                other_body: None,
            });
            metrics.force += force;
            metrics.torque += (position - centre).cross(force);
            metrics.grip += force.length();
        }
        metrics
    }

    fn points_about(metrics: &ContactMetrics, pivot: Vec3, axis: Vec3) -> f32 {
        metrics
            .points
            .iter()
            .map(|p| (p.position - pivot).cross(p.force).dot(axis))
            .sum()
    }

    #[test]
    fn the_torque_about_an_axis_is_the_points_torque_and_a_mean_of_means() {
        let (pivot, axis) = (Vec3::new(0.1, -0.2, 0.0), Vec3::Z);
        let centre = Vec3::new(0.12, -0.18, 0.05);
        // Two fingers on either side of a cap pushed round it, then the solver's next physics
        // step with half the push, carried by one of them: the control step's mean is 0.15.
        let first = metrics_of(
            centre,
            &[
                (Vec3::new(0.15, -0.2, 0.05), Vec3::new(-2.0, 3.0, 0.0)),
                (Vec3::new(0.05, -0.2, 0.06), Vec3::new(2.0, -1.0, 0.5)),
            ],
        );
        let second = metrics_of(
            centre,
            &[(Vec3::new(0.15, -0.2, 0.05), Vec3::new(0.0, 2.0, 0.0))],
        );
        for metrics in [&first, &second] {
            let expected = points_about(metrics, pivot, axis);
            assert!((metrics.torque_about(pivot, axis) - expected).abs() < 1e-6);
        }
        let mut mean = ContactMetrics::default();
        mean.accumulate(&first);
        mean.accumulate(&second);
        mean.scale(0.5);
        let (mut last, expected) = (second.clone(), 0.5 * (0.2 + 0.1));
        last.force = mean.force;
        last.torque = mean.torque;
        assert!((points_about(&first, pivot, axis) - 0.2).abs() < 1e-6);
        assert!((points_about(&second, pivot, axis) - 0.1).abs() < 1e-6);
        assert!((last.torque_about(pivot, axis) - expected).abs() < 1e-6);
    }
}
