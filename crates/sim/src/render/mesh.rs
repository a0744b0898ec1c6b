//! Each part's shape as world-space triangles: cuboids as their 12 faces, balls, cylinders and
//! capsules tessellated ([`SEGMENTS`] around), meshes as they are.

use crate::view::{Part, PartShape};

/// Facets around a round shape.
const SEGMENTS: usize = 16;
/// Rings from pole to pole of a ball (and of a capsule's two caps together).
const RINGS: usize = 8;

pub type Triangle = [[f32; 3]; 3];

/// Rotates `v` by the unit quaternion `q` (x, y, z, w).
pub fn rotate(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let [x, y, z, w] = q;
    // t = 2 (q.xyz x v); v' = v + w t + q.xyz x t
    let t = [
        2.0 * (y * v[2] - z * v[1]),
        2.0 * (z * v[0] - x * v[2]),
        2.0 * (x * v[1] - y * v[0]),
    ];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn normalize(a: [f32; 3]) -> [f32; 3] {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if n > 0.0 { scale(a, 1.0 / n) } else { a }
}

/// Two unit vectors perpendicular to unit `axis` and to each other.
fn basis(axis: [f32; 3]) -> ([f32; 3], [f32; 3]) {
    let helper = if axis[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = normalize(cross(axis, helper));
    (u, cross(axis, u))
}

/// A quad split in two.
fn quad(out: &mut Vec<Triangle>, a: [f32; 3], b: [f32; 3], c: [f32; 3], d: [f32; 3]) {
    out.push([a, b, c]);
    out.push([a, c, d]);
}

fn cuboid(out: &mut Vec<Triangle>, h: [f32; 3]) {
    let v = |sx: f32, sy: f32, sz: f32| [sx * h[0], sy * h[1], sz * h[2]];
    let faces = [
        [
            v(1., -1., -1.),
            v(1., 1., -1.),
            v(1., 1., 1.),
            v(1., -1., 1.),
        ],
        [
            v(-1., -1., -1.),
            v(-1., -1., 1.),
            v(-1., 1., 1.),
            v(-1., 1., -1.),
        ],
        [
            v(-1., 1., -1.),
            v(-1., 1., 1.),
            v(1., 1., 1.),
            v(1., 1., -1.),
        ],
        [
            v(-1., -1., -1.),
            v(1., -1., -1.),
            v(1., -1., 1.),
            v(-1., -1., 1.),
        ],
        [
            v(-1., -1., 1.),
            v(1., -1., 1.),
            v(1., 1., 1.),
            v(-1., 1., 1.),
        ],
        [
            v(-1., -1., -1.),
            v(-1., 1., -1.),
            v(1., 1., -1.),
            v(1., -1., -1.),
        ],
    ];
    for [a, b, c, d] in faces {
        quad(out, a, b, c, d);
    }
}

/// A tube of `radius` from `a` to `b` with a half ball at each end when `caps` (a capsule),
/// or flat discs (a cylinder).
fn tube(out: &mut Vec<Triangle>, a: [f32; 3], b: [f32; 3], radius: f32, caps: bool) {
    let axis = sub(b, a);
    let unit = if axis == [0.0; 3] {
        [0.0, 0.0, 1.0]
    } else {
        normalize(axis)
    };
    let (u, w) = basis(unit);
    let ring = |k: usize| {
        let t = k as f32 / SEGMENTS as f32 * std::f32::consts::TAU;
        add(scale(u, t.cos() * radius), scale(w, t.sin() * radius))
    };
    for k in 0..SEGMENTS {
        let (r0, r1) = (ring(k), ring(k + 1));
        quad(out, add(a, r0), add(a, r1), add(b, r1), add(b, r0));
        if !caps {
            out.push([a, add(a, r1), add(a, r0)]);
            out.push([b, add(b, r0), add(b, r1)]);
        }
    }
    if caps {
        // Each end's half ball: rings from the rim (latitude 0) to the pole.
        let half = RINGS / 2;
        for (centre, dir) in [(a, scale(unit, -1.0)), (b, unit)] {
            let point = |k: usize, lat: usize| {
                let phi = lat as f32 / half as f32 * std::f32::consts::FRAC_PI_2;
                add(
                    centre,
                    add(scale(ring(k), phi.cos()), scale(dir, phi.sin() * radius)),
                )
            };
            bands(out, half, point);
        }
    }
}

fn ball(out: &mut Vec<Triangle>, radius: f32) {
    let point = |k: usize, lat: usize| {
        let theta = k as f32 / SEGMENTS as f32 * std::f32::consts::TAU;
        let phi = lat as f32 / RINGS as f32 * std::f32::consts::PI - std::f32::consts::FRAC_PI_2;
        [
            radius * phi.cos() * theta.cos(),
            radius * phi.cos() * theta.sin(),
            radius * phi.sin(),
        ]
    };
    bands(out, RINGS, point);
}

/// The quads between `rings` + 1 rings of [`SEGMENTS`] points each, `point(k, ring)`.
fn bands(out: &mut Vec<Triangle>, rings: usize, point: impl Fn(usize, usize) -> [f32; 3]) {
    for lat in 0..rings {
        for k in 0..SEGMENTS {
            quad(
                out,
                point(k, lat),
                point(k + 1, lat),
                point(k + 1, lat + 1),
                point(k, lat + 1),
            );
        }
    }
}

/// `part`'s triangles in world coordinates (none for a shape the view does not draw).
pub fn triangles(part: &Part) -> Vec<Triangle> {
    let mut local = Vec::new();
    match &part.shape {
        PartShape::Cuboid { half_extents } => cuboid(&mut local, *half_extents),
        PartShape::Ball { radius } => ball(&mut local, *radius),
        PartShape::Capsule { a, b, radius } => tube(&mut local, *a, *b, *radius, true),
        PartShape::Cylinder {
            half_height,
            radius,
        } => tube(
            &mut local,
            [0.0, -half_height, 0.0],
            [0.0, *half_height, 0.0],
            *radius,
            false,
        ),
        PartShape::Mesh {
            vertices,
            triangles,
        } => {
            let at = |i: u32| vertices.get(i as usize).copied();
            local.extend(
                triangles
                    .iter()
                    .filter_map(|[a, b, c]| Some([at(*a)?, at(*b)?, at(*c)?])),
            );
        }
        PartShape::Other => {}
    }
    for triangle in &mut local {
        for v in triangle.iter_mut() {
            *v = add(rotate(part.rotation, *v), part.translation);
        }
    }
    local
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarter_turn_about_z_takes_x_to_y() {
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let v = rotate([0.0, 0.0, h, h], [1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-6 && (v[1] - 1.0).abs() < 1e-6 && v[2].abs() < 1e-6);
    }

    #[test]
    fn every_vertex_of_a_tessellated_ball_lies_on_it() {
        let part = Part {
            name: "object/part_0".into(),
            shape: PartShape::Ball { radius: 0.05 },
            translation: [1.0, 2.0, 3.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
            drawn: true,
        };
        let tris = triangles(&part);
        assert_eq!(tris.len(), 2 * SEGMENTS * RINGS);
        for v in tris.iter().flatten() {
            let d = sub(*v, [1.0, 2.0, 3.0]);
            let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((r - 0.05).abs() < 1e-5, "{r}");
        }
    }

    #[test]
    fn a_capsule_reaches_its_radius_past_each_end() {
        let part = Part {
            name: "hand/index/link_0".into(),
            shape: PartShape::Capsule {
                a: [0.0, 0.0, 0.0],
                b: [0.0, 0.0, 0.1],
                radius: 0.01,
            },
            translation: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
            drawn: true,
        };
        let zs: Vec<f32> = triangles(&part).iter().flatten().map(|v| v[2]).collect();
        let (lo, hi) = zs
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), &z| (l.min(z), h.max(z)));
        assert!(
            (lo + 0.01).abs() < 1e-6 && (hi - 0.11).abs() < 1e-6,
            "{lo} {hi}"
        );
    }
}
