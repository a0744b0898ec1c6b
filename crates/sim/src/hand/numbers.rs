//! Numbers in a description, checked before any loader reads them: `rapier3d-urdf` and
//! `rapier3d-mjcf` parse `nan` and `inf` as numbers and a malformed list as whatever part of it
//! parses (measured with 0.36.1: `pos="0 nan 0.045"`, `range="0 nan"` and a NaN capsule
//! radius loaded, the last truncating every episode with no error). Every attribute that holds
//! numbers in MuJoCo's or ROS's schema must be a whitespace-separated list of finite numbers;
//! an error names the file, the element (and its `name`) and the attribute.

use std::path::Path;

use crate::error::{Result, invalid_at as invalid};

/// Which schema's numeric attributes to check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Urdf,
    Mjcf,
}

/// MJCF attributes that hold numbers (MuJoCo's XML reference), on any element.
const MJCF: &[&str] = &[
    "pos",
    "quat",
    "axisangle",
    "euler",
    "xyaxes",
    "zaxis",
    "axis",
    "size",
    "fromto",
    "range",
    "ctrlrange",
    "forcerange",
    "actuatorfrcrange",
    "lengthrange",
    "mass",
    "diaginertia",
    "fullinertia",
    "density",
    "friction",
    "frictionloss",
    "damping",
    "stiffness",
    "armature",
    "ref",
    "springref",
    "springdamper",
    "margin",
    "gap",
    "solref",
    "solimp",
    "solreflimit",
    "solimplimit",
    "solreffriction",
    "solimpfriction",
    "kp",
    "kv",
    "gear",
    "coef",
    "polycoef",
    "scale",
    "rgba",
    "gravity",
    "timestep",
    "refpos",
    "refquat",
    "gainprm",
    "biasprm",
    "dynprm",
    "settotalmass",
    "boundmass",
    "boundinertia",
];

/// URDF attributes that hold numbers (ROS's URDF schema).
const URDF: &[&str] = &[
    "xyz",
    "rpy",
    "value",
    "ixx",
    "ixy",
    "ixz",
    "iyy",
    "iyz",
    "izz",
    "lower",
    "upper",
    "effort",
    "velocity",
    "multiplier",
    "offset",
    "radius",
    "length",
    "size",
    "scale",
    "damping",
    "friction",
    "rgba",
];

/// Checks every numeric attribute of `text` (the file `path`). Text that is not well-formed
/// XML is left to the loader, whose error names the line.
pub fn check(text: &str, path: &Path, format: Format) -> Result<()> {
    let Ok(document) = roxmltree::Document::parse(text) else {
        return Ok(());
    };
    let names = match format {
        Format::Urdf => URDF,
        Format::Mjcf => MJCF,
    };
    for node in document.descendants().filter(|n| n.is_element()) {
        for attribute in node.attributes() {
            if !names.contains(&attribute.name()) {
                continue;
            }
            let value = attribute.value();
            let bad = value
                .split_whitespace()
                .find(|token| !token.parse::<f64>().is_ok_and(f64::is_finite));
            if let Some(token) = bad {
                let element = match node.attribute("name") {
                    Some(name) => format!("<{} name={name:?}>", node.tag_name().name()),
                    None => format!("<{}>", node.tag_name().name()),
                };
                let line = document.text_pos_at(attribute.range_value().start).row;
                return Err(invalid(
                    path,
                    format!("line {line}, {element} attribute {:?}", attribute.name()),
                    format!("{value:?} is not a list of finite numbers ({token:?})"),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_and_malformed_numbers_are_refused_naming_element_and_attribute() {
        let path = Path::new("hand.xml");
        let good = r#"<mujoco><worldbody><body name="b" pos="0 0.1 -2e-3"><joint range="0 1.57" limited="true"/></body></worldbody></mujoco>"#;
        check(good, path, Format::Mjcf).expect("finite numbers pass");
        for (text, attribute, token) in [
            (
                r#"<mujoco><body name="palm" pos="0 nan 0.045"/></mujoco>"#,
                "pos",
                "nan",
            ),
            (
                r#"<mujoco><joint name="j" range="0 inf"/></mujoco>"#,
                "range",
                "inf",
            ),
            (r#"<mujoco><geom size="0.01 0.x"/></mujoco>"#, "size", "0.x"),
        ] {
            let err = check(text, path, Format::Mjcf).expect_err(text).to_string();
            assert!(err.contains("hand.xml"), "{err}");
            assert!(err.contains(&format!("attribute {attribute:?}")), "{err}");
            assert!(err.contains(&format!("({token:?})")), "{err}");
        }
        let urdf = r#"<robot name="r"><link name="l"><inertial><mass value="NaN"/></inertial></link></robot>"#;
        let err = check(urdf, Path::new("hand.urdf"), Format::Urdf)
            .expect_err("NaN mass")
            .to_string();
        assert!(err.contains("<mass>") && err.contains("\"value\""), "{err}");
        // Names are not numbers.
        check(
            r#"<robot name="inf"><link name="nan"/></robot>"#,
            path,
            Format::Urdf,
        )
        .expect("names pass");
    }
}
