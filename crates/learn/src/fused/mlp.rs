//! A tanh MLP on host buffers: forward into a kept tape, backward into gradient buffers, Adam
//! in place, every buffer allocated once and reused across minibatches. Weights are stored as
//! candle's `Linear` stores them (`[outputs, inputs]`, row-major), so they copy to and from
//! the networks' variables as they are.

use super::matmul::{Mat, product};

/// A parameter with its gradient and Adam moments.
#[derive(Clone, Debug, Default)]
pub(crate) struct Param {
    pub value: Vec<f32>,
    pub grad: Vec<f32>,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
}

impl Param {
    /// A parameter holding `value`, with zero gradient and the moments `m`, `v`.
    pub fn new(value: Vec<f32>, m: Vec<f32>, v: Vec<f32>) -> Self {
        Self {
            grad: vec![0.0; value.len()],
            value,
            m,
            v,
        }
    }

    /// The gradient's squared norm, summed in f64 in element order (as `Adam::step`).
    pub fn grad_squares(&self) -> f64 {
        self.grad.iter().map(|&g| f64::from(g) * f64::from(g)).sum()
    }
}

/// One affine layer.
#[derive(Clone, Debug)]
pub(crate) struct Layer {
    pub weight: Param,
    pub bias: Param,
    pub inputs: usize,
    pub outputs: usize,
}

/// The layers and the activations of the last forward pass.
#[derive(Clone, Debug)]
pub(crate) struct Mlp {
    pub layers: Vec<Layer>,
    /// Each layer's output for the rows of the last forward (tanh applied but for the last).
    tape: Vec<Vec<f32>>,
    /// Two buffers for the backward pass's output gradients.
    grad_out: Vec<f32>,
    grad_in: Vec<f32>,
}

/// tanh to within a few units in the last place of `f32::tanh`, branch-free so that the
/// compiler vectorizes a loop of it: Eigen's rational approximation (degree 13 over 6) on
/// `[-7.905, 7.905]`, outside which tanh rounds to +-1 in f32.
#[inline]
pub(crate) fn tanh(x: f32) -> f32 {
    const CLAMP: f32 = 7.905_311;
    const A: [f32; 7] = [
        4.893_524_6e-3,
        6.372_619_3e-4,
        1.485_722_4e-5,
        5.122_297e-8,
        -8.604_672e-11,
        2.000_188e-13,
        -2.760_768_5e-16,
    ];
    const B: [f32; 4] = [4.893_525e-3, 2.268_434_6e-3, 1.185_347_1e-4, 1.198_258_4e-6];
    let x = x.clamp(-CLAMP, CLAMP);
    let x2 = x * x;
    let p = ((((((A[6] * x2 + A[5]) * x2 + A[4]) * x2 + A[3]) * x2 + A[2]) * x2 + A[1]) * x2
        + A[0])
        * x;
    let q = ((B[3] * x2 + B[2]) * x2 + B[1]) * x2 + B[0];
    p / q
}

impl Mlp {
    pub fn new(layers: Vec<Layer>) -> Self {
        Self {
            tape: vec![Vec::new(); layers.len()],
            layers,
            grad_out: Vec::new(),
            grad_in: Vec::new(),
        }
    }

    /// The output of the last forward pass, `[rows, outputs]`.
    pub fn output(&self) -> &[f32] {
        self.tape.last().map_or(&[], Vec::as_slice)
    }

    /// Runs `rows` rows of `input` (`[rows, inputs]`) through the layers, tanh after every
    /// layer but the last, keeping every layer's output for [`Self::backward`].
    pub fn forward(&mut self, input: &[f32], rows: usize) {
        let last = self.layers.len().saturating_sub(1);
        for (k, layer) in self.layers.iter().enumerate() {
            let (before, after) = self.tape.split_at_mut(k);
            let x = if k == 0 { input } else { &before[k - 1] };
            let out = &mut after[0];
            out.resize(rows * layer.outputs, 0.0);
            // Bias rows first, then the product accumulated onto them.
            for row in out.chunks_exact_mut(layer.outputs) {
                row.copy_from_slice(&layer.bias.value);
            }
            product(
                out,
                Mat::rows(x, rows, layer.inputs),
                Mat::rows(&layer.weight.value, layer.outputs, layer.inputs).t(),
                true,
            );
            if k < last {
                out.iter_mut().for_each(|v| *v = tanh(*v));
            }
        }
    }

    /// Sets every layer's gradient from `d_output` (the loss's gradient at the last forward's
    /// output, `[rows, outputs]`); `input` is the forward's input.
    pub fn backward(&mut self, input: &[f32], rows: usize, d_output: &[f32]) {
        let Self {
            layers,
            tape,
            grad_out,
            grad_in,
        } = self;
        grad_out.clear();
        grad_out.extend_from_slice(d_output);
        for k in (0..layers.len()).rev() {
            let layer = &mut layers[k];
            let x = if k == 0 { input } else { &tape[k - 1] };
            let d = &grad_out[..rows * layer.outputs];
            // dW = d^T x, db = column sums of d.
            product(
                &mut layer.weight.grad,
                Mat::rows(d, rows, layer.outputs).t(),
                Mat::rows(x, rows, layer.inputs),
                false,
            );
            layer.bias.grad.fill(0.0);
            for row in d.chunks_exact(layer.outputs) {
                layer
                    .bias
                    .grad
                    .iter_mut()
                    .zip(row)
                    .for_each(|(g, &v)| *g += v);
            }
            if k == 0 {
                break;
            }
            // dx = d W, then through the tanh that made x: (1 - x^2).
            grad_in.resize(rows * layer.inputs, 0.0);
            product(
                grad_in,
                Mat::rows(d, rows, layer.outputs),
                Mat::rows(&layer.weight.value, layer.outputs, layer.inputs),
                false,
            );
            grad_in
                .iter_mut()
                .zip(x.iter())
                .for_each(|(g, &h)| *g *= 1.0 - h * h);
            std::mem::swap(grad_out, grad_in);
        }
    }

    /// Every parameter in checkpoint order (`0.weight`, `0.bias`, `1.weight`, ...).
    pub fn params_mut(&mut self) -> impl Iterator<Item = &mut Param> {
        self.layers
            .iter_mut()
            .flat_map(|l| [&mut l.weight, &mut l.bias])
    }

    /// Every parameter in checkpoint order.
    pub fn params(&self) -> impl Iterator<Item = &Param> {
        self.layers.iter().flat_map(|l| [&l.weight, &l.bias])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_tanh_is_within_a_few_ulp_of_std() {
        let mut worst = 0.0f32;
        for i in -200_000..=200_000 {
            let x = i as f32 * 1e-4;
            let (fast, exact) = (tanh(x), x.tanh());
            worst = worst.max((fast - exact).abs() / exact.abs().max(1e-30));
        }
        assert!(worst < 5e-7, "worst relative error {worst}");
        assert_eq!(tanh(50.0), 1.0);
        assert_eq!(tanh(-50.0), -1.0);
        assert_eq!(tanh(0.0), 0.0);
    }
}
