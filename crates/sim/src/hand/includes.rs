//! MJCF `<include>`s expanded into one document before `rapier3d-mjcf` parses it: the loader
//! refuses included files whose root is `<mujocoinclude>` (measured with 0.36.1), which is how
//! gymnasium-robotics ships Adroit's parts. MuJoCo resolves include paths against the main
//! file's folder, as here.

use std::path::{Path, PathBuf};

use crate::error::{Result, invalid_at as invalid, read_text as read};

/// Replaces each `<include file="..."/>` with the children of the included file's root
/// (`<mujoco>` or `<mujocoinclude>`), recursively. MuJoCo resolves include paths against the
/// main file's folder, as here.
pub fn expand_includes(text: &str, path: &Path, base: &Path, depth: usize) -> Result<String> {
    if depth > 16 {
        return Err(invalid(
            path,
            "include",
            "includes nest deeper than 16 files",
        ));
    }
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
        let included: PathBuf = base.join(&file);
        let inner = read(&included)?;
        out.push_str(&expand_includes(
            root_children(&inner, &included)?,
            &included,
            base,
            depth + 1,
        )?);
        rest = &rest[start + len + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

/// Where an element named `name` opens in `text` (not one whose name merely starts so).
fn find_tag(text: &str, name: &str) -> Option<usize> {
    let pattern = format!("<{name}");
    let mut from = 0;
    while let Some(at) = text[from..].find(&pattern) {
        let at = from + at;
        let next = text[at + pattern.len()..].chars().next();
        if matches!(next, Some(c) if c.is_whitespace() || c == '/' || c == '>') {
            return Some(at);
        }
        from = at + pattern.len();
    }
    None
}

fn attribute(tag: &str, name: &str) -> Option<String> {
    let at = tag.find(&format!("{name}="))? + name.len() + 1;
    let quote = tag[at..].chars().next()?;
    let value = &tag[at + 1..];
    Some(value[..value.find(quote)?].to_string())
}

/// The text between the root element's start and end tags, skipping the XML declaration and
/// comments before it.
fn root_children<'a>(text: &'a str, path: &Path) -> Result<&'a str> {
    let mut at = 0;
    loop {
        let Some(open) = text[at..].find('<') else {
            return Err(invalid(path, "mujoco", "no root element"));
        };
        let open = at + open;
        let rest = &text[open..];
        if rest.starts_with("<?") {
            at = open + rest.find("?>").map_or(rest.len(), |e| e + 2);
        } else if rest.starts_with("<!--") {
            at = open + rest.find("-->").map_or(rest.len(), |e| e + 3);
        } else {
            let name_end = rest[1..]
                .find(|c: char| c.is_whitespace() || c == '>' || c == '/')
                .map_or(rest.len(), |e| e + 1);
            let name = &rest[1..name_end];
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
            return Ok(&body[..end]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn includes_are_expanded_without_their_roots() {
        let dir = std::env::temp_dir().join(format!("crm-include-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("parts")).expect("dir");
        std::fs::write(
            dir.join("parts/chain.xml"),
            "<?xml version=\"1.0\"?>\n<!-- a part -->\n<mujocoinclude><body name=\"b\"/><include file=\"parts/leaf.xml\"/></mujocoinclude>",
        )
        .expect("write");
        std::fs::write(
            dir.join("parts/leaf.xml"),
            "<mujoco model=\"x\"><body name=\"c\"/></mujoco>",
        )
        .expect("write");
        let main = "<mujoco><worldbody><include file=\"parts/chain.xml\"/></worldbody></mujoco>";
        let expanded = expand_includes(main, &dir.join("main.xml"), &dir, 0).expect("expanded");
        assert_eq!(
            expanded,
            "<mujoco><worldbody><body name=\"b\"/><body name=\"c\"/></worldbody></mujoco>"
        );
        let missing = "<mujoco><include file=\"nowhere.xml\"/></mujoco>";
        let err = expand_includes(missing, &dir.join("main.xml"), &dir, 0).expect_err("missing");
        assert!(err.to_string().contains("nowhere.xml"), "{err}");
        std::fs::remove_dir_all(dir).ok();
    }
}
