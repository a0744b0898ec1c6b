//! What the CLI's integration tests share: running a repository script that writes a folder
//! (`scripts/make-test-world`, `scripts/make-dexmobile-standin`).

use std::path::Path;
use std::process::Command;

/// Runs the repository's `scripts/SCRIPT DIR`, which writes the folder `dir`.
pub fn scripted(script: &str, dir: &Path) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scripts")
        .join(script);
    let status = Command::new("python3")
        .arg(&path)
        .arg(dir)
        .status()
        .unwrap_or_else(|e| panic!("python3 runs scripts/{script}: {e}"));
    assert!(status.success(), "{script} failed");
}
