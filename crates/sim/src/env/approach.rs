//! The authors' approach geometry ([`crate::config::Approach::Authors`]): how one palm step
//! of the policy is slowed near the target and clamped to the box between the start and
//! 1 cm past the target, axis by axis, as DexMobile's `Dualenv.step` and
//! `Dualcontrol.applyAction` move their arm (read at 692dedc; docs/WORLDS.md, "The
//! baselines' first steps, and the approach geometry").

use rapier3d::prelude::Vec3;

/// How far (m) past the target the clamp box reaches on every axis: their 1 cm.
pub const PAST_TARGET: f32 = 0.01;

/// Per-axis step scale by the gap (m) to the target on that axis: their 1 cm steps become
/// 3 mm within 3 cm and 0.5 mm within 1.5 cm.
pub const SLOWDOWN: [(f32, f32); 2] = [(0.015, 0.05), (0.03, 0.3)];

/// The share of a step an axis keeps at `gap` (m) from the target.
pub fn slowdown(gap: f32) -> f32 {
    SLOWDOWN
        .iter()
        .find(|(within, _)| gap <= *within)
        .map_or(1.0, |(_, scale)| *scale)
}

/// The grasp point's move for a policy step `delta` (m) from `point` (where the arm has it)
/// under the authors' geometry: each axis slowed by its gap to `target`, then the point
/// clamped to the box between `start` (the episode's first grasp point) and 1 cm past
/// `target`.
pub fn authors_step(delta: Vec3, point: Vec3, start: Vec3, target: Vec3) -> Vec3 {
    let axis = |i: usize| {
        let slowed = delta[i] * slowdown((target[i] - point[i]).abs());
        let past = target[i] + PAST_TARGET * (target[i] - start[i]).signum();
        let (low, high) = (start[i].min(past), start[i].max(past));
        (point[i] + slowed).clamp(low, high) - point[i]
    };
    Vec3::new(axis(0), axis(1), axis(2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_slow_near_the_target_and_stop_1_cm_past_it() {
        let start = Vec3::new(0.0, 0.0, 0.3);
        let target = Vec3::new(0.2, -0.1, 0.1);
        // Far from the target on every axis: the step is kept.
        let far = Vec3::new(0.05, -0.02, 0.2);
        let step = authors_step(Vec3::new(0.01, -0.01, -0.01), far, start, target);
        assert!(
            (step - Vec3::new(0.01, -0.01, -0.01)).length() < 1e-7,
            "{step:?}"
        );
        // 2 cm from the target on x: 3 mm per cm; 1 cm away: 0.5 mm per cm.
        let near = Vec3::new(0.18, -0.09, 0.2);
        let step = authors_step(Vec3::new(0.01, -0.01, 0.0), near, start, target);
        assert!((step.x - 0.003).abs() < 1e-7 && (step.y + 0.0005).abs() < 1e-7);
        // Past the box's far side (1 cm beyond the target) the point cannot go.
        let at_edge = Vec3::new(0.2098, -0.05, 0.2);
        let step = authors_step(Vec3::new(0.01, 0.0, 0.0), at_edge, start, target);
        assert!((at_edge.x + step.x - 0.21).abs() < 1e-6, "{step:?}");
        // Nor back behind its start, on any axis (z falls from the start towards the target).
        let at_start = Vec3::new(0.0, 0.0, 0.3);
        let step = authors_step(Vec3::new(-0.01, 0.01, 0.01), at_start, start, target);
        assert_eq!(step, Vec3::ZERO);
    }
}
