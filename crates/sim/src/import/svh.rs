//! The hand profile of the right Schunk SVH in the authors' `robots/dual_2hand.urdf`, as their
//! `crm_ppo/Helper.py` and `Dualcontrol.py` drive it: each finger's PIP is the commanded joint,
//! MCP follows at 0.67 and DIP at the finger's own ratio, every joint clamped at its limit
//! (`finger_model_*`); the thumb's opposition and the spreads are set per topology and held.
//! The numbers below are theirs (Helper.py at 692dedc, the lines are named), not copied files.

use std::collections::BTreeMap;

use rapier3d::math::{Rotation, Vec3};

use crate::benchmark::Topology;
use crate::hand::description::Description;
use crate::hand::profile::{Coupled, Finger, Fingers, Motor, Profile, Ratio, TopologyShape, Wrist};

/// The description, relative to the repository.
pub const DESCRIPTION: &str = "robots/dual_2hand.urdf";
/// The hand's base: everything above it (the UR5 arm) is replaced by our wrist.
pub const PALM: &str = "right_hand_base_link";
/// The link the authors' IK places (PyBullet link 90, `dualEndEffectorIndex`): a task's
/// `Trans` and `Orientation` are this link's pose in the object frame.
pub const END_EFFECTOR: &str = "right_hand_virtual_k";
/// `Helper.convert_hand`: the turn the authors apply after `q_obj ⊗ Orientation`, `[x, y, z,
/// w]` (180 degrees about (0, 1, 1)/sqrt 2).
/// Their literal 0.7071 is kept (it is normalized where used), so the profile's numbers, and
/// with them the world's hash, are the authors'.
#[allow(clippy::approx_constant)]
pub const CONVERT_HAND: [f32; 4] = [0.0, 0.7071, 0.7071, 0.0];

/// One finger: joints proximal first (MCP, PIP, DIP), the ratio of each to the PIP command
/// (`*_alpha_mcp`, 1, `*_alpha_dip`), the joint maxima (`*_joint_max`) and its links
/// (`thumbLinks`, `indexLinks`, ... by name).
struct SvhFinger {
    joints: [&'static str; 3],
    ratios: [f32; 3],
    max: [f32; 3],
    links: &'static [&'static str],
}

const FINGERS: [SvhFinger; 5] = [
    // Helper.py lines 120-122; Dualcontrol.finger_model_thumb: joints 80, 81, 82.
    SvhFinger {
        joints: ["right_hand_Thumb_Flexion", "right_hand_j3", "right_hand_j4"],
        ratios: [0.67, 1.0, 0.5],
        max: [0.9704, 0.98506, 1.406],
        links: &[
            "right_hand_z",
            "right_hand_a",
            "right_hand_b",
            "right_hand_c",
        ],
    },
    // Lines 98-100: joints 87, 88, 89.
    SvhFinger {
        joints: [
            "right_hand_Index_Finger_Proximal",
            "right_hand_Index_Finger_Distal",
            "right_hand_j14",
        ],
        ratios: [0.67, 1.0, 0.77],
        max: [0.79849, 1.334, 1.394],
        links: &["right_hand_l", "right_hand_p", "right_hand_t"],
    },
    // Lines 103-105: joints 91, 92, 93.
    SvhFinger {
        joints: [
            "right_hand_Middle_Finger_Proximal",
            "right_hand_Middle_Finger_Distal",
            "right_hand_j15",
        ],
        ratios: [0.67, 1.0, 0.75],
        max: [0.79849, 1.334, 1.334],
        links: &["right_hand_k", "right_hand_o", "right_hand_s"],
    },
    // Lines 108-110: joints 104, 105, 106.
    SvhFinger {
        joints: ["right_hand_Ring_Finger", "right_hand_j12", "right_hand_j16"],
        ratios: [0.67, 1.0, 0.75],
        max: [0.98175, 1.334, 1.395],
        links: &["right_hand_j", "right_hand_n", "right_hand_r"],
    },
    // Lines 114-116: joints 99, 100, 101.
    SvhFinger {
        joints: ["right_hand_Pinky", "right_hand_j13", "right_hand_j17"],
        ratios: [0.67, 1.0, 0.57],
        max: [0.98175, 1.334, 1.3971],
        links: &["right_hand_i", "right_hand_m", "right_hand_q"],
    },
];

const NAMES: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];

/// The thumb's opposition joint, held per topology (see [`topologies`]).
const OPPOSITION: &str = "right_hand_Thumb_Opposition";

/// Per topology (Helper.py lines 149-184, the 19-joint grasp poses): the PIP commands the
/// fingers start the grasp stage from (elements 2, 6, 9, 17, 13), rounded to 1e-4, and which
/// fingers act (`Dualcontrol.applyAction`).
///
/// The thumb's opposition is held where the authors' code drives it, not at the pose's
/// element 0: `Dualcontrol.applyAction` sets joint 78 ([`OPPOSITION`]) to `self.grasp[6]`,
/// the pose's index PIP, in both stages, and PyBullet stops it at the joint's upper limit
/// (0.9879 in `dual_2hand.urdf`). Their hand reaches it within a second or two of the
/// approach; ours holds it from the start. In PyBullet, at the first grasp step of tasks 7
/// and 11, joint 78 reads 0.730 and 0.723.
fn topologies() -> [(Topology, [f32; 5], &'static [&'static str]); 6] {
    [
        (Topology::Platform, [0.0; 5], &[]),
        (
            Topology::InSiAd2,
            [0.0446, 1.1050, 1.1363, 1.0110, 0.9759],
            &["thumb"],
        ),
        (
            Topology::PPdAb2,
            [0.2693, 0.7690, 0.0, 0.0, 0.0],
            &["thumb", "index"],
        ),
        (
            Topology::PPdAb23,
            [0.2934, 0.7302, 0.7046, 0.0, 0.0],
            &["thumb", "index", "middle"],
        ),
        (
            Topology::PPdAb25,
            [0.2949, 0.7232, 0.7611, 0.7239, 0.5681],
            &["thumb", "index", "middle", "ring", "little"],
        ),
        (
            Topology::PoPmAb25,
            [0.2583, 0.7369, 0.8006, 0.7306, 0.6378],
            &["thumb", "index", "middle", "ring", "little"],
        ),
    ]
}

/// How far the scripted oracle closes a finger beyond its preshape (rad of PIP command).
const ORACLE_CLOSE: f32 = 0.6;

/// The profile, with the grasp point and frame taken from the description's rest poses.
pub fn profile(description: &Description) -> Result<Profile, String> {
    let rest = |name: &str| {
        description
            .link(name)
            .map(|i| description.links[i].rest)
            .ok_or_else(|| format!("{DESCRIPTION} has no link {name:?}"))
    };
    let palm = rest(PALM)?;
    let effector = palm.inverse() * rest(END_EFFECTOR)?;
    let [x, y, z, w] = CONVERT_HAND;
    let convert = Rotation::from_xyzw(x, y, z, w).normalize();
    let frame = effector.rotation * convert.inverse();
    let fingers: Vec<Finger> = FINGERS
        .iter()
        .map(|f| {
            // The authors clamp the PIP command at the largest of max / ratio (MCP, DIP).
            let top = (f.max[0] / f.ratios[0]).max(f.max[2] / f.ratios[2]);
            Finger {
                command: f.joints[1].into(),
                range: [0.0, round(top)],
                joints: f
                    .joints
                    .iter()
                    .zip(f.ratios)
                    .map(|(joint, ratio)| Coupled {
                        joint: (*joint).into(),
                        ratio: Some(Ratio::Value(ratio)),
                        offset: Some(0.0),
                        torque: None,
                    })
                    .collect(),
                links: f.links.iter().map(|l| (*l).into()).collect(),
            }
        })
        .collect();
    let [thumb, index, middle, ring, little]: [Finger; 5] =
        fingers.try_into().map_err(|_| "five fingers".to_string())?;
    let opposition_max = description
        .joint(OPPOSITION)
        .and_then(|j| description.joints[j].limits)
        .map(|[_, upper]| upper)
        .ok_or_else(|| {
            format!("{DESCRIPTION}: joint {OPPOSITION:?} is missing or has no limits")
        })?;
    let mut shapes = BTreeMap::new();
    for (topology, preshape, active) in topologies() {
        let opposition = preshape[1].min(opposition_max);
        let by_name = |values: [f32; 5]| -> BTreeMap<String, f32> {
            NAMES
                .iter()
                .zip(values)
                .filter(|(_, v)| *v != 0.0)
                .map(|(n, v)| ((*n).to_string(), v))
                .collect()
        };
        let closed = NAMES.map(|n| {
            let k = NAMES.iter().position(|m| *m == n).unwrap_or(0);
            if active.contains(&n) {
                round(preshape[k] + ORACLE_CLOSE)
            } else {
                0.0
            }
        });
        shapes.insert(
            topology,
            TopologyShape {
                active: active.iter().map(|n| (*n).to_string()).collect(),
                preshape: by_name(preshape),
                closed: by_name(closed),
                held: BTreeMap::from([(OPPOSITION.into(), opposition)]),
                grasp_point: None,
            },
        );
    }
    let v = |p: Vec3| [round(p.x), round(p.y), round(p.z)];
    let q = |r: Rotation| [r.x, r.y, r.z, r.w].map(round);
    Ok(Profile {
        description: DESCRIPTION.into(),
        palm: PALM.into(),
        // Helper.palmLinks: right_hand_[e1, e2, e3, e, e4].
        palm_links: ["e1", "e2", "e3", "e", "e4"]
            .iter()
            .map(|l| format!("right_hand_{l}"))
            .collect(),
        grasp_point: v(effector.translation),
        // The fingers close towards the base frame's +y and point along +z.
        approach_axis: [0.0, 1.0, 0.0],
        finger_axis: [0.0, 0.0, 1.0],
        grasp_frame: Some(q(frame)),
        // The objects' `lateral_friction` in every target.urdf.
        friction: 1.0,
        // The built-in hand's wrist (worlds/crm/hand.json). Motors stiffer than the built-in
        // hand's (3 N m/rad, 0.2 N m), for links of 25-410 g; the oracle over 3 seeds per task
        // hardly depends on them once fixed and held links are welded (0.506 with the
        // built-in hand's, 0.519 with these, with 0.3 N m, and with 30 N m/rad and 1 N m;
        // docs/notebook/worlds.md). The authors drive every joint by position at 100,000 N.
        wrist: Wrist::BUILTIN,
        motor: Motor {
            stiffness: 10.0,
            damping: 0.2,
            torque: 0.5,
            armature: None,
        },
        fingers: Fingers {
            thumb,
            index,
            middle: Some(middle),
            ring: Some(ring),
            little: Some(little),
        },
        topologies: shapes,
        // Dualcontrol.applyAction in stage 1: `relax` (Helper.py line 153), PIPs at 0.1.
        relaxed: NAMES.iter().map(|n| ((*n).to_string(), 0.1)).collect(),
        // Spreads at 0 in every grasp pose (elements 4, 11, 15); opposition per topology.
        held: BTreeMap::from([
            (OPPOSITION.into(), 0.0),
            ("right_hand_Finger_Spread".into(), 0.0),
            ("right_hand_index_spread".into(), 0.0),
            ("right_hand_ring_spread".into(), 0.0),
        ]),
        // Filled by the import from the couplings the authors' profile overrides.
        description_overrides: Vec::new(),
    })
}

/// Six decimals: the written profile reads the same on every machine.
fn round(v: f32) -> f32 {
    (v * 1e6).round() / 1e6
}
