//! The test world the integration tests share: `scripts/make-test-world` writes it (a URDF
//! hand we made, its profile, a four-finger variant) into a fresh folder.

// Each test crate includes this module and uses part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

use grasp_sim::World;
use grasp_sim::assets::Assets;

/// A fresh copy of the test world under the temporary folder.
pub fn test_world(tag: &str) -> PathBuf {
    let root = std::env::temp_dir().join(format!("crm-test-world-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/make-test-world");
    let status = Command::new("python3")
        .arg(&script)
        .arg(&root)
        .status()
        .expect("python3 runs scripts/make-test-world");
    assert!(status.success(), "make-test-world failed");
    root
}

/// The assets (`CRM_ASSETS`) of a test world's folder.
pub fn assets(root: &Path) -> Assets {
    Assets::parse(&root.join("assets").display().to_string())
}

/// The test world at `root`, loaded.
pub fn load(root: &Path) -> World {
    World::load_with(&root.join("world"), &assets(root)).expect("the test world loads")
}
