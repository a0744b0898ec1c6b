//! One of the paper's five finger actions on a hand: the profile's finger checked against the
//! description (the commanded joint, each coupled joint's ratio: a number, a paper coupling
//! by name, or the description's own).

use super::description::{Description, JointKind};
use super::model::ModelJoint;
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
}

#[allow(clippy::too_many_arguments)]
pub(super) fn finger_model(
    f: usize,
    finger: &Finger,
    at: &str,
    description: &Description,
    joints: &mut [ModelJoint],
    link_index: &dyn Fn(&str) -> Option<usize>,
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
                format!("the hand has no joint {:?} below the palm", entry.joint),
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
    if !finger.links.is_empty() {
        links.clear();
        for (k, name) in finger.links.iter().enumerate() {
            links.push(link_index(name).ok_or_else(|| {
                invalid(
                    format!("{at}.links[{k}]"),
                    format!("the hand has no link {name:?} below the palm"),
                )
            })?);
        }
    }
    Ok(FingerModel {
        range: finger.range,
        coupled,
        links,
    })
}
