//! A small three-stage machine shared by the crate's integration tests.

pub const TOY_SPEC: &str = r#"{
  "name": "toy",
  "features": ["dist", "n_c", "cone"],
  "action_dims": ["dx", "grip"],
  "events": ["arrive", "oor", "succ", "fail"],
  "initial": "approach",
  "stages": [
    {"name": "approach", "actions": [{"dim": "dx", "scale": 0.01}], "abstraction": ["dist"],
     "reward": [{"kind": "neg_exp_norm", "features": ["dist"]}, {"kind": "linear", "feature": "n_c", "coef": -0.5}]},
    {"name": "grasp", "actions": [{"dim": "dx", "scale": 0.002}, {"dim": "grip", "scale": 0.1}],
     "abstraction": ["dist", "n_c", "cone"],
     "reward": [{"kind": "linear", "feature": "n_c", "coef": 0.2}, {"kind": "constant", "value": -0.1}]},
    {"name": "out_of_reach", "terminal": true},
    {"name": "success", "terminal": true},
    {"name": "failure", "terminal": true}
  ],
  "transitions": [
    {"from": "approach", "event": "arrive", "to": "grasp", "reward": 10.0},
    {"from": "approach", "event": "oor", "to": "out_of_reach", "reward": -100.0},
    {"from": "grasp", "event": "oor", "to": "out_of_reach", "reward": -50.0},
    {"from": "grasp", "event": "fail", "to": "failure", "reward": -20.0},
    {"from": "grasp", "event": "succ", "to": "success", "reward": 100.0,
     "bonus": [{"feature": "cone", "reward": 5.0}]}
  ]
}"#;

#[allow(dead_code)] // Not every test file uses it.
pub fn toy_machine() -> crm::Machine {
    let spec = crm::Spec::from_json(TOY_SPEC, "toy").expect("toy spec parses");
    crm::Machine::from_spec(spec).expect("toy spec is valid")
}
