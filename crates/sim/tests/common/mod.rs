//! What the integration tests share: the test world, which `scripts/make-test-world` writes
//! (a URDF hand we made, its profile, a four-finger variant) into a fresh folder, and any
//! other folder a repository script writes.

// Each test crate includes this module and uses part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

use grasp_sim::World;
use grasp_sim::assets::Assets;

/// A fresh copy of the test world under the temporary folder.
pub fn test_world(tag: &str) -> PathBuf {
    scripted("make-test-world", &format!("crm-test-world-{tag}"))
}

/// A fresh folder `name` (with the process id) under the temporary folder, written by the
/// repository's `scripts/SCRIPT`.
pub fn scripted(script: &str, name: &str) -> PathBuf {
    let root = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scripts")
        .join(script);
    let status = Command::new("python3")
        .arg(&path)
        .arg(&root)
        .status()
        .unwrap_or_else(|e| panic!("python3 runs scripts/{script}: {e}"));
    assert!(status.success(), "{script} failed");
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
