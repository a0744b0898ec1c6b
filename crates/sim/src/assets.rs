//! Where a world's files are found: relative to the file that names them, or in the folders of
//! `CRM_ASSETS` (a colon-separated list), so a world can use a file that a package installs
//! or a repository the user cloned, without copying it.
//!
//! A `package://NAME/rest` path (ROS) is `rest` inside a folder named `NAME`: one of the
//! `CRM_ASSETS` folders or one of the referring file's ancestors, or a `NAME` folder directly
//! inside either.

use std::path::{Path, PathBuf};

/// The folders searched after the referring file's own folder.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Assets {
    pub folders: Vec<PathBuf>,
}

impl Assets {
    /// The folders of `CRM_ASSETS`, in order; none when it is unset.
    pub fn from_env() -> Self {
        Self::parse(&std::env::var("CRM_ASSETS").unwrap_or_default())
    }

    /// The folders of a colon-separated list; empty entries are skipped.
    pub fn parse(list: &str) -> Self {
        Self {
            folders: list
                .split(':')
                .filter(|s| !s.is_empty())
                .map(PathBuf::from)
                .collect(),
        }
    }

    /// `name` relative to `base`, else in the first `CRM_ASSETS` folder that has it.
    pub fn file(&self, name: &str, base: &Path) -> Option<PathBuf> {
        let path = Path::new(name);
        if path.is_absolute() {
            return path.is_file().then(|| path.to_path_buf());
        }
        std::iter::once(base.to_path_buf())
            .chain(self.folders.iter().cloned())
            .map(|folder| folder.join(path))
            .find(|p| p.is_file())
    }

    /// A mesh path as robot descriptions write them: `package://NAME/rest`, `file://path`, or
    /// a path relative to `base`.
    pub fn mesh(&self, name: &str, base: &Path) -> Option<PathBuf> {
        if let Some(path) = name.strip_prefix("file://") {
            return self.file(path, base);
        }
        let Some(rest) = name.strip_prefix("package://") else {
            return self.file(name, base);
        };
        let (package, inner) = rest.split_once('/')?;
        let roots = self
            .folders
            .iter()
            .map(PathBuf::as_path)
            .chain(base.ancestors());
        for root in roots {
            let candidates = [
                (root.file_name().and_then(|n| n.to_str()) == Some(package))
                    .then(|| root.join(inner)),
                Some(root.join(package).join(inner)),
            ];
            if let Some(found) = candidates.into_iter().flatten().find(|p| p.is_file()) {
                return Some(found);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn package_and_relative_paths_resolve_and_missing_ones_do_not() {
        let root = std::env::temp_dir().join(format!("crm-assets-{}", std::process::id()));
        let package = root.join("repo/my_hand");
        std::fs::create_dir_all(package.join("meshes")).expect("dir");
        std::fs::create_dir_all(package.join("urdf")).expect("dir");
        std::fs::write(package.join("meshes/link.stl"), "solid x\nendsolid x\n").expect("write");
        let base = package.join("urdf");
        let none = Assets::default();
        // From the description's own ancestors.
        assert_eq!(
            none.mesh("package://my_hand/meshes/link.stl", &base),
            Some(package.join("meshes/link.stl"))
        );
        assert_eq!(
            none.mesh("../meshes/link.stl", &base),
            Some(base.join("../meshes/link.stl"))
        );
        assert_eq!(none.mesh("package://other/meshes/link.stl", &base), None);
        // Through CRM_ASSETS, from anywhere.
        let elsewhere = root.join("world");
        let assets = Assets::parse(&format!("/nonexistent::{}", root.join("repo").display()));
        assert_eq!(assets.folders.len(), 2);
        assert_eq!(
            assets.mesh("package://my_hand/meshes/link.stl", &elsewhere),
            Some(root.join("repo/my_hand/meshes/link.stl"))
        );
        assert_eq!(
            assets.file("my_hand/meshes/link.stl", &elsewhere),
            Some(root.join("repo/my_hand/meshes/link.stl"))
        );
        assert_eq!(assets.file("my_hand/meshes/none.stl", &elsewhere), None);
        std::fs::remove_dir_all(root).ok();
    }
}
