//! Collision hulls a solver can afford. Every contact query with a convex hull walks its
//! points, so a fingertip exported from CAD or a scan (LEAP's in dex-urdf: about 6,000
//! points) makes the hand 19x slower to step than primitives would. A hull of more than
//! [`LARGE_HULL`] points is rebuilt from [`KEPT_POINTS`] of them, spread by farthest-point
//! sampling (deterministic: the first is the point farthest from the centroid); smaller hulls
//! are used as written.

use rapier3d::parry::shape::SharedShape;
use rapier3d::prelude::*;

/// Hulls above this many points are rebuilt. Measured (`crm bench env --world W --steps
/// 1500`, one core): rebuilding the SVH's hulls in the paper's world (72-418 points) would
/// step it 14% faster but moves its shipped model's evaluation (0.965 -> 0.952), so they
/// stay; rebuilt, Allegro's (701 points) step 29% faster, LEAP's (5,949 and 6,195) 19x.
pub const LARGE_HULL: usize = 500;

/// Points a rebuilt hull keeps: LEAP steps 1,836 control steps/s on one core with 64, 1,041
/// with 256, 428 with 1,000 and 98 with its own hulls.
pub const KEPT_POINTS: usize = 64;

/// The shape itself, or, for a hull of more than [`LARGE_HULL`] points, the hull of
/// [`KEPT_POINTS`] of them.
pub fn affordable(shape: &SharedShape) -> SharedShape {
    match shape.as_convex_polyhedron() {
        Some(hull) if hull.points().len() > LARGE_HULL => {
            SharedShape::convex_hull(&farthest_points(hull.points(), KEPT_POINTS))
                .unwrap_or_else(|| shape.clone())
        }
        _ => shape.clone(),
    }
}

/// `count` of `points` (all of them if there are fewer), each the farthest from those taken
/// before it.
fn farthest_points(points: &[Vector], count: usize) -> Vec<Vector> {
    if points.len() <= count {
        return points.to_vec();
    }
    let centroid = points.iter().copied().sum::<Vector>() / points.len() as f32;
    let mut next = largest(points.iter().map(|p| (*p - centroid).length_squared()));
    let mut nearest = vec![f32::INFINITY; points.len()];
    let mut kept = Vec::with_capacity(count);
    while kept.len() < count {
        let taken = points[next];
        kept.push(taken);
        for (gap, point) in nearest.iter_mut().zip(points) {
            *gap = gap.min((*point - taken).length_squared());
        }
        next = largest(nearest.iter().copied());
    }
    kept
}

/// The index of the largest value (the first of equals).
fn largest(values: impl Iterator<Item = f32>) -> usize {
    let mut best = (0, f32::NEG_INFINITY);
    for (i, value) in values.enumerate() {
        if value > best.1 {
            best = (i, value);
        }
    }
    best.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a sphere of radius 1 (a golden-angle spiral).
    fn sphere(count: usize) -> Vec<Vector> {
        (0..count)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / count as f32;
                let r = (1.0 - z * z).sqrt();
                let angle = i as f32 * 2.399_963;
                Vector::new(r * angle.cos(), r * angle.sin(), z)
            })
            .collect()
    }

    fn hull_points(shape: &SharedShape) -> usize {
        shape.as_convex_polyhedron().map_or(0, |h| h.points().len())
    }

    #[test]
    fn a_large_hull_is_rebuilt_from_few_points_that_still_span_it() {
        let Some(large) = SharedShape::convex_hull(&sphere(2000)) else {
            panic!("a sphere's hull");
        };
        assert!(hull_points(&large) > LARGE_HULL);
        let rebuilt = affordable(&large);
        assert!(hull_points(&rebuilt) <= KEPT_POINTS);
        let (before, after) = (large.compute_local_aabb(), rebuilt.compute_local_aabb());
        for axis in 0..3 {
            assert!(
                (before.maxs[axis] - after.maxs[axis]).abs() < 0.1,
                "{after:?}"
            );
            assert!(
                (before.mins[axis] - after.mins[axis]).abs() < 0.1,
                "{after:?}"
            );
        }
        // Deterministic: the same points every time.
        let again = affordable(&large);
        let points = |s: &SharedShape| s.as_convex_polyhedron().map(|h| h.points().to_vec());
        assert_eq!(points(&rebuilt), points(&again));
    }

    #[test]
    fn a_small_hull_and_other_shapes_are_kept_as_written() {
        let Some(small) = SharedShape::convex_hull(&sphere(LARGE_HULL / 2)) else {
            panic!("a sphere's hull");
        };
        assert_eq!(hull_points(&affordable(&small)), hull_points(&small));
        let ball = SharedShape::ball(0.01);
        assert!(affordable(&ball).as_ball().is_some());
    }
}
