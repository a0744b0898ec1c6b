//! The profile's couplings against the description's: a joint the description couples to
//! another (URDF `<mimic>`, MJCF joint equalities, Adroit's tendons) that the profile couples
//! otherwise (another multiplier or offset, another leader), makes a finger's command, or
//! holds still contradicts the hand's maker. `crm world check` refuses such a profile unless it
//! lists the joint in `description_overrides` (the override is kept out of the world's hash:
//! it changes nothing the hand does).

use std::collections::BTreeMap;

use super::description::Description;
use super::model::HandModel;
use super::profile::Profile;

/// One joint whose profile coupling differs from its description's.
#[derive(Clone, Debug, PartialEq)]
pub struct Conflict {
    pub joint: String,
    /// The description's coupling, as `J = r x L + o`.
    pub description: String,
    /// What the profile does with the joint instead.
    pub profile: String,
    /// The profile field that does it.
    pub field: String,
}

impl std::fmt::Display for Conflict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "joint {:?}: the description couples it as {}; the profile ({}) {}",
            self.joint, self.description, self.field, self.profile
        )
    }
}

/// What [`check`] found: the conflicts the profile does not override, the ones it does, and
/// the overrides that name a joint without a conflict.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Couplings {
    pub conflicts: Vec<Conflict>,
    pub overridden: Vec<Conflict>,
    pub needless: Vec<String>,
}

fn coupling(joint: &str, ratio: f32, leader: &str, offset: f32) -> String {
    format!("{joint} = {ratio} x {leader} + {offset}")
}

/// Whether two couplings' numbers differ beyond rounding in a description's text.
fn differ(a: f32, b: f32) -> bool {
    (a - b).abs() > 1e-4 * a.abs().max(b.abs()).max(1.0)
}

/// Compares the profile's couplings (as `model` resolved them) with `description`'s.
pub fn check(description: &Description, profile: &Profile, model: &HandModel) -> Couplings {
    let declared = |name: &str| {
        description
            .joint(name)
            .and_then(|d| description.joints[d].mimic.clone())
    };
    let mut found = Vec::new();
    let names = crate::view::FINGERS;
    for (f, finger) in profile.fingers.all().into_iter().enumerate() {
        let Some(finger) = finger else {
            continue;
        };
        for (k, (entry, &(_, ratio, offset))) in finger
            .joints
            .iter()
            .zip(&model.fingers[f].coupled)
            .enumerate()
        {
            let Some(mimic) = declared(&entry.joint) else {
                continue;
            };
            let theirs = coupling(&entry.joint, mimic.ratio, &mimic.leader, mimic.offset);
            if entry.joint == finger.command {
                found.push(Conflict {
                    joint: entry.joint.clone(),
                    description: theirs,
                    profile: format!("makes it the {} finger's command", names[f]),
                    field: format!("fingers.{}.command", names[f]),
                });
            } else if mimic.leader != finger.command
                || differ(ratio, mimic.ratio)
                || differ(offset, mimic.offset)
            {
                found.push(Conflict {
                    joint: entry.joint.clone(),
                    description: theirs,
                    profile: format!(
                        "couples it as {}",
                        coupling(&entry.joint, ratio, &finger.command, offset)
                    ),
                    field: format!("fingers.{}.joints[{k}]", names[f]),
                });
            }
        }
    }
    // Held joints, each once with the angles and topologies it is held at.
    let mut held: BTreeMap<usize, Vec<(f32, &str)>> = BTreeMap::new();
    for topology in crate::taxonomy::Topology::ALL {
        for &(j, angle) in model.held(topology) {
            held.entry(j).or_default().push((angle, topology.name()));
        }
    }
    for (j, angles) in held {
        let name = &model.joints[j].name;
        let Some(mimic) = declared(name) else {
            continue;
        };
        let mut distinct: Vec<f32> = angles.iter().map(|(a, _)| *a).collect();
        distinct.sort_by(f32::total_cmp);
        distinct.dedup();
        let at = distinct
            .iter()
            .map(|a| a.to_string())
            .collect::<Vec<_>>()
            .join(", ");
        found.push(Conflict {
            joint: name.clone(),
            description: coupling(name, mimic.ratio, &mimic.leader, mimic.offset),
            profile: format!("holds it at {at}"),
            field: if profile.held.contains_key(name) {
                format!("held.{name}")
            } else {
                "held (no finger commands it, so it is held at 0)".into()
            },
        });
    }
    let (overridden, conflicts) = found
        .into_iter()
        .partition(|c| profile.description_overrides.contains(&c.joint));
    let overridden: Vec<Conflict> = overridden;
    let needless = profile
        .description_overrides
        .iter()
        .filter(|name| !overridden.iter().any(|c| &c.joint == *name))
        .cloned()
        .collect();
    Couplings {
        conflicts,
        overridden,
        needless,
    }
}
