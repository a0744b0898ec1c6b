//! The built-in benchmark and grasping spec: sizes, coverage, the paper's reward ordering, and
//! clear refusals of malformed files.

use grasp_sim::Benchmark;
use grasp_sim::benchmark::{Objective, Topology};
use grasp_sim::spec::{check_compatible, grasping_machine, grasping_spec};

#[test]
fn the_benchmark_has_20_objects_7_objectives_6_topologies_and_26_tasks() {
    let benchmark = Benchmark::builtin();
    assert_eq!(benchmark.objects.len(), 20);
    assert_eq!(benchmark.tasks.len(), 26);
    for objective in Objective::ALL {
        assert!(
            benchmark.tasks.iter().any(|t| t.objective == objective),
            "no task for {objective:?}"
        );
    }
    for topology in Topology::ALL {
        assert!(
            benchmark.tasks.iter().any(|t| t.topology == topology),
            "no task for {topology:?}"
        );
    }
    for object in &benchmark.objects {
        assert!(
            benchmark.tasks.iter().any(|t| t.object == object.name),
            "object {} has no task",
            object.name
        );
        let dims = object.dimensions();
        assert!(
            dims.iter().all(|d| *d > 0.005 && *d < 0.4),
            "{}: {dims:?}",
            object.name
        );
        assert_eq!(
            object.features().len(),
            grasp_sim::benchmark::OBJECT_FEATURES.len()
        );
    }
}

#[test]
fn the_grasping_spec_fits_the_environment_and_orders_rewards_as_the_paper_requires() {
    let spec = grasping_spec();
    check_compatible(&spec).expect("built-in spec fits the environment");
    let machine = grasping_machine();
    let stage = |name: &str| machine.stage_id(name).expect(name);
    let event = |name: &str| machine.event_id(name).expect(name);
    let approach = stage("approach");
    let grasp = stage("grasp");
    let r_arrive = machine
        .edge_reward(approach, event("arrive"))
        .expect("arrive edge");
    let r_aor = machine
        .edge_reward(approach, event("aor"))
        .expect("aor edge");
    let r_gor = machine.edge_reward(grasp, event("gor")).expect("gor edge");
    let r_fail = machine
        .edge_reward(grasp, event("fail"))
        .expect("fail edge");
    let r_succ = machine
        .edge_reward(grasp, event("succ"))
        .expect("succ edge");
    // Paper, section IV-D: R_aor < R_gor < R_fail < 0 < R_arrive, success the largest.
    assert!(
        r_aor < r_gor && r_gor < r_fail && r_fail < 0.0 && 0.0 < r_arrive,
        "{r_aor} {r_gor} {r_fail} {r_arrive}"
    );
    assert!(r_succ > r_arrive);
    // R_arrive is above the best reward the approach stage can give.
    assert!(r_arrive > machine.best_intra_reward(approach));
    // The approach stage moves the palm only; the grasp stage adds the five fingers.
    assert_eq!(machine.action_dims(approach).count(), 3);
    assert_eq!(machine.action_dims(grasp).count(), 8);
    for terminal in ["out_of_reach", "success", "failure"] {
        assert!(machine.is_terminal(stage(terminal)));
    }
    // The approach stage cannot fail or succeed directly (paper, section IV-A).
    assert!(machine.edge_reward(approach, event("succ")).is_none());
    assert!(machine.edge_reward(approach, event("fail")).is_none());
}

#[test]
fn a_malformed_benchmark_file_is_refused_with_file_path_and_reason() {
    let builtin = Benchmark::builtin();
    let mut value = serde_json::to_value(&builtin).expect("serializes");
    value["tasks"][3]["object"] = "teapot".into();
    let err = Benchmark::from_json(&value.to_string(), "edited.json")
        .expect_err("unknown object")
        .to_string();
    assert!(
        err.contains("edited.json")
            && err.contains("tasks[3]")
            && err.contains("unknown object \"teapot\""),
        "{err}"
    );

    let mut value = serde_json::to_value(&builtin).expect("serializes");
    value["objects"][0]["mass"] = (-1.0).into();
    let err = Benchmark::from_json(&value.to_string(), "edited.json")
        .expect_err("negative mass")
        .to_string();
    assert!(err.contains("objects[0] (mug).mass"), "{err}");

    let err = Benchmark::from_json("{\"objects\": [], \"tasks\": 7}", "bad.json")
        .expect_err("type error")
        .to_string();
    assert!(err.contains("bad.json at line 1"), "{err}");

    let dir = std::env::temp_dir().join("grasp-sim-missing-benchmark.json");
    let err = Benchmark::load(&dir).expect_err("missing file").to_string();
    assert!(err.contains("grasp-sim-missing-benchmark.json"), "{err}");
}

#[test]
fn a_spec_that_does_not_fit_the_environment_is_refused() {
    let mut spec = grasping_spec();
    spec.features.swap(0, 1);
    let err = check_compatible(&spec)
        .expect_err("swapped features")
        .to_string();
    assert!(err.contains("features[0]"), "{err}");
    let mut spec = grasping_spec();
    spec.events.push("teleport".into());
    let err = check_compatible(&spec)
        .expect_err("unknown event")
        .to_string();
    assert!(err.contains("teleport"), "{err}");
}

#[test]
fn the_flat_ablation_spec_is_one_stage_with_every_action() {
    let spec = grasp_sim::spec::flat_spec();
    check_compatible(&spec).expect("flat spec fits the environment");
    let machine = crm::Machine::from_spec(spec).expect("valid");
    let task = machine.initial();
    assert_eq!(machine.action_dims(task).count(), 8);
    let stages: Vec<usize> = (0..machine.stage_count())
        .filter(|&s| !machine.is_terminal(s))
        .collect();
    assert_eq!(stages, vec![task]);
}

/// The flat machine's reward is the staged machine's intra-stage terms summed (docs/LEARNING.md,
/// "The baselines' rewards"), and its terminal transitions pay what the staged ones do: the
/// two specs cannot drift apart.
#[test]
fn the_flat_ablation_rewards_are_the_staged_machines() {
    let (flat, staged) = (grasp_sim::spec::flat_spec(), grasping_spec());
    let staged_terms: Vec<_> = staged
        .stages
        .iter()
        .filter(|s| !s.terminal)
        .flat_map(|s| s.reward.clone())
        .collect();
    let task = flat.stages.iter().find(|s| !s.terminal).expect("one stage");
    assert_eq!(task.reward, staged_terms);
    for edge in &flat.transitions {
        let same = staged
            .transitions
            .iter()
            .find(|e| e.event == edge.event && e.to == edge.to)
            .unwrap_or_else(|| panic!("the staged machine has no {} edge", edge.event));
        assert_eq!(
            (edge.reward, &edge.bonus),
            (same.reward, &same.bonus),
            "{}",
            edge.event
        );
    }
}
