//! A policy as an ONNX model for a robot's runtime (ONNX Runtime, TensorRT, ...), the
//! deterministic action `crm` itself takes (`crm eval --deterministic`, `crm serve-policy`):
//! the observation normalization of the stage, the stage's one-hot encoding, the network, the
//! action's squashing and the stage's action mask, in one graph (opset 17).
//!
//! Inputs: `observation` `float[N, W]`, each row the stage's abstract state (its features in
//! the order `crm.observation_features` names for the stage, zero-padded to `W`), and `stage`
//! `int64[N]`, the stage's index in `crm.stages`. Outputs: `action` `float[N, A]`, the policy's
//! action over the union action space as `crm` computes it (zero outside the stage's action
//! set), and `action_clipped`, the same clipped to `[-1, 1]` as the machine takes it (it then
//! scales each dimension). PPO learners: the Gaussian's mean, and on the dimensions the
//! environment folds (`crm.folded`) the mean magnitude of the clipped sampled action, by the
//! same Simpson rule as `crate::folded`; CRM-SAC: `tanh` of the mean.

mod proto;

use prost::Message;

use crate::error::{Error, Result};
use crate::network::{ActorCritic, Layout};
use crate::normalize::ObsNorm;
use crate::sac::SacNets;
use proto::{Attribute, Dimension, Graph, Model, Node, OperatorSetId, StringEntry, Tensor};

/// What the graph needs besides the networks.
pub struct Context<'a> {
    pub machine: &'a crm::Machine,
    /// Dimensions the environment takes the magnitude of (`SimConfig::folded_actions`).
    pub folded: &'a [bool],
    /// `metadata_props` besides the layout's: world hash, lineage, algorithm, ...
    pub metadata: Vec<(String, String)>,
}

/// Simpson's rule of `crate::folded`: its nodes and weights.
const INTERVALS: usize = 512;
const HALF_WIDTH: f64 = 8.0;
/// As `normalize.rs`.
const NORM_EPSILON: f64 = 1e-8;

#[derive(Default)]
struct Builder {
    nodes: Vec<Node>,
    initializers: Vec<Tensor>,
    count: usize,
}

impl Builder {
    fn constant(&mut self, name: &str, dims: &[usize], data: Vec<f32>) -> String {
        self.initializers.push(Tensor {
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: proto::FLOAT,
            float_data: data,
            name: name.to_string(),
            ..Tensor::default()
        });
        name.to_string()
    }

    fn ints(&mut self, name: &str, data: Vec<i64>) -> String {
        self.initializers.push(Tensor {
            dims: vec![data.len() as i64],
            data_type: proto::INT64,
            int64_data: data,
            name: name.to_string(),
            ..Tensor::default()
        });
        name.to_string()
    }

    /// One node; returns its output's name.
    fn op(&mut self, op: &str, inputs: &[&str], attributes: Vec<Attribute>) -> String {
        self.count += 1;
        let output = format!("{}_{}", op.to_lowercase(), self.count);
        self.nodes.push(Node {
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![output.clone()],
            name: output.clone(),
            op_type: op.to_string(),
            attribute: attributes,
        });
        output
    }

    fn named(&mut self, op: &str, inputs: &[&str], output: &str) {
        self.nodes.push(Node {
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![output.to_string()],
            name: output.to_string(),
            op_type: op.to_string(),
            attribute: Vec::new(),
        });
    }
}

fn int_attr(name: &str, value: i64) -> Attribute {
    Attribute {
        name: name.into(),
        i: value,
        r#type: 2,
        ..Attribute::default()
    }
}

/// One dense layer: the weight's dimensions `[out, in]`, the weight and the bias.
type Layer = (Vec<usize>, Vec<f32>, Vec<f32>);

/// The named parameters `PREFIX.K.weight` and `PREFIX.K.bias` in layer order.
fn layers(params: &[(String, candle_core::Var)], prefix: &str) -> Result<Vec<Layer>> {
    let find = |name: &str| params.iter().find(|(n, _)| n == name).map(|(_, v)| v);
    let mut out = Vec::new();
    for k in 0.. {
        let (Some(weight), Some(bias)) = (
            find(&format!("{prefix}.{k}.weight")),
            find(&format!("{prefix}.{k}.bias")),
        ) else {
            break;
        };
        let dims = weight.as_tensor().dims().to_vec();
        let w = weight.as_tensor().flatten_all()?.to_vec1::<f32>()?;
        let b = bias.as_tensor().to_vec1::<f32>()?;
        out.push((dims, w, b));
    }
    if out.is_empty() {
        return Err(Error::Config {
            field: "checkpoint",
            message: format!("no {prefix} layers"),
        });
    }
    Ok(out)
}

/// The graph's front: the stage's normalization of the observation and its one-hot,
/// concatenated (the network's input). Also returns the stage's action mask.
fn encode(
    b: &mut Builder,
    layout: Layout,
    norm: &ObsNorm,
    machine: &crm::Machine,
) -> (String, String) {
    let (stages, width, actions) = (layout.stages, layout.state_width, layout.actions);
    let (mean, var, _) = norm.to_parts();
    let mut shift = vec![0.0f32; stages * width];
    let mut scale = vec![1.0f32; stages * width];
    let mut present = vec![0.0f32; stages * width];
    for s in 0..stages {
        let len = machine
            .spec()
            .stages
            .get(s)
            .map_or(0, |st| st.abstraction.len());
        for k in 0..width {
            let i = s * width + k;
            if k < len {
                shift[i] = mean.get(i).copied().unwrap_or(0.0) as f32;
                scale[i] =
                    (1.0 / (var.get(i).copied().unwrap_or(1.0) + NORM_EPSILON).sqrt()) as f32;
                present[i] = 1.0;
            }
        }
    }
    let mut eye = vec![0.0f32; stages * stages];
    for s in 0..stages {
        eye[s * stages + s] = 1.0;
    }
    let masks: Vec<f32> = (0..stages).flat_map(|s| machine.action_mask(s)).collect();
    b.constant("norm_shift", &[stages, width], shift);
    b.constant("norm_scale", &[stages, width], scale);
    b.constant("norm_present", &[stages, width], present);
    b.constant("stage_one_hot", &[stages, stages], eye);
    b.constant("stage_masks", &[stages, actions], masks);
    b.constant("clip_obs_low", &[], vec![-crate::normalize::CLIP_OBS]);
    b.constant("clip_obs_high", &[], vec![crate::normalize::CLIP_OBS]);
    let gather =
        |b: &mut Builder, table: &str| b.op("Gather", &[table, "stage"], vec![int_attr("axis", 0)]);
    let shift = gather(b, "norm_shift");
    let scale = gather(b, "norm_scale");
    let present = gather(b, "norm_present");
    let one_hot = gather(b, "stage_one_hot");
    let mask = gather(b, "stage_masks");
    let centered = b.op("Sub", &["observation", &shift], vec![]);
    let z = b.op("Mul", &[&centered, &scale], vec![]);
    let clipped = b.op("Clip", &[&z, "clip_obs_low", "clip_obs_high"], vec![]);
    let normalized = b.op("Mul", &[&clipped, &present], vec![]);
    let input = b.op(
        "Concat",
        &[&normalized, &one_hot],
        vec![int_attr("axis", 1)],
    );
    (input, mask)
}

/// The MLP: `Gemm` per layer, `activation` between.
fn mlp(b: &mut Builder, input: &str, prefix: &str, layers: &[Layer], activation: &str) -> String {
    let mut x = input.to_string();
    for (k, (dims, w, bias)) in layers.iter().enumerate() {
        let wn = b.constant(&format!("{prefix}.{k}.weight"), dims, w.clone());
        let bn = b.constant(&format!("{prefix}.{k}.bias"), &[bias.len()], bias.clone());
        x = b.op("Gemm", &[&x, &wn, &bn], vec![int_attr("transB", 1)]);
        if k + 1 < layers.len() {
            x = b.op(activation, &[&x], vec![]);
        }
    }
    x
}

/// `E[|clip(a, -1, 1)|]` for `a ~ N(mean, std^2)` per dimension, by `crate::folded`'s rule.
fn folded_mean(b: &mut Builder, mean: &str, std: &[f32]) -> String {
    let n = INTERVALS + 1;
    let h = 2.0 * HALF_WIDTH / INTERVALS as f64;
    let norm = h / 3.0 / (2.0 * std::f64::consts::PI).sqrt();
    let mut offsets = Vec::with_capacity(std.len() * n);
    for &s in std {
        for k in 0..n {
            let z = -HALF_WIDTH + h * k as f64;
            offsets.push((f64::from(s.max(0.0)) * z) as f32);
        }
    }
    let weights: Vec<f32> = (0..n)
        .map(|k| {
            let z = -HALF_WIDTH + h * k as f64;
            let w = match k {
                0 => 1.0,
                k if k == INTERVALS => 1.0,
                k if k % 2 == 1 => 4.0,
                _ => 2.0,
            };
            (w * (-0.5 * z * z).exp() * norm) as f32
        })
        .collect();
    b.constant("folded_offsets", &[1, std.len(), n], offsets);
    b.constant("folded_weights", &[n], weights);
    b.constant("unit_low", &[], vec![-1.0]);
    b.constant("unit_high", &[], vec![1.0]);
    b.ints("axis_two", vec![2]);
    let column = b.op("Unsqueeze", &[mean, "axis_two"], vec![]);
    let points = b.op("Add", &[&column, "folded_offsets"], vec![]);
    let clipped = b.op("Clip", &[&points, "unit_low", "unit_high"], vec![]);
    let magnitude = b.op("Abs", &[&clipped], vec![]);
    let weighted = b.op("Mul", &[&magnitude, "folded_weights"], vec![]);
    b.op(
        "ReduceSum",
        &[&weighted, "axis_two"],
        vec![int_attr("keepdims", 0)],
    )
}

fn value_info(name: &str, elem: i32, dims: Vec<Dimension>, doc: &str) -> proto::ValueInfo {
    proto::ValueInfo {
        name: name.into(),
        r#type: Some(proto::Type {
            tensor_type: Some(proto::TensorType {
                elem_type: elem,
                shape: Some(proto::Shape { dim: dims }),
            }),
        }),
        doc_string: doc.into(),
    }
}

fn batch() -> Dimension {
    Dimension {
        value: Some(proto::dimension::Value::DimParam("N".into())),
    }
}

fn size(n: usize) -> Dimension {
    Dimension {
        value: Some(proto::dimension::Value::DimValue(n as i64)),
    }
}

/// The model around a graph whose last node wrote `action` (before its clip).
fn finish(mut b: Builder, layout: Layout, ctx: &Context<'_>, doc: &str) -> Result<Vec<u8>> {
    b.named(
        "Clip",
        &["action", "unit_low", "unit_high"],
        "action_clipped",
    );
    let machine = ctx.machine;
    let spec = machine.spec();
    let stages: Vec<&str> = (0..layout.stages).map(|s| machine.stage_name(s)).collect();
    let features: serde_json::Value = spec
        .stages
        .iter()
        .map(|s| (s.name.clone(), serde_json::json!(s.abstraction)))
        .collect::<serde_json::Map<_, _>>()
        .into();
    let mut metadata = vec![
        (
            "crm.stages".to_string(),
            serde_json::to_string(&stages).unwrap_or_default(),
        ),
        ("crm.observation_features".to_string(), features.to_string()),
        (
            "crm.actions".to_string(),
            serde_json::to_string(&spec.action_dims).unwrap_or_default(),
        ),
        (
            "crm.folded".to_string(),
            serde_json::to_string(ctx.folded).unwrap_or_default(),
        ),
        (
            "crm.observation_width".to_string(),
            layout.state_width.to_string(),
        ),
    ];
    metadata.extend(ctx.metadata.iter().cloned());
    let graph = Graph {
        node: b.nodes,
        name: "crm_policy".into(),
        initializer: b.initializers,
        doc_string: doc.into(),
        input: vec![
            value_info(
                "observation",
                proto::FLOAT,
                vec![batch(), size(layout.state_width)],
                "the stage's abstract state, features in crm.observation_features' order, zero-padded",
            ),
            value_info(
                "stage",
                proto::INT64,
                vec![batch()],
                "the stage's index in crm.stages",
            ),
        ],
        output: vec![
            value_info(
                "action",
                proto::FLOAT,
                vec![batch(), size(layout.actions)],
                "the deterministic action over crm.actions, zero outside the stage's set",
            ),
            value_info(
                "action_clipped",
                proto::FLOAT,
                vec![batch(), size(layout.actions)],
                "action clipped to [-1, 1], as the machine takes it before scaling",
            ),
        ],
    };
    let model = Model {
        ir_version: 8,
        producer_name: "crm-grasp".into(),
        producer_version: env!("CARGO_PKG_VERSION").into(),
        doc_string: doc.into(),
        graph: Some(graph),
        opset_import: vec![OperatorSetId {
            domain: String::new(),
            version: 17,
        }],
        metadata_props: metadata
            .into_iter()
            .map(|(key, value)| StringEntry { key, value })
            .collect(),
    };
    Ok(model.encode_to_vec())
}

/// A PPO learner's deterministic policy as an ONNX model.
pub fn export_ppo(net: &ActorCritic, ctx: &Context<'_>) -> Result<Vec<u8>> {
    let layout = net.layout();
    let mut b = Builder::default();
    let (input, mask) = encode(&mut b, layout, net.norm(), ctx.machine);
    let mean = mlp(
        &mut b,
        &input,
        "actor",
        &layers(net.params(), "actor")?,
        "Tanh",
    );
    let std = net.std()?;
    let folded = folded_mean(&mut b, &mean, &std);
    // Folded dimensions take the mean magnitude, the others the mean: mean + f * (folded - mean).
    let flags: Vec<f32> = (0..layout.actions)
        .map(|k| {
            if ctx.folded.get(k).copied().unwrap_or(false) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    b.constant("folded_flags", &[layout.actions], flags);
    let gap = b.op("Sub", &[&folded, &mean], vec![]);
    let chosen_gap = b.op("Mul", &[&gap, "folded_flags"], vec![]);
    let chosen = b.op("Add", &[&mean, &chosen_gap], vec![]);
    b.named("Mul", &[&chosen, &mask], "action");
    finish(
        b,
        layout,
        ctx,
        "crm-grasp PPO policy: the deterministic action",
    )
}

/// CRM-SAC's deterministic policy (`tanh` of the mean) as an ONNX model.
pub fn export_sac(nets: &SacNets, ctx: &Context<'_>) -> Result<Vec<u8>> {
    let layout = nets.layout;
    let mut b = Builder::default();
    let (input, mask) = encode(&mut b, layout, nets.norm(), ctx.machine);
    let out = mlp(
        &mut b,
        &input,
        "actor",
        &layers(&nets.params, "actor")?,
        "Relu",
    );
    b.ints("slice_start", vec![0]);
    b.ints("slice_end", vec![layout.actions as i64]);
    b.ints("slice_axis", vec![1]);
    let mean = b.op(
        "Slice",
        &[&out, "slice_start", "slice_end", "slice_axis"],
        vec![],
    );
    let squashed = b.op("Tanh", &[&mean], vec![]);
    b.constant("unit_low", &[], vec![-1.0]);
    b.constant("unit_high", &[], vec![1.0]);
    b.named("Mul", &[&squashed, &mask], "action");
    finish(
        b,
        layout,
        ctx,
        "crm-grasp CRM-SAC policy: the deterministic action",
    )
}
