//! `Machine::from_spec`: resolving names to indices and refusing invalid specs with the
//! offending name in the message.

use std::collections::{BTreeSet, VecDeque};

use super::{Edge, Machine, Stage, StageId};
use crate::error::{Result, invalid};
use crate::reward::{CompiledTerm, RewardTerm};
use crate::spec::Spec;

pub(super) fn index_of(names: &[String], wanted: &str) -> Option<usize> {
    names.iter().position(|name| name == wanted)
}

fn check_unique(names: &[String], what: &str) -> Result<()> {
    let mut seen = BTreeSet::new();
    for (i, name) in names.iter().enumerate() {
        if name.is_empty() {
            return Err(invalid(format!("{what}[{i}]"), "empty name"));
        }
        if !seen.insert(name.as_str()) {
            return Err(invalid(
                format!("{what}[{i}]"),
                format!("duplicate name {name:?}"),
            ));
        }
    }
    Ok(())
}

fn compile_term(term: &RewardTerm, features: &[String], at: &str) -> Result<CompiledTerm> {
    let feature = |name: &str| {
        index_of(features, name)
            .ok_or_else(|| invalid(at, format!("unknown feature {name:?} in reward term")))
    };
    let finite = |value: f32, field: &str| {
        if value.is_finite() {
            Ok(value)
        } else {
            Err(invalid(format!("{at}.{field}"), "must be finite"))
        }
    };
    Ok(match term {
        RewardTerm::Linear {
            feature: name,
            coef,
        } => CompiledTerm::Linear {
            index: feature(name)?,
            coef: finite(*coef, "coef")?,
        },
        RewardTerm::NegExpNorm {
            features: names,
            coef,
            scale,
            cap,
        } => {
            if names.is_empty() {
                return Err(invalid(at, "neg_exp_norm needs at least one feature"));
            }
            CompiledTerm::NegExpNorm {
                indices: names.iter().map(|n| feature(n)).collect::<Result<_>>()?,
                coef: finite(*coef, "coef")?,
                scale: finite(*scale, "scale")?,
                cap: finite(*cap, "cap")?,
            }
        }
        RewardTerm::Constant { value } => CompiledTerm::Constant {
            value: finite(*value, "value")?,
        },
    })
}

impl Machine {
    /// Validates a spec: unique names, known stages, events, features and action dimensions,
    /// no edge out of a terminal stage, one edge at most per `(stage, event)`, and every
    /// terminal stage reachable from the initial one. Errors name the offending item.
    pub fn from_spec(spec: Spec) -> Result<Self> {
        check_unique(&spec.features, "features")?;
        check_unique(&spec.action_dims, "action_dims")?;
        check_unique(&spec.events, "events")?;
        let stage_names: Vec<String> = spec.stages.iter().map(|s| s.name.clone()).collect();
        check_unique(&stage_names, "stages")?;

        let mut stages = Vec::with_capacity(spec.stages.len());
        for (i, stage) in spec.stages.iter().enumerate() {
            let at = format!("stages[{i}] ({})", stage.name);
            if stage.terminal && !stage.actions.is_empty() {
                return Err(invalid(&at, "a terminal stage has no actions"));
            }
            let mut actions = Vec::new();
            let mut seen_dims = BTreeSet::new();
            for (k, action) in stage.actions.iter().enumerate() {
                let dim = index_of(&spec.action_dims, &action.dim).ok_or_else(|| {
                    invalid(
                        format!("{at}.actions[{k}]"),
                        format!("unknown action dimension {:?}", action.dim),
                    )
                })?;
                if !seen_dims.insert(dim) {
                    return Err(invalid(
                        format!("{at}.actions[{k}]"),
                        format!("duplicate action dimension {:?}", action.dim),
                    ));
                }
                if !(action.scale.is_finite() && action.scale > 0.0) {
                    return Err(invalid(
                        format!("{at}.actions[{k}].scale"),
                        "must be finite and positive",
                    ));
                }
                actions.push((dim, action.scale));
            }
            let abstraction = stage
                .abstraction
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    index_of(&spec.features, name).ok_or_else(|| {
                        invalid(
                            format!("{at}.abstraction[{k}]"),
                            format!("unknown feature {name:?}"),
                        )
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            let reward = stage
                .reward
                .iter()
                .enumerate()
                .map(|(k, term)| compile_term(term, &spec.features, &format!("{at}.reward[{k}]")))
                .collect::<Result<Vec<_>>>()?;
            stages.push(Stage {
                name: stage.name.clone(),
                terminal: stage.terminal,
                actions,
                abstraction,
                reward,
            });
        }

        let initial = index_of(&stage_names, &spec.initial)
            .ok_or_else(|| invalid("initial", format!("unknown stage {:?}", spec.initial)))?;
        if stages[initial].terminal {
            return Err(invalid(
                "initial",
                format!("stage {:?} is terminal", spec.initial),
            ));
        }

        let mut edges: Vec<Vec<Option<Edge>>> = vec![vec![None; spec.events.len()]; stages.len()];
        for (i, edge) in spec.transitions.iter().enumerate() {
            let at = format!("transitions[{i}]");
            let from = index_of(&stage_names, &edge.from)
                .ok_or_else(|| invalid(&at, format!("unknown stage {:?}", edge.from)))?;
            let to = index_of(&stage_names, &edge.to)
                .ok_or_else(|| invalid(&at, format!("unknown stage {:?}", edge.to)))?;
            let event = index_of(&spec.events, &edge.event)
                .ok_or_else(|| invalid(&at, format!("unknown event {:?}", edge.event)))?;
            if stages[from].terminal {
                return Err(invalid(
                    &at,
                    format!("edge out of terminal stage {:?}", edge.from),
                ));
            }
            if from == to {
                return Err(invalid(&at, format!("self-loop on stage {:?}", edge.from)));
            }
            if !edge.reward.is_finite() {
                return Err(invalid(format!("{at}.reward"), "must be finite"));
            }
            if edges[from][event].is_some() {
                return Err(invalid(
                    &at,
                    format!(
                        "second edge for stage {:?} and event {:?}",
                        edge.from, edge.event
                    ),
                ));
            }
            let bonus = edge
                .bonus
                .iter()
                .enumerate()
                .map(|(k, b)| {
                    let index = index_of(&spec.features, &b.feature).ok_or_else(|| {
                        invalid(
                            format!("{at}.bonus[{k}]"),
                            format!("unknown feature {:?}", b.feature),
                        )
                    })?;
                    if !b.reward.is_finite() {
                        return Err(invalid(format!("{at}.bonus[{k}].reward"), "must be finite"));
                    }
                    Ok((index, b.reward))
                })
                .collect::<Result<Vec<_>>>()?;
            edges[from][event] = Some(Edge {
                to,
                reward: edge.reward,
                bonus,
            });
        }

        let reachable = reachable_from(initial, &edges);
        if !stages.iter().any(|s| s.terminal) {
            return Err(invalid("stages", "no terminal stage"));
        }
        for (id, stage) in stages.iter().enumerate() {
            if stage.terminal && !reachable.contains(&id) {
                return Err(invalid(
                    "stages",
                    format!(
                        "terminal stage {:?} is unreachable from {:?}",
                        stage.name, spec.initial
                    ),
                ));
            }
            if !stage.terminal && edges[id].iter().all(Option::is_none) {
                return Err(invalid(
                    "transitions",
                    format!("non-terminal stage {:?} has no edge out", stage.name),
                ));
            }
        }

        Ok(Self {
            spec,
            stages,
            initial,
            edges,
        })
    }
}

fn reachable_from(start: StageId, edges: &[Vec<Option<Edge>>]) -> BTreeSet<StageId> {
    let mut seen = BTreeSet::from([start]);
    let mut queue = VecDeque::from([start]);
    while let Some(stage) = queue.pop_front() {
        for edge in edges[stage].iter().flatten() {
            if seen.insert(edge.to) {
                queue.push_back(edge.to);
            }
        }
    }
    seen
}
