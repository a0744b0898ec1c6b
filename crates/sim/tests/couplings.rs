//! Hands whose descriptions couple their joints (MJCF `<equality><joint>`, made here): `crm
//! world init` drafts from those couplings (a thumb whose two other joints follow its first, a
//! finger led by its first joint), and a profile that couples, commands or holds a coupled
//! joint otherwise is reported naming the joint and both couplings unless it overrides it by
//! name, which leaves the world's hash as it is. The draft names the fingers by their tips'
//! row, so a little finger on a metacarpal that starts low in the palm (as the Shadow hand's)
//! is still the little one.

use std::path::{Path, PathBuf};

use grasp_sim::World;
use grasp_sim::assets::Assets;
use grasp_sim::init::init_world;

/// A five-finger MJCF hand (the built-in hand's layout, Apache-2.0, written here) whose thumb
/// has three joints, the last two following the first, and whose fingers follow their first
/// joint (MuJoCo: `joint1 = polycoef[0] + polycoef[1] joint2`).
fn coupled_hand() -> String {
    let mut bodies = String::new();
    let finger = |name: &str, y: f32| {
        format!(
            r#"      <body name="{name}_proximal" pos="0.045 {y} -0.004">
        <joint name="{name}_mcp" type="hinge" axis="0 1 0" range="-0.2 1.6"/>
        <geom type="capsule" fromto="0 0 0 0.045 0 0" size="0.0085" mass="0.03"/>
        <body name="{name}_middle" pos="0.045 0 0">
          <joint name="{name}_pip" type="hinge" axis="0 1 0" range="-0.2 2.0"/>
          <geom type="capsule" fromto="0 0 0 0.028 0 0" size="0.008" mass="0.02"/>
          <body name="{name}_distal" pos="0.028 0 0">
            <joint name="{name}_dip" type="hinge" axis="0 1 0" range="-0.2 2.0"/>
            <geom type="capsule" fromto="0 0 0 0.022 0 0" size="0.0075" mass="0.015"/>
          </body>
        </body>
      </body>
"#
        )
    };
    let mut equalities = String::new();
    for (name, y) in [
        ("index", 0.03),
        ("middle", 0.01),
        ("ring", -0.01),
        ("little", -0.03),
    ] {
        bodies.push_str(&finger(name, y));
        equalities.push_str(&format!(
            "    <joint joint1=\"{name}_pip\" joint2=\"{name}_mcp\" polycoef=\"0.05 1.2 0 0 0\"/>\n    <joint joint1=\"{name}_dip\" joint2=\"{name}_mcp\" polycoef=\"0 0.7 0 0 0\"/>\n"
        ));
    }
    format!(
        r#"<mujoco model="coupled-hand">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>
    <body name="palm">
      <geom name="palm" type="box" size="0.045 0.042 0.012" mass="0.4"/>
      <body name="thumb_base" pos="-0.045 0.02 -0.004" quat="0 0 1 0">
        <joint name="thumb_cmc" type="hinge" axis="0 -1 0" range="-0.2 1.8"/>
        <geom type="capsule" fromto="0 0 0 0.03 0 0" size="0.0095" mass="0.03"/>
        <body name="thumb_proximal" pos="0.03 0 0">
          <joint name="thumb_mcp" type="hinge" axis="0 -1 0" range="-0.2 2.4"/>
          <geom type="capsule" fromto="0 0 0 0.035 0 0" size="0.009" mass="0.02"/>
          <body name="thumb_distal" pos="0.035 0 0">
            <joint name="thumb_ip" type="hinge" axis="0 -1 0" range="-0.2 2.4"/>
            <geom type="capsule" fromto="0 0 0 0.03 0 0" size="0.009" mass="0.02"/>
          </body>
        </body>
      </body>
{bodies}    </body>
  </worldbody>
  <equality>
    <joint joint1="thumb_mcp" joint2="thumb_cmc" polycoef="0.1 0.8 0 0 0"/>
    <joint joint1="thumb_ip" joint2="thumb_cmc" polycoef="0 0.6 0 0 0"/>
{equalities}  </equality>
</mujoco>
"#
    )
}

fn temp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("crm-couplings-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// Drafts a world for the coupled hand under `root`; returns its folder.
fn drafted(root: &Path) -> (PathBuf, Vec<String>) {
    let hand = root.join("assets/coupled.xml");
    std::fs::create_dir_all(hand.parent().expect("parent")).expect("assets");
    std::fs::write(&hand, coupled_hand()).expect("write the hand");
    let out = root.join("world");
    let assets = Assets::parse(&root.join("assets").display().to_string());
    let drafted = init_world(&hand, &out, None, None, &assets).expect("a draft");
    (out, drafted.notes)
}

fn load(root: &Path, dir: &Path) -> Result<World, String> {
    let assets = Assets::parse(&root.join("assets").display().to_string());
    World::load_with(dir, &assets).map_err(|e| e.to_string())
}

fn edit_profile(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("hand.json");
    let mut profile: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("hand.json")).expect("JSON");
    edit(&mut profile);
    std::fs::write(&path, serde_json::to_string_pretty(&profile).expect("JSON")).expect("write");
}

#[test]
fn an_mjcf_draft_commands_each_leader_and_couples_its_followers_as_described() {
    let root = temp("draft");
    let (dir, notes) = drafted(&root);
    let world = load(&root, &dir).expect("the draft loads");
    let profile: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("hand.json")).expect("profile"))
            .expect("JSON");
    // The thumb: its first joint commands, over its own limits; both others follow it.
    let thumb = &profile["fingers"]["thumb"];
    assert_eq!(thumb["command"], "thumb_cmc", "{thumb}");
    assert_eq!(thumb["range"], serde_json::json!([0.0, 1.8]));
    let coupled = |finger: &serde_json::Value, joint: &str| {
        finger["joints"]
            .as_array()
            .expect("joints")
            .iter()
            .find(|j| j["joint"] == joint)
            .cloned()
            .unwrap_or_else(|| panic!("{joint} coupled: {finger}"))
    };
    for joint in ["thumb_mcp", "thumb_ip"] {
        assert_eq!(coupled(thumb, joint)["ratio"], "description", "{joint}");
    }
    // A finger led by its first joint.
    let index = &profile["fingers"]["index"];
    assert_eq!(index["command"], "index_mcp", "{index}");
    assert_eq!(index["range"], serde_json::json!([0.0, 1.6]));
    for joint in ["index_pip", "index_dip"] {
        assert_eq!(coupled(index, joint)["ratio"], "description", "{joint}");
    }
    // Nothing that follows is held.
    let held = profile["held"].as_object().cloned().unwrap_or_default();
    for joint in [
        "thumb_mcp",
        "thumb_ip",
        "index_pip",
        "index_dip",
        "little_dip",
    ] {
        assert!(!held.contains_key(joint), "{joint} held: {held:?}");
    }
    assert!(
        notes.iter().any(|n| n.contains("\"thumb_mcp\" follows \"thumb_cmc\"")
            && n.contains("0.8 x + 0.1")),
        "{notes:?}"
    );
    // The loaded hand: the description's multipliers and offsets, and no conflict.
    let hand = &world.benchmark.hand;
    let thumb = &hand.fingers[0].coupled;
    let of = |coupled: &[(usize, f32, f32)], name: &str| {
        coupled
            .iter()
            .find(|&&(j, _, _)| hand.joints[j].name == name)
            .map(|&(_, r, o)| (r, o))
            .unwrap_or_else(|| panic!("{name}"))
    };
    assert_eq!(of(thumb, "thumb_mcp"), (0.8, 0.1));
    assert_eq!(of(thumb, "thumb_ip"), (0.6, 0.0));
    assert_eq!(of(&hand.fingers[1].coupled, "index_pip"), (1.2, 0.05));
    assert_eq!(world.coupling_conflicts(), (Vec::new(), Vec::new()));
    std::fs::remove_dir_all(root).ok();
}

#[test]
fn a_profile_against_the_descriptions_couplings_is_reported_until_it_overrides_them() {
    let root = temp("conflicts");
    let (dir, _) = drafted(&root);
    // The paper's coupling on a joint the description couples otherwise, and a follower left
    // out of its finger (so held at 0).
    edit_profile(&dir, |p| {
        let thumb = &mut p["fingers"]["thumb"]["joints"];
        let ip = thumb
            .as_array_mut()
            .expect("joints")
            .iter_mut()
            .find(|j| j["joint"] == "thumb_ip")
            .expect("thumb_ip");
        ip["ratio"] = serde_json::json!(0.5);
        p["fingers"]["index"]["joints"]
            .as_array_mut()
            .expect("joints")
            .retain(|j| j["joint"] != "index_dip");
    });
    let world = load(&root, &dir).expect("it loads: only the check refuses");
    let (conflicts, needless) = world.coupling_conflicts();
    assert!(needless.is_empty());
    assert_eq!(conflicts.len(), 2, "{conflicts:#?}");
    let ip = conflicts
        .iter()
        .find(|c| c.contains("\"thumb_ip\""))
        .expect("thumb_ip");
    assert!(
        ip.contains("thumb_ip = 0.6 x thumb_cmc + 0")
            && ip.contains("thumb_ip = 0.5 x thumb_cmc + 0")
            && ip.contains("fingers.thumb.joints["),
        "{ip}"
    );
    let dip = conflicts
        .iter()
        .find(|c| c.contains("\"index_dip\""))
        .expect("index_dip");
    assert!(
        dip.contains("index_dip = 0.7 x index_mcp + 0") && dip.contains("holds it at 0"),
        "{dip}"
    );
    let hash = world.hash.clone();

    // Named overrides keep the profile's couplings; the world's hash stays.
    edit_profile(&dir, |p| {
        p["description_overrides"] = serde_json::json!(["thumb_ip", "index_dip"]);
    });
    let world = load(&root, &dir).expect("loads");
    assert_eq!(world.coupling_conflicts(), (Vec::new(), Vec::new()));
    assert_eq!(world.hash, hash);
    let summary = world.summary();
    assert_eq!(
        summary["description_overrides"].as_array().map(Vec::len),
        Some(2),
        "{summary}"
    );

    // An override without a conflict is reported; one naming no joint is refused.
    edit_profile(&dir, |p| {
        p["description_overrides"] = serde_json::json!(["thumb_ip", "index_dip", "ring_pip"]);
    });
    let (_, needless) = load(&root, &dir).expect("loads").coupling_conflicts();
    assert_eq!(needless, vec!["ring_pip".to_string()]);
    edit_profile(&dir, |p| {
        p["description_overrides"] = serde_json::json!(["thumb_ipp"]);
    });
    let err = load(&root, &dir).expect_err("no such joint");
    assert!(
        err.contains("description_overrides[0]")
            && err.contains("thumb_ipp")
            && err.contains("thumb_ip"),
        "{err}"
    );
    std::fs::remove_dir_all(root).ok();
}

/// The coupled hand with its little finger on a metacarpal that starts low in the palm, near
/// the thumb's end of the fingers' bases (as the Shadow hand's `LFJ5`), cupping about an axis
/// across the palm: the fingers keep their names, the cupping joint is held.
#[test]
fn a_little_finger_on_a_low_metacarpal_is_still_the_little_one() {
    let root = temp("metacarpal");
    let hand = root.join("assets/coupled.xml");
    std::fs::create_dir_all(hand.parent().expect("parent")).expect("assets");
    let text = coupled_hand();
    let little = r#"      <body name="little_proximal" pos="0.045 -0.03 -0.004">"#;
    assert_eq!(text.matches(little).count(), 1);
    let start = text.find(little).expect("the little finger");
    let end = start + text[start..].find("\n      </body>\n").expect("its end") + 14;
    let finger = text[start..end].replace(
        r#"<body name="little_proximal" pos="0.045 -0.03 -0.004">"#,
        r#"<body name="little_proximal" pos="0.065 0 0">"#,
    );
    let metacarpal = format!(
        r#"      <body name="little_metacarpal" pos="-0.02 -0.03 -0.004">
        <joint name="little_cup" type="hinge" axis="1 0 0" range="0 0.7"/>
        <geom type="capsule" fromto="0 0 0 0.065 0 0" size="0.009" mass="0.03"/>
{finger}
      </body>"#
    );
    std::fs::write(
        &hand,
        format!("{}{}{}", &text[..start], metacarpal, &text[end..]),
    )
    .expect("write the hand");
    let out = root.join("world");
    let assets = Assets::parse(&root.join("assets").display().to_string());
    let drafted = init_world(&hand, &out, None, None, &assets).expect("a draft");
    let profile: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("hand.json")).expect("profile"))
            .expect("JSON");
    for name in ["index", "middle", "ring", "little"] {
        assert_eq!(
            profile["fingers"][name]["command"],
            format!("{name}_mcp"),
            "{name}: {}",
            profile["fingers"]
        );
    }
    assert!(
        drafted
            .notes
            .iter()
            .any(|n| n.starts_with("held at 0") && n.contains("little_cup")),
        "{:?}",
        drafted.notes
    );
    std::fs::remove_dir_all(root).ok();
}
