//! MJCF mesh files found before `rapier3d-mjcf` converts the model: it resolves a mesh against
//! `<compiler meshdir/assetdir>` and the main file's folder and skips one it cannot open with
//! only a log line (measured with 0.36.1: a missing fingertip collision mesh passed `crm world
//! check` and lowered the oracle). Here a mesh missing there is looked up in the `CRM_ASSETS`
//! folders (under `meshdir`, then by its own path) and, when found, the model is pointed at
//! it; a mesh found nowhere, or in a format the loader cannot read, is an error naming the
//! mesh, the body and geom that use it (collision or visual) and every place searched. Each
//! mesh file's bytes go into the world's hash.

use std::path::{Path, PathBuf};

use rapier3d_mjcf::mjcf_rs::Model;

use sha2::Sha256;

use super::includes::add_content;
use crate::assets::Assets;
use crate::error::{Error, Result, invalid_at as invalid};

/// Points every mesh of `model` at a file that exists, or fails naming the first that has
/// none; adds each mesh file's bytes to `digest`. `base` is the main file's folder; `path`
/// names errors.
pub fn resolve(
    model: &mut Model,
    base: &Path,
    assets: &Assets,
    path: &Path,
    digest: &mut Sha256,
) -> Result<()> {
    for k in 0..model.assets.meshes.len() {
        let mesh = &model.assets.meshes[k];
        let Some(file) = mesh.file.clone() else {
            continue; // inline vertices
        };
        let name = mesh.name.clone().unwrap_or_else(|| file.clone());
        let mut searched: Vec<PathBuf> = Vec::new();
        if let Some(first) = model.resolve_mesh_file(mesh, base) {
            searched.push(first);
        }
        let dir = model
            .compiler
            .mesh_dir
            .clone()
            .or_else(|| model.compiler.asset_dir.clone());
        for folder in &assets.folders {
            for candidate in dir
                .as_ref()
                .map(|d| folder.join(d).join(&file))
                .into_iter()
                .chain([folder.join(&file)])
            {
                if !searched.contains(&candidate) {
                    searched.push(candidate);
                }
            }
        }
        let user = users(model, &name);
        let Some(found) = searched.iter().find(|p| p.is_file()).cloned() else {
            let places: Vec<String> = searched.iter().map(|p| p.display().to_string()).collect();
            return Err(invalid(
                path,
                format!("mesh {name:?}{user}"),
                format!(
                    "file {file:?} not found; searched {} (meshdir or assetdir of <compiler>, relative to the main file, then each CRM_ASSETS folder)",
                    places.join(", ")
                ),
            ));
        };
        let extension = found
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(extension.as_deref(), Some("stl" | "obj")) {
            return Err(invalid(
                path,
                format!("mesh {name:?}{user}"),
                format!(
                    "{} cannot be read: meshes load from STL or OBJ files",
                    found.display()
                ),
            ));
        }
        let bytes = std::fs::read(&found).map_err(|error| Error::Io {
            path: found.display().to_string(),
            error,
        })?;
        add_content(digest, &bytes);
        if searched.first() != Some(&found) {
            let absolute = std::path::absolute(&found).unwrap_or(found);
            model.assets.meshes[k].file = Some(absolute.display().to_string());
        }
    }
    Ok(())
}

/// `, used by body "b" geom "g" (collision)`: where a mesh is used, for errors.
fn users(model: &Model, mesh: &str) -> String {
    let mut uses = Vec::new();
    for entry in &model.bodies {
        for (g, geom) in entry.body.geoms.iter().enumerate() {
            if geom.mesh.as_deref() == Some(mesh) {
                let kind = if geom.contype == 0 && geom.conaffinity == 0 {
                    "visual"
                } else {
                    "collision"
                };
                let body = entry.body.name.as_deref().unwrap_or("world");
                let geom = geom.name.clone().unwrap_or_else(|| format!("#{g}"));
                uses.push(format!("body {body:?} geom {geom:?} ({kind})"));
            }
        }
    }
    if uses.is_empty() {
        String::new()
    } else {
        format!(", used by {}", uses.join(", "))
    }
}
