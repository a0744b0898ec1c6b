//! The grasp-topology selection network (paper, section II-B): a multi-class, multi-label MLP
//! from object features and a one-hot task objective to one probability per topology; the
//! highest probability picks the topology. Inputs and labels are plain vectors, so this crate
//! does not depend on the environment; `crm topology` builds them from the benchmark.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{D, DType, Device, Tensor, Var};
use candle_nn::{AdamW, Linear, Module, Optimizer, ParamsAdamW};

use crate::error::{Error, Result};
use crate::noise::Noise;

const FORMAT: &str = "crm-grasp-topology/1";
const HEADER_KEY: &str = "crm_grasp_topology";

/// One training example: network input and a multi-hot label over topologies.
#[derive(Clone, Debug, PartialEq)]
pub struct Example {
    pub input: Vec<f32>,
    pub label: Vec<f32>,
}

/// The network and its sizes.
pub struct TopologyNet {
    inputs: usize,
    outputs: usize,
    hidden: usize,
    layers: Vec<Linear>,
    params: Vec<(String, Var)>,
}

impl std::fmt::Debug for TopologyNet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TopologyNet")
            .field("inputs", &self.inputs)
            .field("outputs", &self.outputs)
            .field("hidden", &self.hidden)
            .finish_non_exhaustive()
    }
}

fn refuse(path: &Path, message: impl Into<String>) -> Error {
    Error::Checkpoint {
        path: path.display().to_string(),
        message: message.into(),
    }
}

impl TopologyNet {
    /// A two-layer MLP `inputs -> hidden -> outputs`, initialized from `seed`.
    pub fn new(inputs: usize, hidden: usize, outputs: usize, seed: u64) -> Result<Self> {
        let device = Device::Cpu;
        let mut noise = Noise::new(seed);
        let mut params = Vec::new();
        let mut layers = Vec::new();
        for (k, (i, o)) in [(inputs, hidden), (hidden, outputs)]
            .into_iter()
            .enumerate()
        {
            let bound = (6.0 / i as f32).sqrt() * 0.5;
            let weights: Vec<f32> = (0..i * o)
                .map(|_| (noise.normal() * bound / 2.0).clamp(-bound, bound))
                .collect();
            let weight = Var::from_vec(weights, (o, i), &device)?;
            let bias = Var::zeros(o, DType::F32, &device)?;
            layers.push(Linear::new(
                weight.as_tensor().clone(),
                Some(bias.as_tensor().clone()),
            ));
            params.push((format!("layer{k}.weight"), weight));
            params.push((format!("layer{k}.bias"), bias));
        }
        Ok(Self {
            inputs,
            outputs,
            hidden,
            layers,
            params,
        })
    }

    fn logits(&self, input: &Tensor) -> Result<Tensor> {
        let hidden = self.layers[0].forward(input)?.relu()?;
        Ok(self.layers[1].forward(&hidden)?)
    }

    fn batch(&self, examples: &[Example]) -> Result<(Tensor, Tensor)> {
        for e in examples {
            if e.input.len() != self.inputs || e.label.len() != self.outputs {
                return Err(Error::Length {
                    what: "topology example",
                    expected: self.inputs,
                    got: e.input.len(),
                });
            }
        }
        let device = Device::Cpu;
        let inputs: Vec<f32> = examples.iter().flat_map(|e| e.input.clone()).collect();
        let labels: Vec<f32> = examples.iter().flat_map(|e| e.label.clone()).collect();
        Ok((
            Tensor::from_vec(inputs, (examples.len(), self.inputs), &device)?,
            Tensor::from_vec(labels, (examples.len(), self.outputs), &device)?,
        ))
    }

    /// Trains with binary cross-entropy per topology (multi-label); returns the final loss.
    pub fn train(
        &mut self,
        examples: &[Example],
        epochs: usize,
        learning_rate: f64,
    ) -> Result<f32> {
        let (inputs, labels) = self.batch(examples)?;
        let vars = self.params.iter().map(|(_, v)| v.clone()).collect();
        let mut optimizer = AdamW::new(
            vars,
            ParamsAdamW {
                lr: learning_rate,
                weight_decay: 1e-4,
                ..ParamsAdamW::default()
            },
        )?;
        let mut last = f32::NAN;
        for _ in 0..epochs {
            let logits = self.logits(&inputs)?;
            // BCE with logits: max(x, 0) - x * y + log(1 + exp(-|x|)).
            let loss = ((logits.relu()? - (&logits * &labels)?)?
                + logits.abs()?.neg()?.exp()?.affine(1.0, 1.0)?.log()?)?
            .mean_all()?;
            optimizer.backward_step(&loss)?;
            last = loss.to_scalar()?;
        }
        Ok(last)
    }

    /// Probabilities per topology for each input row.
    pub fn predict(&self, inputs: &[Vec<f32>]) -> Result<Vec<Vec<f32>>> {
        let examples: Vec<Example> = inputs
            .iter()
            .map(|input| Example {
                input: input.clone(),
                label: vec![0.0; self.outputs],
            })
            .collect();
        let (inputs, _) = self.batch(&examples)?;
        Ok(candle_nn::ops::sigmoid(&self.logits(&inputs)?)?.to_vec2()?)
    }

    /// Share of examples whose highest-probability topology is one of their labels.
    pub fn accuracy(&self, examples: &[Example]) -> Result<f32> {
        let (inputs, labels) = self.batch(examples)?;
        let best = self.logits(&inputs)?.argmax(D::Minus1)?.to_vec1::<u32>()?;
        let labels: Vec<Vec<f32>> = labels.to_vec2()?;
        let hits = best
            .iter()
            .zip(&labels)
            .filter(|(b, l)| l[**b as usize] > 0.5)
            .count();
        Ok(hits as f32 / examples.len().max(1) as f32)
    }

    /// Saves the network with a header naming its sizes and its inputs and outputs.
    pub fn save(&self, path: &Path, input_names: &[String], output_names: &[String]) -> Result<()> {
        let header = serde_json::json!({
            "format": FORMAT,
            "inputs": self.inputs,
            "hidden": self.hidden,
            "outputs": self.outputs,
            "input_names": input_names,
            "output_names": output_names,
        });
        let metadata = HashMap::from([(HEADER_KEY.to_string(), header.to_string())]);
        let tensors: Vec<(&str, &Tensor)> = self
            .params
            .iter()
            .map(|(n, v)| (n.as_str(), v.as_tensor()))
            .collect();
        safetensors::serialize_to_file(tensors, Some(metadata), path)
            .map_err(|e| refuse(path, format!("cannot write: {e}")))
    }

    /// Loads a saved network; returns it with its input and output names.
    pub fn load(path: &Path) -> Result<(Self, Vec<String>, Vec<String>)> {
        let bytes = std::fs::read(path).map_err(|e| refuse(path, format!("cannot read: {e}")))?;
        Self::from_bytes(&bytes, path)
    }

    /// Loads a saved network from its bytes; `path` names it in errors.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<(Self, Vec<String>, Vec<String>)> {
        let (_, metadata) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| refuse(path, format!("not a safetensors file ({e})")))?;
        let header: serde_json::Value = metadata
            .metadata()
            .as_ref()
            .and_then(|m| m.get(HEADER_KEY))
            .and_then(|json| serde_json::from_str(json).ok())
            .ok_or_else(|| refuse(path, "not a topology network (no header)"))?;
        if header["format"] != FORMAT {
            return Err(refuse(
                path,
                format!("format {}, this build reads {FORMAT}", header["format"]),
            ));
        }
        let size = |key: &str| {
            header[key]
                .as_u64()
                .map(|v| v as usize)
                .ok_or_else(|| refuse(path, format!("header lacks {key}")))
        };
        let names = |key: &str| -> Vec<String> {
            header[key]
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_str().map(String::from))
                        .collect()
                })
                .unwrap_or_default()
        };
        let net = Self::new(size("inputs")?, size("hidden")?, size("outputs")?, 0)?;
        let tensors = candle_core::safetensors::load_buffer(bytes, &Device::Cpu)?;
        for (name, var) in &net.params {
            let tensor = tensors
                .get(name)
                .ok_or_else(|| refuse(path, format!("missing tensor {name}")))?;
            var.set(tensor)?;
        }
        Ok((net, names("input_names"), names("output_names")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two separable classes and one input that carries two labels.
    fn examples() -> Vec<Example> {
        let mut out = Vec::new();
        let mut noise = Noise::new(3);
        for k in 0..60 {
            let class = k % 3;
            let mut input = vec![0.0; 4];
            input[class] = 1.0;
            input[3] = 0.1 * noise.normal();
            let label = match class {
                0 => vec![1.0, 0.0, 0.0],
                1 => vec![0.0, 1.0, 0.0],
                _ => vec![0.0, 1.0, 1.0],
            };
            out.push(Example { input, label });
        }
        out
    }

    #[test]
    fn it_learns_a_multi_label_mapping_and_round_trips() {
        let data = examples();
        let mut net = TopologyNet::new(4, 16, 3, 1).expect("net");
        let before = net.accuracy(&data).expect("accuracy");
        let loss = net.train(&data, 300, 0.02).expect("train");
        assert!(loss < 0.1, "loss {loss}");
        assert_eq!(
            net.accuracy(&data).expect("accuracy"),
            1.0,
            "before training {before}"
        );
        let probs = net.predict(&[vec![0.0, 0.0, 1.0, 0.0]]).expect("predict");
        assert!(
            probs[0][1] > 0.8 && probs[0][2] > 0.8 && probs[0][0] < 0.2,
            "{probs:?}"
        );

        let path =
            std::env::temp_dir().join(format!("crm-topology-{}.safetensors", std::process::id()));
        let names = |n: usize| (0..n).map(|k| format!("f{k}")).collect::<Vec<_>>();
        net.save(&path, &names(4), &names(3)).expect("save");
        let (loaded, inputs, outputs) = TopologyNet::load(&path).expect("load");
        assert_eq!((inputs.len(), outputs.len()), (4, 3));
        assert_eq!(
            loaded
                .predict(&[vec![0.0, 0.0, 1.0, 0.0]])
                .expect("predict"),
            probs
        );
        std::fs::write(&path, b"junk").expect("write");
        assert!(TopologyNet::load(&path).is_err());
        std::fs::remove_file(&path).ok();
    }
}
