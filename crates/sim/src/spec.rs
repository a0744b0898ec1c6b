//! The grasping CRM (paper, section IV): approach, grasp, out-of-reach, success and failure,
//! checked in as `crates/sim/specs/grasping.json`; the flat machine of the plain-PPO
//! ablation (`flat.json`); and the check that a spec fits this environment's observation and
//! action layout.

use crate::error::{Error, Result};
use crate::observation::{ACTIONS, FEATURES};

const BUILTIN: &str = include_str!("../specs/grasping.json");
const FLAT: &str = include_str!("../specs/flat.json");

/// The built-in grasping spec.
pub fn grasping_spec() -> crm::Spec {
    match crm::Spec::from_json(BUILTIN, "crates/sim/specs/grasping.json") {
        Ok(spec) => spec,
        // The built-in spec is checked by the crate's tests.
        Err(err) => panic!("built-in grasping spec is invalid: {err}"),
    }
}

/// The built-in grasping machine.
pub fn grasping_machine() -> crm::Machine {
    match crm::Machine::from_spec(grasping_spec()) {
        Ok(machine) => machine,
        Err(err) => panic!("built-in grasping spec is invalid: {err}"),
    }
}

/// The flat, unstaged machine of the plain-PPO ablation: one stage with every action and
/// the whole observation, the sum of the staged machine's reward terms, and the same terminal
/// outcomes and rewards (`crates/sim/specs/flat.json`).
pub fn flat_spec() -> crm::Spec {
    match crm::Spec::from_json(FLAT, "crates/sim/specs/flat.json") {
        Ok(spec) => spec,
        // The built-in spec is checked by the crate's tests.
        Err(err) => panic!("built-in flat spec is invalid: {err}"),
    }
}

/// Refuses a spec whose features, action dimensions or events do not match this environment.
pub fn check_compatible(spec: &crm::Spec) -> Result<()> {
    let mismatch = |what: &str, expected: &[&str], got: &[String]| -> Result<()> {
        if expected.len() != got.len() || expected.iter().zip(got).any(|(a, b)| a != b) {
            let first = expected
                .iter()
                .zip(got)
                .position(|(a, b)| a != b)
                .unwrap_or(expected.len().min(got.len()));
            return Err(Error::Crm(crm::Error::Invalid {
                at: format!("{what}[{first}]"),
                message: format!(
                    "the grasping environment provides {} {what} ({:?} at this position), the spec lists {} ({:?})",
                    expected.len(),
                    expected.get(first),
                    got.len(),
                    got.get(first)
                ),
            }));
        }
        Ok(())
    };
    mismatch("features", &FEATURES, &spec.features)?;
    mismatch("action_dims", &ACTIONS, &spec.action_dims)?;
    for event in &spec.events {
        if !["arrive", "aor", "gor", "fail", "succ"].contains(&event.as_str()) {
            return Err(Error::Crm(crm::Error::Invalid {
                at: "events".into(),
                message: format!("the grasping environment never fires {event:?}"),
            }));
        }
    }
    Ok(())
}
