//! MJCF `<include>`s expanded into one document before `rapier3d-mjcf` parses it: the loader
//! refuses included files whose root is `<mujocoinclude>` (measured with 0.36.1), which is how
//! gymnasium-robotics ships Adroit's parts.
//!
//! Every form MuJoCo accepts is taken: `<include file="..."/>` and `<include
//! file="..."></include>`, nested to any depth below 16. A file is looked up relative to the
//! file that includes it, then to the main file's folder (MuJoCo's own rule), then in each
//! `CRM_ASSETS` folder; a miss names every place searched. Each file read is checked for
//! non-finite or malformed numbers (`numbers.rs`) before it is spliced in, so an error names
//! the file the user wrote.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::assets::Assets;
use crate::error::{Result, invalid_at as invalid, read_text as read};

/// Where a document's includes are searched, and the digest of what it read.
pub struct Expansion<'a> {
    /// The main file's folder.
    pub base: &'a Path,
    pub assets: &'a Assets,
    /// The text of every file read, in order: part of the world's hash.
    pub digest: Sha256,
}

impl<'a> Expansion<'a> {
    pub fn new(base: &'a Path, assets: &'a Assets) -> Self {
        Self {
            base,
            assets,
            digest: Sha256::new(),
        }
    }

    /// `text` (the file `path`) with each `<include>` replaced by the children of the
    /// included file's root (`<mujoco>` or `<mujocoinclude>`), recursively.
    pub fn expand(&mut self, text: &str, path: &Path, depth: usize) -> Result<String> {
        if depth > 16 {
            return Err(invalid(
                path,
                "include",
                "includes nest deeper than 16 files",
            ));
        }
        if depth == 0 {
            // An included file is checked whole where it is read (below), so its line numbers
            // are its own and a part with several top-level elements is still one document.
            super::numbers::check(text, path, super::numbers::Format::Mjcf)?;
        }
        add_content(&mut self.digest, text.as_bytes());
        let mut out = String::with_capacity(text.len());
        let mut rest = text;
        while let Some(start) = find_tag(rest, "include") {
            out.push_str(&rest[..start]);
            let Some(len) = rest[start..].find('>') else {
                return Err(invalid(path, "include", "unterminated <include> element"));
            };
            let tag = &rest[start..start + len + 1];
            let file = attribute(tag, "file")
                .ok_or_else(|| invalid(path, "include", "an <include> without a file attribute"))?;
            let included = self.find(&file, path)?;
            let inner = read(&included)?;
            super::numbers::check(&inner, &included, super::numbers::Format::Mjcf)?;
            let children = root_children(&inner, &included)?;
            out.push_str(&self.expand(children, &included, depth + 1)?);
            rest = &rest[start + len + 1..];
            if !tag.ends_with("/>") {
                // `<include file="..."></include>`: the closing tag goes with it.
                let after = rest.trim_start();
                let Some(closed) = after.strip_prefix("</include") else {
                    return Err(invalid(
                        path,
                        format!("include {file:?}"),
                        "an <include> must be empty: `<include file=\"...\"/>` or `<include file=\"...\"></include>`",
                    ));
                };
                let Some(end) = closed.find('>') else {
                    return Err(invalid(path, "include", "unterminated </include> tag"));
                };
                rest = &closed[end + 1..];
            }
        }
        out.push_str(rest);
        Ok(out)
    }

    /// An included file: relative to the including file, the main file's folder, then
    /// `CRM_ASSETS`.
    fn find(&self, file: &str, from: &Path) -> Result<PathBuf> {
        let name = Path::new(file);
        let mut searched: Vec<PathBuf> = Vec::new();
        if name.is_absolute() {
            searched.push(name.to_path_buf());
        } else {
            let own = from.parent().unwrap_or(Path::new("."));
            for folder in [own, self.base]
                .into_iter()
                .chain(self.assets.folders.iter().map(PathBuf::as_path))
            {
                let candidate = folder.join(name);
                if !searched.contains(&candidate) {
                    searched.push(candidate);
                }
            }
        }
        if let Some(found) = searched.iter().find(|p| p.is_file()) {
            return Ok(found.clone());
        }
        let places: Vec<String> = searched.iter().map(|p| p.display().to_string()).collect();
        Err(invalid(
            from,
            format!("include {file:?}"),
            format!(
                "the included file was not found; searched {} (relative to the including file, the main file's folder, then each CRM_ASSETS folder)",
                places.join(", ")
            ),
        ))
    }
}

/// Adds one file's bytes to a content digest, length first, so two files never read as one.
pub fn add_content(digest: &mut Sha256, bytes: &[u8]) {
    digest.update((bytes.len() as u64).to_le_bytes());
    digest.update(bytes);
}

/// Whether `text`'s root is `<mujocoinclude>` or it declares no `<worldbody>`: a part meant
/// to be included by another file, not a model to load.
pub fn fragment_reason(text: &str) -> Option<&'static str> {
    if root_name(text) == Some("mujocoinclude") {
        Some("its root is <mujocoinclude>")
    } else if find_tag(text, "worldbody").is_none() {
        Some("it has no <worldbody>")
    } else {
        None
    }
}

/// The `.xml` files beside `path` and in its parent folder that include it by name: what a
/// user who loaded a fragment meant to load.
pub fn includers(path: &Path) -> Vec<PathBuf> {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return Vec::new();
    };
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut found = Vec::new();
    for dir in [Some(folder), folder.parent()].into_iter().flatten() {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().and_then(|e| e.to_str()) == Some("xml") && p != path)
            .collect();
        files.sort();
        for file in files {
            let Ok(text) = std::fs::read_to_string(&file) else {
                continue;
            };
            let mut rest = text.as_str();
            while let Some(at) = find_tag(rest, "include") {
                let tag = &rest[at..rest[at..].find('>').map_or(rest.len(), |e| at + e)];
                if attribute(tag, "file").is_some_and(|f| f.ends_with(name)) {
                    found.push(file.clone());
                    break;
                }
                rest = &rest[at + 1..];
            }
        }
    }
    found
}

/// Where an element named `name` opens in `text`, outside comments (not one whose name
/// merely starts so).
fn find_tag(text: &str, name: &str) -> Option<usize> {
    let pattern = format!("<{name}");
    let mut from = 0;
    loop {
        let at = from + text[from..].find('<')?;
        let rest = &text[at..];
        if rest.starts_with("<!--") {
            from = at + rest.find("-->").map_or(rest.len(), |e| e + 3);
            continue;
        }
        if rest.starts_with(&pattern) {
            let next = rest[pattern.len()..].chars().next();
            if matches!(next, Some(c) if c.is_whitespace() || c == '/' || c == '>') {
                return Some(at);
            }
        }
        from = at + 1;
    }
}

fn attribute(tag: &str, name: &str) -> Option<String> {
    let mut from = 0;
    loop {
        let at = from + tag[from..].find(&format!("{name}="))?;
        from = at + name.len() + 1;
        // A whole attribute name, not the end of a longer one (`meshfile=`).
        if at > 0 && !tag[..at].ends_with(char::is_whitespace) {
            continue;
        }
        let quote = tag[from..].chars().next()?;
        let value = &tag[from + 1..];
        return Some(value[..value.find(quote)?].to_string());
    }
}

/// The root element's name, after the XML declaration and comments.
fn root_name(text: &str) -> Option<&str> {
    let at = root_start(text)?;
    let rest = &text[at + 1..];
    let end = rest
        .find(|c: char| c.is_whitespace() || c == '>' || c == '/')
        .unwrap_or(rest.len());
    Some(&rest[..end])
}

fn root_start(text: &str) -> Option<usize> {
    let mut at = 0;
    loop {
        let open = at + text[at..].find('<')?;
        let rest = &text[open..];
        if rest.starts_with("<?") {
            at = open + rest.find("?>").map_or(rest.len(), |e| e + 2);
        } else if rest.starts_with("<!--") {
            at = open + rest.find("-->").map_or(rest.len(), |e| e + 3);
        } else if rest.starts_with("<!") {
            at = open + rest.find('>').map_or(rest.len(), |e| e + 1);
        } else {
            return Some(open);
        }
    }
}

/// The text between the root element's start and end tags.
fn root_children<'a>(text: &'a str, path: &Path) -> Result<&'a str> {
    let Some(open) = root_start(text) else {
        return Err(invalid(path, "mujoco", "no root element"));
    };
    let rest = &text[open..];
    let name = root_name(text).unwrap_or("mujoco");
    let Some(tag_end) = rest.find('>') else {
        return Err(invalid(path, name, "unterminated root element"));
    };
    if rest[..tag_end].ends_with('/') {
        return Ok("");
    }
    let body = &rest[tag_end + 1..];
    let close = format!("</{name}");
    let Some(end) = body.rfind(&close) else {
        return Err(invalid(path, name, "the root element is not closed"));
    };
    Ok(&body[..end])
}

#[cfg(test)]
mod tests;
