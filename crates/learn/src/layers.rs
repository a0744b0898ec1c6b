//! Layers of the learners' networks and how their weights start: He-uniform (the SAC
//! networks, the topology network) or orthogonal (the PPO actor-critic, as CleanRL's
//! `layer_init`), from the seeded generator so networks are bitwise reproducible.

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{Linear, Module};

use crate::error::Result;
use crate::noise::Noise;

/// Uniform initial weights in `[-bound, bound]` from the seeded generator.
fn uniform(noise: &mut Noise, n: usize, bound: f32) -> Vec<f32> {
    (0..n)
        .map(|_| (2.0 * noise.unit_f32() - 1.0) * bound)
        .collect()
}

/// How a layer's weights start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Init {
    /// Uniform with the variance of He initialization, scaled by the gain.
    HeUniform(f32),
    /// A (semi-)orthogonal matrix scaled by the gain (PyTorch's `orthogonal_`, as CleanRL).
    Orthogonal(f32),
}

/// A `rows x cols` matrix, row-major, with orthonormal rows or columns (whichever are
/// fewer), from Gaussian samples by modified Gram-Schmidt, times `gain`.
pub(crate) fn orthogonal(noise: &mut Noise, rows: usize, cols: usize, gain: f32) -> Vec<f32> {
    // Orthonormalize the shorter side's vectors of the longer length.
    let (count, len) = if rows <= cols {
        (rows, cols)
    } else {
        (cols, rows)
    };
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(count);
    while basis.len() < count {
        let mut v: Vec<f64> = (0..len).map(|_| f64::from(noise.normal())).collect();
        for b in &basis {
            let dot: f64 = v.iter().zip(b).map(|(x, y)| x * y).sum();
            v.iter_mut().zip(b).for_each(|(x, y)| *x -= dot * y);
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-6 {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
        }
    }
    let mut out = vec![0.0f32; rows * cols];
    for (i, b) in basis.iter().enumerate() {
        for (j, &x) in b.iter().enumerate() {
            let (r, c) = if rows <= cols { (i, j) } else { (j, i) };
            out[r * cols + c] = (x * f64::from(gain)) as f32;
        }
    }
    out
}

pub(crate) fn layer(
    noise: &mut Noise,
    device: &Device,
    name: &str,
    inputs: usize,
    outputs: usize,
    init: Init,
    params: &mut Vec<(String, Var)>,
) -> Result<Linear> {
    let values = match init {
        Init::HeUniform(gain) => {
            uniform(noise, inputs * outputs, gain * (6.0 / inputs as f32).sqrt())
        }
        Init::Orthogonal(gain) => orthogonal(noise, outputs, inputs, gain),
    };
    let weight = Var::from_vec(values, (outputs, inputs), device)?;
    let bias = Var::zeros(outputs, DType::F32, device)?;
    let linear = Linear::new(weight.as_tensor().clone(), Some(bias.as_tensor().clone()));
    params.push((format!("{name}.weight"), weight));
    params.push((format!("{name}.bias"), bias));
    Ok(linear)
}

/// An MLP with He-uniform weights and a small last layer (0.01), which keeps an initial
/// policy near its mean and values near zero (the SAC networks).
pub(crate) fn mlp(
    noise: &mut Noise,
    device: &Device,
    prefix: &str,
    widths: &[usize],
    params: &mut Vec<(String, Var)>,
) -> Result<Vec<Linear>> {
    mlp_init(
        noise,
        device,
        prefix,
        widths,
        params,
        Init::HeUniform(1.0),
        Init::HeUniform(0.01),
    )
}

/// An MLP whose hidden layers start with `hidden` and whose output layer with `output`.
pub(crate) fn mlp_init(
    noise: &mut Noise,
    device: &Device,
    prefix: &str,
    widths: &[usize],
    params: &mut Vec<(String, Var)>,
    hidden: Init,
    output: Init,
) -> Result<Vec<Linear>> {
    let last = widths.len() - 2;
    widths
        .windows(2)
        .enumerate()
        .map(|(k, w)| {
            let init = if k == last { output } else { hidden };
            layer(
                noise,
                device,
                &format!("{prefix}.{k}"),
                w[0],
                w[1],
                init,
                params,
            )
        })
        .collect()
}

/// The hidden layers' nonlinearity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Activation {
    /// Stable-Baselines3's PPO default (the PPO learners).
    Tanh,
    /// Stable-Baselines3's SAC default (CRM-SAC); also far cheaper than `tanh` on the CPU.
    Relu,
}

/// Runs an MLP: `tanh` after every hidden layer.
pub(crate) fn run(layers: &[Linear], input: &Tensor) -> Result<Tensor> {
    run_with(layers, input, Activation::Tanh)
}

/// Runs an MLP with `activation` after every hidden layer.
pub(crate) fn run_with(
    layers: &[Linear],
    input: &Tensor,
    activation: Activation,
) -> Result<Tensor> {
    let mut x = input.clone();
    for (k, layer) in layers.iter().enumerate() {
        x = layer.forward(&x)?;
        if k + 1 < layers.len() {
            x = match activation {
                Activation::Tanh => x.tanh()?,
                Activation::Relu => x.relu()?,
            };
        }
    }
    Ok(x)
}
