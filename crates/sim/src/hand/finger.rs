//! One of the paper's five finger actions on a hand: the profile's finger checked against the
//! description (the commanded joint, each coupled joint's ratio: a number, a paper coupling
//! by name, or the description's own).

use super::description::{Description, JointKind};
use super::model::ModelJoint;
use super::names::did_you_mean;
use super::profile::{Finger, Ratio};
use super::{ALPHA_DIP, ALPHA_MCP, ALPHA_TMCP};
use crate::error::{Error, Result};

/// One of the paper's five finger actions on this hand.
#[derive(Clone, Debug)]
pub struct FingerModel {
    /// `[open, closed]` command range (rad).
    pub range: [f32; 2],
    /// `(joint, ratio, offset)`: each follows `ratio * command + offset`, proximal first.
    pub coupled: Vec<(usize, f32, f32)>,
    /// Links whose contacts count as the finger's, proximal first.
    pub links: Vec<usize>,
    /// Whether the hand has this finger (a four-finger hand's profile leaves one out).
    pub present: bool,
}

impl FingerModel {
    /// A finger the hand lacks: no joints, no links, a command range of zero.
    pub fn absent() -> Self {
        Self {
            range: [0.0, 0.0],
            coupled: Vec::new(),
            links: Vec::new(),
            present: false,
        }
    }
}

#[allow(clippy::too_many_arguments)]
pub(super) fn finger_model(
    f: usize,
    finger: &Finger,
    at: &str,
    description: &Description,
    joints: &mut [ModelJoint],
    link_index: &dyn Fn(&str) -> Option<usize>,
    link_names: &[String],
    invalid: &dyn Fn(String, String) -> Error,
) -> Result<FingerModel> {
    let [lo, hi] = finger.range;
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(invalid(
            format!("{at}.range"),
            format!("must be finite with open < closed, got {:?}", finger.range),
        ));
    }
    if finger.joints.is_empty() {
        return Err(invalid(
            format!("{at}.joints"),
            "a finger needs at least one joint".into(),
        ));
    }
    if !finger.joints.iter().any(|c| c.joint == finger.command) {
        return Err(invalid(
            format!("{at}.command"),
            format!("{:?} must be one of the finger's joints", finger.command),
        ));
    }
    let mut coupled = Vec::new();
    let mut links = Vec::new();
    for (k, entry) in finger.joints.iter().enumerate() {
        let field = format!("{at}.joints[{k}]");
        let Some(j) = joints.iter().position(|j| j.name == entry.joint) else {
            return Err(invalid(
                format!("{field}.joint"),
                format!(
                    "the hand has no joint {:?} below the palm{}",
                    entry.joint,
                    did_you_mean(&entry.joint, joints.iter().map(|j| j.name.as_str()))
                ),
            ));
        };
        if joints[j].kind != JointKind::Revolute {
            return Err(invalid(
                format!("{field}.joint"),
                "a finger joint must be revolute".into(),
            ));
        }
        let mimic = description
            .joint(&entry.joint)
            .and_then(|d| description.joints[d].mimic.clone())
            .filter(|m| m.leader == finger.command);
        let ratio = match &entry.ratio {
            Some(Ratio::Value(value)) => *value,
            Some(Ratio::Named(name)) => match (name.as_str(), f) {
                ("pip", _) | ("tmcp", _) => 1.0,
                ("mcp", 1..) => ALPHA_MCP,
                ("dip", 1..) => ALPHA_DIP[f - 1],
                ("ip", 0) => ALPHA_TMCP,
                ("description", _) => mimic.as_ref().map(|m| m.ratio).ok_or_else(|| {
                    invalid(
                        format!("{field}.ratio"),
                        format!(
                            "the description declares no coupling of {:?} to {:?}",
                            entry.joint, finger.command
                        ),
                    )
                })?,
                _ => {
                    return Err(invalid(
                        format!("{field}.ratio"),
                        format!(
                            "{name:?} is not a coupling of this finger (pip, tmcp, mcp, dip, ip, description)"
                        ),
                    ));
                }
            },
            None if entry.joint == finger.command => 1.0,
            None => mimic.as_ref().map(|m| m.ratio).ok_or_else(|| {
                invalid(
                    format!("{field}.ratio"),
                    "needed: the description declares no coupling for this joint".into(),
                )
            })?,
        };
        let offset = entry
            .offset
            .or_else(|| mimic.as_ref().map(|m| m.offset))
            .unwrap_or(0.0);
        if !(ratio.is_finite() && offset.is_finite()) {
            return Err(invalid(format!("{field}.ratio"), "must be finite".into()));
        }
        if let Some(torque) = entry.torque {
            if !(torque.is_finite() && torque > 0.0) {
                return Err(invalid(
                    format!("{field}.torque"),
                    format!("must be positive, got {torque}"),
                ));
            }
            joints[j].torque = torque;
        }
        coupled.push((j, ratio, offset));
        links.push(joints[j].child);
    }
    check_reach(finger, &coupled, joints, at, invalid)?;
    if !finger.links.is_empty() {
        links.clear();
        for (k, name) in finger.links.iter().enumerate() {
            links.push(link_index(name).ok_or_else(|| {
                invalid(
                    format!("{at}.links[{k}]"),
                    format!(
                        "the hand has no link {name:?} below the palm{}",
                        did_you_mean(name, link_names.iter().map(String::as_str))
                    ),
                )
            })?);
        }
    }
    Ok(FingerModel {
        range: finger.range,
        coupled,
        links,
        present: true,
    })
}

/// How far past a joint's limits a profile may put it (rad): the description's own rounding.
const LIMIT_SLACK: f32 = 1e-3;

/// Refuses a command range some end of which moves none of the finger's joints: past where
/// every coupled joint has reached its limit the command does nothing. A joint may saturate
/// before the end while another still closes, as the authors' SVH commands run (their PIP
/// stops at 0.985 rad while the thumb's IP closes to 2.812 x 0.5).
fn check_reach(
    finger: &Finger,
    coupled: &[(usize, f32, f32)],
    joints: &[ModelJoint],
    at: &str,
    invalid: &dyn Fn(String, String) -> Error,
) -> Result<()> {
    let (mut low, mut high) = (f32::INFINITY, f32::NEG_INFINITY);
    for &(j, ratio, offset) in coupled {
        let Some([lo, hi]) = joints[j].limits.filter(|_| ratio != 0.0) else {
            // A joint without limits (or not coupled) moves over any command.
            return Ok(());
        };
        let (a, b) = ((lo - offset) / ratio, (hi - offset) / ratio);
        low = low.min(a.min(b));
        high = high.max(a.max(b));
    }
    let [open, closed] = finger.range;
    for (end, command) in [("open", open), ("closed", closed)] {
        if command < low - LIMIT_SLACK || command > high + LIMIT_SLACK {
            let limits: Vec<String> = coupled
                .iter()
                .filter_map(|&(j, _, _)| {
                    let [lo, hi] = joints[j].limits?;
                    Some(format!("{:?} [{lo}, {hi}]", joints[j].name))
                })
                .collect();
            return Err(invalid(
                format!("{at}.range"),
                format!(
                    "the {end} command {command} is beyond the description's joint limits: the \
                     finger's joints move only for commands in [{low}, {high}] ({})",
                    limits.join(", ")
                ),
            ));
        }
    }
    Ok(())
}

/// `None` when `angle` is within the joint's limits (or it has none), else what they are.
pub(super) fn beyond_limits(joint: &ModelJoint, angle: f32) -> Option<String> {
    let [lo, hi] = joint.limits?;
    (angle < lo - LIMIT_SLACK || angle > hi + LIMIT_SLACK)
        .then(|| format!("beyond the description's limits [{lo}, {hi}] of that joint"))
}
