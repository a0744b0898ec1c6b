//! MJCF descriptions as their authors ship them, through `Description::load`: a scene that
//! includes the hand with a closing tag and `<compiler angle meshdir>`, the same scene finding its
//! parts through `CRM_ASSETS`, and the refusals: a part loaded on its own, a missing collision
//! or visual mesh, a NaN attribute. The files are written here (a two-link hand of boxes).

use std::path::{Path, PathBuf};

use grasp_sim::assets::Assets;
use grasp_sim::hand::description::Description;

/// A binary STL cube of half side `half`.
fn cube_stl(path: &Path, half: f32) {
    let corners: Vec<[f32; 3]> = (0..8)
        .map(|i| {
            let s = |bit: u32| if i & (1 << bit) == 0 { -half } else { half };
            [s(0), s(1), s(2)]
        })
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let mut bytes = vec![b' '; 80];
    bytes.extend_from_slice(&12u32.to_le_bytes());
    for [a, b, c, d] in quads {
        for tri in [[a, b, c], [a, c, d]] {
            bytes.extend_from_slice(&[0u8; 12]);
            for k in tri {
                for v in corners[k] {
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
            }
            bytes.extend_from_slice(&[0u8; 2]);
        }
    }
    std::fs::create_dir_all(path.parent().expect("folder")).expect("mesh folder");
    std::fs::write(path, bytes).expect("write mesh");
}

const BODY: &str = r#"<mujocoinclude>
  <body name="robot0:palm" pos="0 0 0.1">
    <geom name="palm_box" type="box" size="0.04 0.04 0.01"/>
    <body name="robot0:finger" pos="0.05 0 0">
      <joint name="robot0:pip" axis="0 1 0" range="0 1.57"/>
      <geom name="finger_collision" type="mesh" mesh="finger"/>
      <geom name="finger_visual" type="mesh" mesh="finger_skin" contype="0" conaffinity="0"/>
    </body>
  </body>
</mujocoinclude>
"#;

const ASSETS: &str = r#"<mujocoinclude>
  <compiler angle="radian" meshdir="meshes"/>
  <asset>
    <mesh name="finger" file="finger.stl"/>
    <mesh name="finger_skin" file="skin.stl"/>
  </asset>
</mujocoinclude>
"#;

const SCENE: &str = r#"<?xml version="1.0"?>
<mujoco model="scene">
  <include file="hand/assets.xml"></include>
  <worldbody>
    <include file="hand/body.xml"></include>
  </worldbody>
</mujoco>
"#;

/// A hand package (`hand/` with `meshes/`) under `root/package` and a scene under `root`.
fn write_hand(root: &Path) -> PathBuf {
    let _ = std::fs::remove_dir_all(root);
    let package = root.join("package");
    std::fs::create_dir_all(package.join("hand")).expect("package");
    std::fs::write(package.join("hand/body.xml"), BODY).expect("body");
    std::fs::write(package.join("hand/assets.xml"), ASSETS).expect("assets");
    cube_stl(&package.join("meshes/finger.stl"), 0.01);
    cube_stl(&package.join("meshes/skin.stl"), 0.011);
    let scene = package.join("scene.xml");
    std::fs::write(&scene, SCENE).expect("scene");
    scene
}

fn scratch(tag: &str) -> PathBuf {
    std::env::temp_dir().join(format!("crm-descriptions-{tag}-{}", std::process::id()))
}

#[test]
fn a_scene_with_closing_tag_includes_and_a_meshdir_loads_its_meshes() {
    let root = scratch("scene");
    let scene = write_hand(&root);
    let hand = Description::load(&scene, &Assets::default()).expect("the scene loads");
    let finger = &hand.links[hand.link("robot0:finger").expect("finger link")];
    assert_eq!(
        finger.shapes.len(),
        1,
        "the collision mesh, not the visual one"
    );
    let extents = finger.shapes[0].1.compute_local_aabb().extents();
    assert!((extents.x - 0.02).abs() < 1e-4, "{extents:?}");
    // rapier3d-mjcf draws every geom; the visual-only one is among them.
    let widest = finger
        .visuals
        .iter()
        .map(|v| v.vertices.iter().map(|p| p[0]).fold(f32::MIN, f32::max))
        .fold(f32::MIN, f32::max);
    assert!((widest - 0.011).abs() < 1e-4, "the visual mesh: {widest}");
    let pip = &hand.joints[hand.joint("robot0:pip").expect("pip")];
    assert_eq!(pip.limits, Some([0.0, 1.57]));

    // The same scene elsewhere finds its parts and meshes through CRM_ASSETS.
    let elsewhere = root.join("elsewhere/scene.xml");
    std::fs::create_dir_all(elsewhere.parent().expect("folder")).expect("folder");
    std::fs::write(&elsewhere, SCENE).expect("scene copy");
    let err = Description::load(&elsewhere, &Assets::default())
        .expect_err("no parts beside it")
        .to_string();
    assert!(
        err.contains("hand/assets.xml") && err.contains("searched"),
        "{err}"
    );
    let assets = Assets::parse(&root.join("package").display().to_string());
    let found = Description::load(&elsewhere, &assets).expect("through CRM_ASSETS");
    assert_eq!(found.links.len(), hand.links.len());
    std::fs::remove_dir_all(root).ok();
}

#[test]
fn a_part_loaded_on_its_own_is_refused_naming_the_scene_that_includes_it() {
    let root = scratch("fragment");
    let scene = write_hand(&root);
    let part = root.join("package/hand/body.xml");
    let err = Description::load(&part, &Assets::default())
        .expect_err("a part")
        .to_string();
    assert!(
        err.contains("body.xml") && err.contains("<mujocoinclude>"),
        "{err}"
    );
    assert!(err.contains(&scene.display().to_string()), "{err}");
    std::fs::remove_dir_all(root).ok();
}

#[test]
fn a_missing_collision_or_visual_mesh_is_an_error_naming_body_and_places() {
    let root = scratch("meshes");
    let scene = write_hand(&root);
    for (file, geom, kind) in [
        ("finger.stl", "finger_collision", "collision"),
        ("skin.stl", "finger_visual", "visual"),
    ] {
        let mesh = root.join("package/meshes").join(file);
        let bytes = std::fs::read(&mesh).expect("mesh");
        std::fs::remove_file(&mesh).expect("remove");
        let err = Description::load(&scene, &Assets::default())
            .expect_err("a missing mesh")
            .to_string();
        for want in [
            "scene.xml",
            file,
            "\"robot0:finger\"",
            geom,
            kind,
            "searched",
            mesh.to_str().expect("utf-8"),
        ] {
            assert!(err.contains(want), "{err:?} lacks {want:?}");
        }
        std::fs::write(&mesh, bytes).expect("restore");
    }
    std::fs::remove_dir_all(root).ok();
}

#[test]
fn a_nan_attribute_in_an_included_part_is_refused_naming_file_element_and_attribute() {
    let root = scratch("nan");
    let scene = write_hand(&root);
    let body = root.join("package/hand/body.xml");
    for (from, to, attribute) in [
        ("pos=\"0.05 0 0\"", "pos=\"0.05 nan 0\"", "pos"),
        ("range=\"0 1.57\"", "range=\"0 NaN\"", "range"),
        ("size=\"0.04 0.04 0.01\"", "size=\"0.04 0.04 0.0l\"", "size"),
    ] {
        std::fs::write(&body, BODY.replacen(from, to, 1)).expect("edit");
        let err = Description::load(&scene, &Assets::default())
            .expect_err("a bad number")
            .to_string();
        assert!(
            err.contains("body.xml") && err.contains(&format!("attribute {attribute:?}")),
            "{err}"
        );
    }
    std::fs::write(&body, BODY).expect("restore");
    let parts = root.join("package/hand/assets.xml");
    std::fs::write(
        &parts,
        ASSETS.replacen(
            "file=\"skin.stl\"",
            "file=\"skin.stl\" scale=\"1 inf 1\"",
            1,
        ),
    )
    .expect("edit");
    let err = Description::load(&scene, &Assets::default())
        .expect_err("a bad number in a part of two elements")
        .to_string();
    assert!(
        err.contains("assets.xml") && err.contains("line 5") && err.contains("\"scale\""),
        "{err}"
    );
    std::fs::remove_dir_all(root).ok();
}
