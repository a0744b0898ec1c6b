//! What a recording holds, entity by entity (z up, metres, newtons):
//! - `world/table`, `world/object/part_K`, `world/hand/palm`, `world/hand/FINGER/link_K`:
//!   each collider's shape once (static) and its pose on every control step (30 Hz; the
//!   physics' 240 Hz is not logged);
//! - `world/contacts` (points) and `world/contacts/forces` (arrows, 5 mm per newton), at most
//!   [`MAX_CONTACTS`] per step; `world/grasp_location`, the task's target on the object;
//! - `crm/stage` (text, when it changes) and `crm/stage_index` (scalar), `crm/reward/intra` and
//!   `crm/reward/transition` (scalars), `crm/transitions` (a text log entry per transition
//!   with its event and transition reward), `crm/episode` (how the episode ended);
//! - per training iteration (timeline `iteration`): `training/...` success, returns split into
//!   intra-stage and transition reward, episode length, stage mix, losses.
//!
//! Episodes use the timeline `step` (control step within the episode).

use grasp_sim::view::{ContactView, Part, PartShape};
use rerun::{RecordingStream, RecordingStreamResult};

/// Contacts logged per step at most (the rest are dropped), to bound a step's size.
pub const MAX_CONTACTS: usize = 32;
/// Arrow length per newton of contact force.
const METRES_PER_NEWTON: f32 = 0.005;

/// The part's colour: the same palette the videos draw with.
fn color(name: &str) -> rerun::Color {
    let [r, g, b] = grasp_sim::render::part_color(name);
    rerun::Color::from_rgb(r, g, b)
}

/// Rotates rerun's cylinder axis (z) onto rapier's (y): -90 degrees about x.
const Z_TO_Y: [f32; 4] = [
    -std::f32::consts::FRAC_1_SQRT_2,
    0.0,
    0.0,
    std::f32::consts::FRAC_1_SQRT_2,
];

fn multiply(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]
}

fn path(part: &Part) -> String {
    format!("world/{}", part.name)
}

/// Shapes once per episode, static (and the table's pose: it never moves).
pub fn log_shapes(rec: &RecordingStream, parts: &[Part]) -> RecordingStreamResult<()> {
    rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    for part in parts.iter().filter(|p| p.drawn) {
        let c = color(&part.name);
        let path = path(part);
        if part.name == "table" {
            rec.log_static(path.clone(), &transform(part))?;
        }
        match part.shape {
            PartShape::Cuboid { half_extents } => rec.log_static(
                path,
                &rerun::Boxes3D::from_half_sizes([half_extents])
                    .with_colors([c])
                    .with_fill_mode(rerun::FillMode::Solid),
            )?,
            PartShape::Ball { radius } => rec.log_static(
                path,
                &rerun::Ellipsoids3D::from_radii([radius])
                    .with_colors([c])
                    .with_fill_mode(rerun::FillMode::Solid),
            )?,
            PartShape::Capsule { a, b, radius } => rec.log_static(
                path,
                &rerun::Capsules3D::from_endpoints_and_radii([a], [b], [radius]).with_colors([c]),
            )?,
            PartShape::Cylinder {
                half_height,
                radius,
            } => rec.log_static(
                path,
                &rerun::Cylinders3D::from_lengths_and_radii([2.0 * half_height], [radius])
                    .with_colors([c])
                    .with_fill_mode(rerun::FillMode::Solid),
            )?,
            PartShape::Mesh {
                ref vertices,
                ref triangles,
            } => rec.log_static(
                path,
                &rerun::Mesh3D::new(vertices.iter().copied())
                    .with_triangle_indices(triangles.iter().copied())
                    .with_albedo_factor(c.0),
            )?,
            PartShape::Other => {}
        }
    }
    Ok(())
}

fn transform(part: &Part) -> rerun::Transform3D {
    let rotation = match part.shape {
        PartShape::Cylinder { .. } => multiply(part.rotation, Z_TO_Y),
        _ => part.rotation,
    };
    rerun::Transform3D::from_translation_rotation(
        part.translation,
        rerun::Quaternion::from_xyzw(rotation),
    )
}

/// The pose of every part that moves (all but the table, logged once with its shape) at the
/// current time.
pub fn log_poses(rec: &RecordingStream, parts: &[Part]) -> RecordingStreamResult<()> {
    for part in parts.iter().filter(|p| p.drawn && p.name != "table") {
        rec.log(path(part), &transform(part))?;
    }
    Ok(())
}

/// Contact points, force arrows and the grasp location at the current time.
pub fn log_contacts(
    rec: &RecordingStream,
    contacts: &[ContactView],
    grasp_location: Option<[f32; 3]>,
) -> RecordingStreamResult<()> {
    let shown = &contacts[..contacts.len().min(MAX_CONTACTS)];
    let origins: Vec<[f32; 3]> = shown.iter().map(|c| c.position).collect();
    let vectors: Vec<[f32; 3]> = shown
        .iter()
        .map(|c| c.force.map(|f| f * METRES_PER_NEWTON))
        .collect();
    rec.log(
        "world/contacts",
        &rerun::Points3D::new(origins.clone())
            .with_radii([0.003])
            .with_colors([rerun::Color::from_rgb(220, 40, 40)]),
    )?;
    rec.log(
        "world/contacts/forces",
        &rerun::Arrows3D::from_vectors(vectors)
            .with_origins(origins)
            .with_colors([rerun::Color::from_rgb(240, 120, 20)]),
    )?;
    if let Some(location) = grasp_location {
        rec.log(
            "world/grasp_location",
            &rerun::Points3D::new([location])
                .with_radii([0.006])
                .with_colors([{
                    let [r, g, b] = grasp_sim::render::GRASP_LOCATION_COLOR;
                    rerun::Color::from_rgb(r, g, b)
                }]),
        )?;
    }
    Ok(())
}

/// The stage as a scalar every step, and as text when it changes.
pub fn log_stage(
    rec: &RecordingStream,
    stage: &str,
    index: usize,
    changed: bool,
) -> RecordingStreamResult<()> {
    rec.log("crm/stage_index", &rerun::Scalars::single(index as f64))?;
    if changed {
        rec.log("crm/stage", &rerun::TextDocument::new(stage))?;
    }
    Ok(())
}

/// This step's intra-stage and transition rewards.
pub fn log_rewards(
    rec: &RecordingStream,
    intra: f32,
    transition: f32,
) -> RecordingStreamResult<()> {
    rec.log(
        "crm/reward/intra",
        &rerun::Scalars::single(f64::from(intra)),
    )?;
    rec.log(
        "crm/reward/transition",
        &rerun::Scalars::single(f64::from(transition)),
    )
}

/// One stage transition as a text log entry.
pub fn log_transition(
    rec: &RecordingStream,
    from: &str,
    to: &str,
    event: &str,
    reward: f32,
) -> RecordingStreamResult<()> {
    let level = match to {
        "success" => rerun::TextLogLevel::INFO,
        "fail" | "aor" | "gor" => rerun::TextLogLevel::WARN,
        _ => rerun::TextLogLevel::DEBUG,
    };
    rec.log(
        "crm/transitions",
        &rerun::TextLog::new(format!(
            "{from} -> {to} on {event}, transition reward {reward:+.1}"
        ))
        .with_level(level),
    )
}

/// How the episode ended, as a text log entry at `crm/episode`.
pub fn log_end(
    rec: &RecordingStream,
    stage: &str,
    steps: i64,
    truncated: bool,
) -> RecordingStreamResult<()> {
    let text = if truncated {
        format!("episode truncated in {stage} after {steps} steps (time limit)")
    } else {
        format!("episode ended in {stage} after {steps} steps")
    };
    rec.log(
        "crm/episode",
        &rerun::TextLog::new(text).with_level(rerun::TextLogLevel::INFO),
    )
}

/// One training iteration's series.
pub fn log_iteration(rec: &RecordingStream, it: &crm_api::Iteration) -> RecordingStreamResult<()> {
    rec.set_time_sequence("iteration", it.iteration as i64);
    rec.set_time_sequence("steps", it.steps as i64);
    let scalar = |path: &str, v: f64| rec.log(path, &rerun::Scalars::single(v));
    scalar("training/success_rate", it.success_rate_last_100)?;
    for (path, value) in [
        ("training/return/total", it.mean_return),
        ("training/return/intra_stage", it.mean_intra_return),
        ("training/return/transition", it.mean_transition_return),
        ("training/episode_length", it.mean_episode_length),
    ] {
        if let Some(value) = value {
            scalar(path, value)?;
        }
    }
    for (stage, share) in &it.stage_mix {
        scalar(&format!("training/stage_mix/{stage}"), *share)?;
    }
    for (task, success) in &it.task_success {
        scalar(&format!("training/task_success/{task}"), *success)?;
    }
    scalar("training/loss/policy", it.policy_loss)?;
    scalar("training/loss/value", it.value_loss)?;
    scalar("training/entropy", it.entropy)?;
    scalar("training/steps_per_s", it.steps_per_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cylinder_fix_maps_z_onto_y() {
        // Rotating (0, 0, 1) by Z_TO_Y gives (0, 1, 0): q v q*.
        let v = [0.0, 0.0, 1.0, 0.0];
        let conj = [-Z_TO_Y[0], -Z_TO_Y[1], -Z_TO_Y[2], Z_TO_Y[3]];
        let r = multiply(multiply(Z_TO_Y, v), conj);
        assert!(
            r[0].abs() < 1e-6 && (r[1] - 1.0).abs() < 1e-6 && r[2].abs() < 1e-6,
            "{r:?}"
        );
        // Identity stays identity.
        assert_eq!(multiply([0.0, 0.0, 0.0, 1.0], Z_TO_Y), Z_TO_Y);
    }
}
