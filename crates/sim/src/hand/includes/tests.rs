use super::*;

/// A scratch folder, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("crm-include-{name}-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).expect("scratch dir");
        Self(dir)
    }

    fn write(&self, name: &str, text: &str) -> PathBuf {
        let path = self.0.join(name);
        std::fs::create_dir_all(path.parent().expect("parent")).expect("dir");
        std::fs::write(&path, text).expect("write");
        path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

fn expand(main: &str, path: &Path, assets: &Assets) -> Result<String> {
    let base = path.parent().expect("folder");
    Expansion::new(base, assets).expand(main, path, 0)
}

#[test]
fn includes_are_expanded_without_their_roots_or_closing_tags() {
    let dir = Scratch::new("forms");
    dir.write(
        "parts/chain.xml",
        "<?xml version=\"1.0\"?>\n<!-- a part: <include file=\"none.xml\"/> -->\n<mujocoinclude><body name=\"b\"/><include file=\"leaf.xml\"></include></mujocoinclude>",
    );
    // Relative to the including file (parts/), as nested includes are written.
    dir.write(
        "parts/leaf.xml",
        "<mujoco model=\"x\"><body name=\"c\"/></mujoco>",
    );
    let main = "<mujoco><worldbody><include file=\"parts/chain.xml\"></include>\n<!-- <include file=\"commented.xml\"/> --></worldbody></mujoco>";
    let expanded = expand(main, &dir.0.join("main.xml"), &Assets::default()).expect("expanded");
    assert_eq!(
        expanded,
        "<mujoco><worldbody><body name=\"b\"/><body name=\"c\"/>\n<!-- <include file=\"commented.xml\"/> --></worldbody></mujoco>"
    );
    let missing = "<mujoco><include file=\"nowhere.xml\"/></mujoco>";
    let err = expand(missing, &dir.0.join("main.xml"), &Assets::default())
        .expect_err("missing")
        .to_string();
    assert!(
        err.contains("nowhere.xml") && err.contains("searched"),
        "{err}"
    );
    let not_empty = "<mujoco><include file=\"parts/leaf.xml\"><body/></include></mujoco>";
    let err = expand(not_empty, &dir.0.join("main.xml"), &Assets::default())
        .expect_err("an include with children")
        .to_string();
    assert!(err.contains("must be empty"), "{err}");
}

#[test]
fn an_include_missing_beside_the_scene_is_found_through_crm_assets() {
    let package = Scratch::new("package");
    package.write(
        "hand/parts.xml",
        "<mujocoinclude><body name=\"palm\"/></mujocoinclude>",
    );
    let scene = Scratch::new("scene");
    let main = "<mujoco><worldbody><include file=\"hand/parts.xml\"/></worldbody></mujoco>";
    let path = scene.0.join("scene.xml");
    let err = expand(main, &path, &Assets::default()).expect_err("not beside the scene");
    let text = err.to_string();
    assert!(
        text.contains(&scene.0.join("hand/parts.xml").display().to_string()),
        "{text}"
    );
    let assets = Assets {
        folders: vec![PathBuf::from("/nonexistent"), package.0.clone()],
    };
    let expanded = expand(main, &path, &assets).expect("through CRM_ASSETS");
    assert!(expanded.contains("<body name=\"palm\"/>"), "{expanded}");
}

#[test]
fn a_fragment_is_recognized_and_the_files_that_include_it_are_named() {
    let dir = Scratch::new("fragment");
    let part = dir.write(
        "assets/hand_body.xml",
        "<mujocoinclude><body name=\"robot0:palm\"/></mujocoinclude>",
    );
    let scene = dir.write(
        "hand_scene.xml",
        "<mujoco><worldbody><include file=\"assets/hand_body.xml\"/></worldbody></mujoco>",
    );
    let text = std::fs::read_to_string(&part).expect("part");
    assert_eq!(fragment_reason(&text), Some("its root is <mujocoinclude>"));
    assert_eq!(includers(&part), vec![scene.clone()]);
    let scene_text = std::fs::read_to_string(&scene).expect("scene");
    assert_eq!(fragment_reason(&scene_text), None);
    assert_eq!(
        fragment_reason("<mujoco><asset/></mujoco>"),
        Some("it has no <worldbody>")
    );
}
