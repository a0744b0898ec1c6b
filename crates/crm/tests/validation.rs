//! A spec that breaks a rule of the machine is refused with the offending name.
#![allow(clippy::expect_used, clippy::unwrap_used)]

mod common;

use common::TOY_SPEC;

fn edited(edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let mut value: serde_json::Value = serde_json::from_str(TOY_SPEC).expect("toy spec is json");
    edit(&mut value);
    value.to_string()
}

fn refusal(text: &str) -> String {
    let spec = match crm::Spec::from_json(text, "edited.json") {
        Ok(spec) => spec,
        Err(err) => return err.to_string(),
    };
    crm::Machine::from_spec(spec)
        .expect_err("spec must be refused")
        .to_string()
}

#[test]
fn an_edge_out_of_a_terminal_stage_is_refused() {
    let text = edited(|v| {
        v["transitions"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!(
                {"from": "failure", "event": "arrive", "to": "grasp", "reward": 1.0}
            ));
    });
    let message = refusal(&text);
    assert!(
        message.contains("edge out of terminal stage \"failure\""),
        "{message}"
    );
}

#[test]
fn an_unknown_stage_is_refused() {
    let text = edited(|v| v["transitions"][0]["to"] = "grasping".into());
    let message = refusal(&text);
    assert!(message.contains("unknown stage \"grasping\""), "{message}");
    assert!(message.contains("transitions[0]"), "{message}");
}

#[test]
fn an_unknown_event_or_feature_is_refused() {
    let message = refusal(&edited(|v| v["transitions"][1]["event"] = "oops".into()));
    assert!(message.contains("unknown event \"oops\""), "{message}");
    let message = refusal(&edited(|v| {
        v["stages"][1]["abstraction"][0] = "speed".into()
    }));
    assert!(message.contains("unknown feature \"speed\""), "{message}");
    assert!(message.contains("stages[1] (grasp)"), "{message}");
}

#[test]
fn an_unreachable_terminal_is_refused() {
    let text = edited(|v| {
        let edges = v["transitions"].as_array_mut().unwrap();
        edges.retain(|e| e["to"] != "failure");
    });
    let message = refusal(&text);
    assert!(
        message.contains("terminal stage \"failure\" is unreachable"),
        "{message}"
    );
}

#[test]
fn malformed_json_names_file_line_and_reason() {
    let message = refusal("{\n  \"name\": \"x\",\n  \"features\": 3\n}");
    assert!(message.contains("edited.json at line 3"), "{message}");
    assert!(message.contains("invalid type"), "{message}");
}

#[test]
fn unknown_fields_and_duplicate_edges_are_refused() {
    let message = refusal(&edited(|v| v["stages"][0]["speed"] = 1.into()));
    assert!(message.contains("unknown field `speed`"), "{message}");
    let message = refusal(&edited(|v| {
        let first = v["transitions"][0].clone();
        v["transitions"].as_array_mut().unwrap().push(first);
    }));
    assert!(
        message.contains("second edge for stage \"approach\" and event \"arrive\""),
        "{message}"
    );
}

#[test]
fn a_terminal_initial_stage_and_bad_scales_are_refused() {
    let message = refusal(&edited(|v| v["initial"] = "success".into()));
    assert!(
        message.contains("stage \"success\" is terminal"),
        "{message}"
    );
    let message = refusal(&edited(|v| {
        v["stages"][0]["actions"][0]["scale"] = (-1.0).into()
    }));
    assert!(
        message.contains("stages[0] (approach).actions[0].scale"),
        "{message}"
    );
}
