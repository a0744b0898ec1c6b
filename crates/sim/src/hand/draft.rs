//! A first hand profile drafted from a description alone (`crm world init`): the palm, the
//! finger chains, their command joints and couplings, ranges from the joints' limits, the
//! contact links, the axes and a grasp point from the palm's geometry. Every guess is listed
//! in [`Draft::notes`] for the user to confirm; the draft passes [`super::HandModel::new`].
//!
//! The rules, in order: the palm is the first link, from the description's root, where three
//! or more moving chains branch (or the one named); each chain follows its longest branch; a
//! joint whose axis is parallel (|cos| > 0.7) to its chain's last joint flexes, any other
//! (spread, opposition) is held at 0; the thumb is the chain named so (`th`, `thumb`), else the
//! one whose last joint turns about an axis the others do not share, else the chain farthest
//! from the others; the other fingers, along the row of their tips from the end nearer the
//! thumb, are index, middle, ring and little (a hand with three leaves `little` out; a little
//! finger on a metacarpal that starts low in the palm stays last). A finger's second flexion
//! joint is its command (the paper's PIP), the first follows at the paper's `mcp`, the third at
//! `dip`; the thumb's first is its command (TMCP), its last follows at `ip`. The description's
//! couplings come first: the joint a chain's other joints follow (URDF `<mimic>`, MJCF joint
//! equalities) is its command, whatever its place, its range its own limits, and each joint
//! that follows it keeps the description's multiplier and offset and is never held.

use std::collections::BTreeMap;

use rapier3d::prelude::*;

use super::description::{Description, JointKind};
use super::profile::{Coupled, Finger, Fingers, Motor, Profile, Ratio, TopologyShape, Wrist};
use crate::taxonomy::Topology;

/// A drafted profile and what the user must confirm.
#[derive(Clone, Debug)]
pub struct Draft {
    pub profile: Profile,
    pub notes: Vec<String>,
}

/// A moving chain below the palm: its revolute joints (indices into the description's joints,
/// proximal first) and where its first joint sits (description frame).
struct Chain {
    joints: Vec<usize>,
    base: Vec3,
    /// Where its last joint sits at rest: the fingertips' row, which a finger starting lower
    /// in the palm (a little finger's metacarpal) keeps.
    tip: Vec3,
}

/// Drafts a profile for `description` (named `file` in the profile). `palm` overrides the
/// palm the rules would pick.
pub fn draft(description: &Description, file: &str, palm: Option<&str>) -> Result<Draft, String> {
    let mut notes = Vec::new();
    let children = |link: usize| -> Vec<usize> {
        (0..description.joints.len())
            .filter(|&j| description.joints[j].parent == link)
            .collect()
    };
    // Moving joints in the subtree below `joint` (itself included).
    fn moving_below(d: &Description, joint: usize) -> usize {
        let own = usize::from(d.joints[joint].kind != JointKind::Fixed);
        own + (0..d.joints.len())
            .filter(|&j| d.joints[j].parent == d.joints[joint].child)
            .map(|j| moving_below(d, j))
            .sum::<usize>()
    }
    let palm = match palm {
        Some(name) => description.link(name).ok_or_else(|| {
            format!(
                "the description has no link {name:?}{}",
                super::names::did_you_mean(name, description.links.iter().map(|l| l.name.as_str()))
            )
        })?,
        None => {
            let roots: Vec<usize> = (0..description.links.len())
                .filter(|&l| description.joints.iter().all(|j| j.child != l))
                .collect();
            // An MJCF palm welded to the world (no joint) is a root of its own beside the
            // world body: start from the root with the most moving joints below it.
            let moving_under = |link: usize| -> usize {
                children(link)
                    .into_iter()
                    .map(|j| moving_below(description, j))
                    .sum()
            };
            let mut link = *roots
                .iter()
                .max_by_key(|&&r| (moving_under(r), std::cmp::Reverse(r)))
                .ok_or("the description has no root link")?;
            loop {
                let branches: Vec<usize> = children(link)
                    .into_iter()
                    .filter(|&j| moving_below(description, j) > 0)
                    .collect();
                if branches.len() >= 3 {
                    break link;
                }
                let Some(&next) = branches
                    .iter()
                    .max_by_key(|&&j| moving_below(description, j))
                    .or(children(link).first())
                else {
                    return Err(format!(
                        "no link has three or more moving chains below it (reached {:?}); name the palm with --palm",
                        description.links[link].name
                    ));
                };
                link = description.joints[next].child;
            }
        }
    };
    let palm_pose = description.links[palm].rest;
    let axis_of = |j: usize| {
        let joint = &description.joints[j];
        (description.links[joint.parent].rest * joint.frame1).rotation * Vec3::X
    };
    let origin_of = |j: usize| {
        let joint = &description.joints[j];
        (description.links[joint.parent].rest * joint.frame1).translation
    };
    let mut chains: Vec<Chain> = Vec::new();
    for start in children(palm) {
        if moving_below(description, start) == 0 {
            continue;
        }
        let mut joints = Vec::new();
        let mut at = Some(start);
        while let Some(j) = at {
            if description.joints[j].kind == JointKind::Revolute {
                joints.push(j);
            }
            at = children(description.joints[j].child)
                .into_iter()
                .filter(|&k| moving_below(description, k) > 0)
                .max_by_key(|&k| moving_below(description, k));
        }
        if !joints.is_empty() {
            chains.push(Chain {
                base: origin_of(joints[0]),
                tip: origin_of(*joints.last().unwrap_or(&joints[0])),
                joints,
            });
        }
    }
    if !(3..=5).contains(&chains.len()) {
        return Err(format!(
            "{} moving chains below the palm {:?}; a hand has a thumb and two to four fingers (name the palm with --palm)",
            chains.len(),
            description.links[palm].name
        ));
    }
    notes.push(format!(
        "palm: {:?}, where {} moving chains branch",
        description.links[palm].name,
        chains.len()
    ));

    // The thumb: named so, else the chain farthest from the others.
    let named = |c: &Chain| {
        c.joints.iter().any(|&j| {
            let name = description.joints[j].name.to_lowercase();
            name.contains("thumb") || name.starts_with("th") || name.contains("_th")
        })
    };
    let thumb = match chains.iter().position(named) {
        Some(t) => {
            notes.push(format!(
                "thumb: the chain of {:?} (named so)",
                description.joints[chains[t].joints[0]].name
            ));
            t
        }
        None => {
            // The thumb opposes: its last joint turns about an axis the fingers' do not share.
            let flex = |c: &Chain| axis_of(*c.joints.last().unwrap_or(&c.joints[0]));
            let alignment = |t: usize| {
                chains
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| *k != t)
                    .map(|(_, c)| flex(c).dot(flex(&chains[t])).abs())
                    .sum::<f32>()
                    / (chains.len() - 1) as f32
            };
            let mut order: Vec<usize> = (0..chains.len()).collect();
            order.sort_by(|&a, &b| alignment(a).total_cmp(&alignment(b)));
            let (least, next) = (order[0], order[1]);
            if alignment(next) - alignment(least) > 0.3 {
                notes.push(format!(
                    "thumb: the chain of {:?}, whose joints turn about an axis the other chains' do not share",
                    description.joints[chains[least].joints[0]].name
                ));
                least
            } else {
                let spread = |t: usize| {
                    chains
                        .iter()
                        .enumerate()
                        .filter(|(k, _)| *k != t)
                        .map(|(_, c)| (c.base - chains[t].base).length())
                        .sum::<f32>()
                };
                let t = (0..chains.len())
                    .max_by(|&a, &b| spread(a).total_cmp(&spread(b)))
                    .unwrap_or(0);
                notes.push(format!(
                    "thumb: the chain of {:?}, the farthest from the others (no chain is named thumb or turns apart)",
                    description.joints[chains[t].joints[0]].name
                ));
                t
            }
        }
    };
    // The fingers' tips stand in a row across the way the fingers point: ordered along it
    // from the end nearer the thumb. (Across: a shorter finger, a finger on a metacarpal
    // that starts low in the palm, and the thumb's place along the palm do not tilt it.)
    let thumb_base = chains[thumb].base;
    let mut others: Vec<usize> = (0..chains.len()).filter(|&k| k != thumb).collect();
    let pointing = others
        .iter()
        .map(|&k| (chains[k].tip - chains[k].base).normalize_or_zero())
        .sum::<Vec3>()
        .normalize_or_zero();
    let across = |v: Vec3| v - pointing * v.dot(pointing);
    let mut ends = (others[0], others[1]);
    for &a in &others {
        for &b in &others {
            let far = across(chains[ends.1].tip - chains[ends.0].tip).length();
            if across(chains[b].tip - chains[a].tip).length() > far {
                ends = (a, b);
            }
        }
    }
    let row = across(chains[ends.1].tip - chains[ends.0].tip).normalize_or_zero();
    let at = |k: usize| chains[k].tip.dot(row);
    let thumb_at = thumb_base.dot(row);
    let from_first = (at(ends.0) - thumb_at).abs() <= (at(ends.1) - thumb_at).abs();
    others.sort_by(|&a, &b| {
        let order = at(a).total_cmp(&at(b));
        if from_first { order } else { order.reverse() }
    });

    // Each finger: flexion joints, command, couplings, range, links.
    let mut held_spreads = Vec::new();
    let mut finger = |chain: &Chain, is_thumb: bool, name: &str| -> Result<Finger, String> {
        let last = axis_of(*chain.joints.last().unwrap_or(&chain.joints[0]));
        let (flex, spread): (Vec<usize>, Vec<usize>) = chain
            .joints
            .iter()
            .partition(|&&j| axis_of(j).dot(last).abs() > 0.7);
        held_spreads.extend(spread.iter().map(|&j| description.joints[j].name.clone()));
        // The joint the description makes the chain's others follow leads it: it is the
        // command. Else the paper's: the thumb's first flexion joint, a finger's second.
        let followers = |leader: usize| {
            chain
                .joints
                .iter()
                .filter(|&&j| {
                    description.joints[j]
                        .mimic
                        .as_ref()
                        .is_some_and(|m| m.leader == description.joints[leader].name)
                })
                .count()
        };
        let leader = flex
            .iter()
            .copied()
            .filter(|&l| followers(l) > 0)
            .max_by_key(|&l| followers(l));
        let command = match leader {
            Some(leader) => leader,
            None if is_thumb || flex.len() < 2 => flex[0],
            None => flex[1],
        };
        let command_name = description.joints[command].name.clone();
        let mut joints = Vec::new();
        for &j in &chain.joints {
            let joint = &description.joints[j];
            // A joint that follows the command in the description follows it so, whatever
            // its place: never held, its multiplier and offset the description's.
            if let Some(m) = joint.mimic.as_ref().filter(|m| m.leader == command_name) {
                notes.push(format!(
                    "{name}: {:?} follows {command_name:?} as the description couples it: {} x + {}",
                    joint.name, m.ratio, m.offset
                ));
                held_spreads.retain(|h| *h != joint.name);
                joints.push(Coupled {
                    joint: joint.name.clone(),
                    ratio: Some(Ratio::Named("description".into())),
                    offset: None,
                    torque: None,
                });
                continue;
            }
            // A spread joint (not a flexion) is held (`held_spreads` above).
            let Some(k) = flex.iter().position(|&f| f == j) else {
                continue;
            };
            let paper = match (is_thumb, k) {
                _ if j == command => None,
                (true, k) if k + 1 == flex.len() => Some("ip"),
                (false, 0) => Some("mcp"),
                (false, 2) => Some("dip"),
                _ => {
                    held_spreads.push(joint.name.clone());
                    continue;
                }
            };
            let ratio = paper.map(|p| Ratio::Named(p.into()));
            joints.push(Coupled {
                joint: joint.name.clone(),
                ratio,
                offset: None,
                torque: None,
            });
        }
        let range = match description.joints[command].limits {
            Some([lo, hi]) if hi > 0.0 => [lo.max(0.0).min(hi), hi],
            Some([lo, hi]) => [lo, hi],
            None => {
                notes.push(format!(
                    "{name}: {command_name:?} has no limits; the range [0, 1.5] is a guess"
                ));
                [0.0, 1.5]
            }
        };
        notes.push(format!(
            "{name}: command {command_name:?} over [{}, {}], joints {}",
            range[0],
            range[1],
            joints
                .iter()
                .map(|c| match &c.ratio {
                    Some(Ratio::Named(r)) => format!("{:?} ({r})", c.joint),
                    _ => format!("{:?}", c.joint),
                })
                .collect::<Vec<_>>()
                .join(", ")
        ));
        Ok(Finger {
            command: command_name,
            range,
            joints,
            links: Vec::new(),
        })
    };
    let names = ["index", "middle", "ring", "little"];
    let thumb_finger = finger(&chains[thumb], true, "thumb")?;
    let mut fingers: Vec<Finger> = Vec::new();
    for (&k, name) in others.iter().zip(names) {
        fingers.push(finger(&chains[k], false, name)?);
    }
    if others.len() < 4 {
        notes.push(format!(
            "a {}-finger hand: {} left out, its action masked",
            others.len() + 1,
            names[others.len()..].join(" and ")
        ));
    }
    // Held joints rest at 0, or at the limit nearest 0 where 0 is beyond their limits.
    let mut held = BTreeMap::new();
    for name in &held_spreads {
        let limits = description
            .joints
            .iter()
            .find(|j| &j.name == name)
            .and_then(|j| j.limits);
        if let Some([lo, hi]) = limits
            && !(lo..=hi).contains(&0.0)
        {
            let nearest = if lo > 0.0 { lo } else { hi };
            held.insert(name.clone(), (nearest * 1e3).round() / 1e3);
        }
    }
    if !held_spreads.is_empty() {
        let at_limits: Vec<String> = held.iter().map(|(n, v)| format!("{n} at {v}")).collect();
        notes.push(format!(
            "held at 0 (spread, opposition or extra joints; set `held` to another angle): {}{}",
            held_spreads.join(", "),
            if at_limits.is_empty() {
                String::new()
            } else {
                format!(
                    "; where 0 is beyond a joint's limits, at the nearest: {}",
                    at_limits.join(", ")
                )
            }
        ));
    }

    // Axes in the palm frame: fingers point from their first joint to their last (from the
    // palm to their bases for one-joint fingers); the approach axis is where the index closes
    // (its tip's motion under a positive turn of its last joint).
    let to_palm = palm_pose.rotation.inverse();
    let pointing = others
        .iter()
        .map(|&k| {
            let chain = &chains[k];
            let last = origin_of(*chain.joints.last().unwrap_or(&chain.joints[0]));
            let along = last - chain.base;
            if along.length() > 1e-4 {
                along.normalize()
            } else {
                (chain.base - palm_pose.translation).normalize_or_zero()
            }
        })
        .sum::<Vec3>();
    let along = (to_palm * pointing).normalize_or_zero();
    let index = &chains[others[0]];
    let turn = to_palm * axis_of(*index.joints.last().unwrap_or(&index.joints[0]));
    let closing = turn.cross(along);
    let approach = (closing - along * closing.dot(along)).normalize_or_zero();
    if along == Vec3::ZERO || approach == Vec3::ZERO {
        return Err("the fingers' directions could not be found from the joints' frames".into());
    }
    // The grasp point: 3 cm off the palm's face along the approach, over the palm's centre.
    let aabb = description.links[palm]
        .shapes
        .iter()
        .map(|(pose, shape)| shape.compute_aabb(pose))
        .reduce(|a, b| a.merged(&b));
    let (centre, depth) = match aabb {
        Some(aabb) => (aabb.center(), aabb.half_extents().dot(approach.abs())),
        None => (Vec3::ZERO, 0.0),
    };
    let grasp = centre + approach * (depth + 0.03);
    let round = |v: Vec3| v.to_array().map(|x| (x * 1e4).round() / 1e4);
    notes.push(format!(
        "finger_axis {:?}, approach_axis {:?}, grasp_point {:?} (palm frame: 3 cm off the palm's face); try it with `crm oracle --world DIR`",
        round(along),
        round(approach),
        round(grasp)
    ));

    let all: Vec<&str> = std::iter::once("thumb")
        .chain(names.iter().copied().take(fingers.len()))
        .collect();
    let ranges: BTreeMap<&str, [f32; 2]> = std::iter::once(("thumb", thumb_finger.range))
        .chain(names.iter().copied().zip(fingers.iter().map(|f| f.range)))
        .collect();
    let shape = |active: &[&str]| TopologyShape {
        active: active.iter().map(|s| s.to_string()).collect(),
        preshape: BTreeMap::new(),
        closed: active
            .iter()
            .map(|&f| {
                let [lo, hi] = ranges[f];
                (f.to_string(), ((lo + 0.8 * (hi - lo)) * 1e3).round() / 1e3)
            })
            .collect(),
        held: BTreeMap::new(),
        grasp_point: None,
    };
    let mut topologies = BTreeMap::new();
    topologies.insert(Topology::Platform, TopologyShape::default());
    for (topology, active) in [
        (Topology::PoPmAb25, &all[..]),
        (Topology::PPdAb2, &all[..2]),
        (Topology::PPdAb23, &all[..3]),
        (Topology::PPdAb25, &all[..]),
        (Topology::InSiAd2, &all[..2]),
    ] {
        topologies.insert(topology, shape(active));
    }
    notes.push(
        "topologies: every finger in poPmAb25 and pPdAb25, thumb and index in pPdAb2 and InSiAd2, \
         and the middle in pPdAb23; the oracle closes each to 80% of its range"
            .into(),
    );
    let mut fingers = fingers.into_iter();
    let index = fingers.next().ok_or("no index finger")?;
    let middle = fingers.next().ok_or("no middle finger")?;
    let profile = Profile {
        description: file.to_string(),
        palm: description.links[palm].name.clone(),
        palm_links: Vec::new(),
        grasp_point: round(grasp),
        approach_axis: round(approach),
        finger_axis: round(along),
        grasp_frame: None,
        // The built-in hand's (worlds/crm/hand.json).
        friction: 1.0,
        wrist: Wrist::BUILTIN,
        motor: Motor::BUILTIN,
        fingers: Fingers {
            thumb: thumb_finger,
            index,
            middle: Some(middle),
            ring: fingers.next(),
            little: fingers.next(),
        },
        topologies,
        relaxed: BTreeMap::new(),
        held,
        description_overrides: Vec::new(),
    };
    Ok(Draft { profile, notes })
}
