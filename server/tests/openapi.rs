//! The OpenAPI document covers every REST route, and the `crm-server` binary starts. (Being an
//! integration test of this package also makes `cargo test --workspace` build the binary
//! that the end-to-end tests in `tests/` start.)

#[test]
fn every_route_is_in_the_openapi_document() {
    let doc = document();
    let paths = doc["paths"].as_object().expect("paths");
    let source = include_str!("../src/api/mod.rs");
    let mut routes = Vec::new();
    // `.route("/path", ...)`, however rustfmt wraps it.
    for piece in source.split(".route(").skip(1) {
        let route = piece
            .trim_start()
            .strip_prefix('"')
            .and_then(|rest| rest.split('"').next())
            .expect("route");
        let full = if route == "/healthz" {
            route.to_string()
        } else {
            format!("/api/v1{route}")
        };
        routes.push(full);
    }
    assert!(routes.len() >= 15, "{routes:?}");
    for route in &routes {
        assert!(paths.contains_key(route), "{route} is not in openapi.json");
    }
    for path in paths.keys() {
        assert!(
            routes.contains(path),
            "openapi.json documents {path}, no such route"
        );
    }
}

#[test]
fn the_binary_refuses_bad_settings_with_exit_code_2() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_crm-server"))
        .args(["--lease-ttl-s", "1", "--heartbeat-interval-s", "5"])
        .output()
        .expect("run crm-server");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("lease_ttl_s"), "{stderr}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_crm-server"))
        .args(["--mlflow-uri", "localhost:5000"])
        .output()
        .expect("run crm-server");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("mlflow_uri"), "{stderr}");
}

#[test]
fn the_documents_sweep_axes_are_the_training_specs_fields() {
    let schemas = schemas();
    let listed = schemas["SweepRequest"]["properties"]["axes"]["properties"]
        .as_object()
        .expect("axes");
    let mut listed: Vec<&str> = listed.keys().map(String::as_str).collect();
    let mut axes = crm_server::api::axis_names();
    listed.sort_unstable();
    axes.sort_unstable();
    assert_eq!(listed, axes);
}

#[test]
fn the_documents_task_and_topology_enums_are_the_catalogs() {
    let catalog = crm_api::Catalog::builtin().expect("catalog");
    let ids: Vec<String> = catalog.tasks.iter().map(|t| t.id.clone()).collect();
    let mut topologies = vec!["task".to_string(), "auto".to_string()];
    topologies.extend(catalog.topologies.iter().cloned());
    let strings = |v: &serde_json::Value| -> Vec<String> {
        v.as_array()
            .expect("enum")
            .iter()
            .filter_map(|s| s.as_str().map(String::from))
            .collect()
    };
    let schemas = &schemas();
    let flat = ["TrainPpoRequest", "TrainOtherRequest", "EvalFlatRequest"];
    let documents = ["TrainPpoDocument", "TrainOtherDocument", "EvalDocument"];
    let envs = documents.map(|name| (name, &schemas[name]["properties"]["env"]["properties"]));
    for (name, props) in flat
        .map(|name| (name, &schemas[name]["properties"]))
        .into_iter()
        .chain(envs)
    {
        assert_eq!(strings(&props["task"]["enum"]), ids, "{name}.task");
        assert_eq!(
            strings(&props["tasks"]["items"]["enum"]),
            ids,
            "{name}.tasks"
        );
        assert_eq!(
            strings(&props["topology"]["enum"]),
            topologies,
            "{name}.topology"
        );
        // Both may be null (absent), and the enum says so (OpenAPI 3.0's nullable).
        for field in ["task", "topology"] {
            assert!(
                props[field]["enum"]
                    .as_array()
                    .expect("enum")
                    .contains(&serde_json::Value::Null)
            );
        }
    }
    // A cloning names the same tasks, and its palm shifts are keyed by them.
    let imitation = &schemas["ImitationSpec"]["properties"];
    assert_eq!(strings(&imitation["tasks"]["items"]["enum"]), ids);
    let mut keyed: Vec<String> = imitation["shifts"]["properties"]
        .as_object()
        .expect("shifts")
        .keys()
        .cloned()
        .collect();
    let mut sorted = ids.clone();
    keyed.sort();
    sorted.sort();
    assert_eq!(keyed, sorted);
    assert_eq!(
        strings(&imitation["stages"]["items"]["enum"]),
        crm_api::imitation::STAGES.map(String::from).to_vec()
    );
}

#[test]
fn the_documents_learner_settings_are_the_configs_fields() {
    let schemas = &schemas();
    use crm_api::fields::field_names;
    assert_eq!(
        keys(&schemas["PpoConfig"]["properties"]),
        fields(field_names::<crm_api::PpoConfig>())
    );
    assert_eq!(
        keys(&schemas["SacConfig"]["properties"]),
        fields(field_names::<crm_api::SacConfig>())
    );
    // Every value the document allows for the schedule parses.
    for value in schemas["PpoConfig"]["properties"]["lr_schedule"]["enum"]
        .as_array()
        .expect("lr_schedule enum")
    {
        let config = serde_json::json!({ "lr_schedule": value });
        serde_json::from_value::<crm_api::PpoConfig>(config).expect("a documented schedule");
    }
}

/// A train request's property is `nullable` in the document exactly when the server reads
/// `null` there as absent: schemathesis sends `null` wherever the document allows it and
/// expects a refusal wherever it does not.
#[test]
fn the_documents_nullable_train_fields_are_the_ones_the_server_accepts_as_null() {
    let schemas = &schemas();
    for name in ["TrainPpoRequest", "TrainOtherRequest", "SweepBase"] {
        let properties = schemas[name]["properties"].as_object().expect("properties");
        assert!(properties.contains_key("fine_tune"), "{name}");
        for (field, property) in properties {
            if field == "kind" {
                continue;
            }
            let mut body = serde_json::json!({"algorithm": "crm-ppo", "steps": 10});
            body[field] = serde_json::Value::Null;
            let accepted = serde_json::from_value::<crm_api::TrainSpec>(body).is_ok();
            let nullable = property["nullable"] == serde_json::Value::Bool(true);
            assert_eq!(
                accepted, nullable,
                "{name}.{field}: null accepted {accepted}"
            );
        }
    }
}

/// The experiment documents' parts list the fields their Rust types read, so that a field
/// added to one is documented.
#[test]
fn the_documents_experiment_parts_are_the_types_fields() {
    use crm_api::document::{AlgorithmSpec, EnvSpec, EvalRunSpec, RunSpec};
    use crm_api::fields::field_names;
    let schemas = &schemas();
    for name in ["TrainPpoDocument", "TrainOtherDocument", "EvalDocument"] {
        let parts = &schemas[name]["properties"];
        assert_eq!(
            keys(&parts["env"]["properties"]),
            fields(field_names::<EnvSpec>()),
            "{name}.env"
        );
    }
    for name in ["TrainPpoDocument", "TrainOtherDocument"] {
        let parts = &schemas[name]["properties"];
        assert_eq!(
            keys(&parts["algorithm"]["properties"]),
            fields(field_names::<AlgorithmSpec>()),
            "{name}.algorithm"
        );
    }
    // A learner other than the machine's PPO takes no imitation.
    let mut run = fields(field_names::<RunSpec>());
    assert_eq!(
        keys(&schemas["TrainPpoDocument"]["properties"]["run"]["properties"]),
        run
    );
    run.retain(|f| f != "imitation");
    assert_eq!(
        keys(&schemas["TrainOtherDocument"]["properties"]["run"]["properties"]),
        run
    );
    assert_eq!(
        keys(&schemas["EvalDocument"]["properties"]["run"]["properties"]),
        fields(field_names::<EvalRunSpec>())
    );
}

/// An object's keys, sorted.
fn keys(value: &serde_json::Value) -> Vec<String> {
    let mut keys: Vec<String> = value.as_object().expect("object").keys().cloned().collect();
    keys.sort();
    keys
}

/// Field names, sorted.
fn fields(names: &[&str]) -> Vec<String> {
    let mut names: Vec<String> = names.iter().map(|n| n.to_string()).collect();
    names.sort();
    names
}

/// The OpenAPI document the coordinator serves, parsed.
fn document() -> serde_json::Value {
    serde_json::from_str(crm_server::api::OPENAPI).expect("openapi.json is JSON")
}

/// The document's component schemas.
fn schemas() -> serde_json::Value {
    document()["components"]["schemas"].take()
}
