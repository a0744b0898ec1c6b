//! Adam in one fused pass over each parameter, with the gradient norm clipped per network.
//!
//! candle's `AdamW` runs about ten tensor kernels per parameter and step, and a global norm
//! clip another three per parameter plus a host read each; on the CPU those launches, not the
//! arithmetic, dominated the PPO update. Here each gradient is read once into host memory,
//! its squared norm summed in the same pass, and the moments and the parameter updated in a
//! single loop; the parameter is written back once.
//!
//! Gradients are clipped per group (the actor with its log std, and the critic) so a large
//! value loss cannot shrink the policy's step: with one global clip, the minibatches that
//! carry the rare success reward are exactly those whose value error is largest.
//! Defaults: beta 0.9 / 0.999 (Adam's paper, PyTorch), eps 1e-5 (CleanRL's PPO, the
//! `openai/baselines` value), no weight decay.

use candle_core::backprop::GradStore;
use candle_core::{Tensor, Var};

use crate::error::Result;

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
/// CleanRL's `eps=1e-5` for PPO's Adam.
pub const ADAM_EPS: f64 = 1e-5;

/// Gradient norms of one step, before clipping.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GradNorms {
    /// The policy's parameters (and log std).
    pub actor: f32,
    /// The value function's parameters.
    pub critic: f32,
}

/// Adam's moments for a list of named parameters.
#[derive(Clone, Debug)]
pub struct Adam {
    pub learning_rate: f64,
    /// Added to the second moment's root: [`ADAM_EPS`] unless set with [`Adam::with_eps`].
    eps: f32,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
    t: i32,
}

/// Whether a parameter belongs to the critic group (by its checkpoint name).
pub(crate) fn is_critic(name: &str) -> bool {
    name.starts_with("critic.")
}

impl Adam {
    pub fn new(params: &[(String, Var)], learning_rate: f64) -> Self {
        let zeros = || {
            params
                .iter()
                .map(|(_, v)| vec![0.0; v.elem_count()])
                .collect()
        };
        Self {
            learning_rate,
            eps: ADAM_EPS as f32,
            m: zeros(),
            v: zeros(),
            t: 0,
        }
    }

    /// The same optimizer with another epsilon (SAC: PyTorch's 1e-8, as Stable-Baselines3).
    pub fn with_eps(self, eps: f64) -> Self {
        Self {
            eps: eps as f32,
            ..self
        }
    }

    /// One step on `params` (the list this optimizer was made for) with `grads`, each group's
    /// gradient scaled to a norm of at most `max_norm`; parameters without a gradient keep
    /// their value and moments.
    pub fn step(
        &mut self,
        params: &[(String, Var)],
        grads: &GradStore,
        max_norm: f32,
    ) -> Result<GradNorms> {
        let mut flat: Vec<Option<Vec<f32>>> = Vec::with_capacity(params.len());
        let (mut actor, mut critic) = (0.0f64, 0.0f64);
        for (name, var) in params {
            let grad = match grads.get(var.as_tensor()) {
                Some(g) => g.flatten_all()?.to_vec1::<f32>()?,
                None => {
                    flat.push(None);
                    continue;
                }
            };
            let squares: f64 = grad.iter().map(|&g| f64::from(g) * f64::from(g)).sum();
            if is_critic(name) {
                critic += squares;
            } else {
                actor += squares;
            }
            flat.push(Some(grad));
        }
        let norms = GradNorms {
            actor: actor.sqrt() as f32,
            critic: critic.sqrt() as f32,
        };
        let (actor_scale, critic_scale) = (
            clip_scale(norms.actor, max_norm),
            clip_scale(norms.critic, max_norm),
        );
        let adam = self.next_step();
        for (k, ((name, var), grad)) in params.iter().zip(flat).enumerate() {
            let Some(grad) = grad else { continue };
            let g_scale = if is_critic(name) {
                critic_scale
            } else {
                actor_scale
            };
            let mut values = var.as_tensor().flatten_all()?.to_vec1::<f32>()?;
            adam.apply(&mut values, &grad, g_scale, &mut self.m[k], &mut self.v[k]);
            var.set(&Tensor::from_vec(values, var.shape(), var.device())?)?;
        }
        Ok(norms)
    }

    /// The step count and the moments (one list per parameter), for a checkpoint of the whole
    /// training state.
    pub fn state(&self) -> (i32, &[Vec<f32>], &[Vec<f32>]) {
        (self.t, &self.m, &self.v)
    }

    /// Sets the step count and the moments from a checkpoint; each list must have its
    /// parameter's size.
    pub fn restore(&mut self, t: i32, m: Vec<Vec<f32>>, v: Vec<Vec<f32>>) -> Result<()> {
        let sizes = |lists: &[Vec<f32>]| lists.iter().map(Vec::len).collect::<Vec<_>>();
        let expected = sizes(&self.m);
        for (what, lists) in [("Adam's first moments", &m), ("Adam's second moments", &v)] {
            if sizes(lists) != expected {
                return Err(crate::error::Error::Config {
                    field: "optimizer",
                    message: format!(
                        "{what} have sizes {:?}, the parameters {expected:?}",
                        sizes(lists)
                    ),
                });
            }
        }
        (self.t, self.m, self.v) = (t, m, v);
        Ok(())
    }

    /// Counts one step and returns its bias-corrected coefficients, for an update that keeps
    /// its parameters and moments on the host (`fused`).
    pub(crate) fn next_step(&mut self) -> AdamStep {
        self.t += 1;
        let correction1 = 1.0 - BETA1.powi(self.t);
        let correction2 = 1.0 - BETA2.powi(self.t);
        AdamStep {
            step_size: (self.learning_rate / correction1) as f32,
            sqrt_correction2: correction2.sqrt() as f32,
            eps: self.eps,
        }
    }

    /// Moves the moments of parameter `k` out (for a host-side update), leaving them empty
    /// until [`Self::put_moments`] gives them back.
    pub(crate) fn take_moments(&mut self, k: usize) -> (Vec<f32>, Vec<f32>) {
        (
            std::mem::take(&mut self.m[k]),
            std::mem::take(&mut self.v[k]),
        )
    }

    /// Gives back the moments of parameter `k` taken with [`Self::take_moments`].
    pub(crate) fn put_moments(&mut self, k: usize, m: Vec<f32>, v: Vec<f32>) {
        self.m[k] = m;
        self.v[k] = v;
    }
}

/// The factor that brings a group's gradient norm down to `max_norm` (1 when it is below).
pub(crate) fn clip_scale(norm: f32, max_norm: f32) -> f32 {
    if norm > max_norm {
        max_norm / (norm + 1e-6)
    } else {
        1.0
    }
}

/// One Adam step's bias-corrected coefficients.
#[derive(Clone, Copy, Debug)]
pub(crate) struct AdamStep {
    step_size: f32,
    sqrt_correction2: f32,
    eps: f32,
}

impl AdamStep {
    /// Updates the moments `m`, `v` with `grad` times `g_scale` and moves `values` by the
    /// step, in one pass.
    pub(crate) fn apply(
        &self,
        values: &mut [f32],
        grad: &[f32],
        g_scale: f32,
        m: &mut [f32],
        v: &mut [f32],
    ) {
        let (b1, b2) = (BETA1 as f32, BETA2 as f32);
        for (((x, &g), m), v) in values.iter_mut().zip(grad).zip(m).zip(v) {
            let g = g * g_scale;
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            let denom = v.sqrt() / self.sqrt_correction2 + self.eps;
            *x -= self.step_size * *m / denom;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    /// candle's AdamW without weight decay is the reference for one group under the clip.
    #[test]
    fn a_fused_step_matches_candles_adam_when_unclipped() {
        use candle_nn::{AdamW, Optimizer, ParamsAdamW};
        let device = Device::Cpu;
        let make = || -> Vec<(String, Var)> {
            vec![
                (
                    "actor.0.weight".into(),
                    Var::from_vec(vec![0.5f32, -1.0, 2.0, 0.1], (2, 2), &device).expect("v"),
                ),
                (
                    "critic.0.bias".into(),
                    Var::from_vec(vec![0.3f32, -0.2], 2, &device).expect("v"),
                ),
            ]
        };
        let (ours, theirs) = (make(), make());
        let loss = |p: &[(String, Var)]| -> Tensor {
            let a = p[0].1.as_tensor().sqr().expect("sq").sum_all().expect("s");
            let b = (p[1].1.as_tensor() * 3.0).expect("m").sum_all().expect("s");
            (a + b).expect("add")
        };
        let mut adam = Adam::new(&ours, 0.01);
        let mut reference = AdamW::new(
            theirs.iter().map(|(_, v)| v.clone()).collect(),
            ParamsAdamW {
                lr: 0.01,
                weight_decay: 0.0,
                eps: ADAM_EPS,
                ..ParamsAdamW::default()
            },
        )
        .expect("adamw");
        for _ in 0..5 {
            adam.step(&ours, &loss(&ours).backward().expect("grads"), 1e9)
                .expect("step");
            reference
                .step(&loss(&theirs).backward().expect("grads"))
                .expect("step");
        }
        for ((_, a), (_, b)) in ours.iter().zip(&theirs) {
            let a = a
                .as_tensor()
                .flatten_all()
                .expect("f")
                .to_vec1::<f32>()
                .expect("v");
            let b = b
                .as_tensor()
                .flatten_all()
                .expect("f")
                .to_vec1::<f32>()
                .expect("v");
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() < 1e-5, "{a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn a_huge_critic_gradient_does_not_shrink_the_actors_step() {
        let device = Device::Cpu;
        let make = || -> Vec<(String, Var)> {
            ["actor.0.bias", "critic.0.bias"]
                .iter()
                .map(|n| {
                    (
                        n.to_string(),
                        Var::from_vec(vec![0.0f32; 2], 2, &device).expect("v"),
                    )
                })
                .collect()
        };
        let loss = |p: &[(String, Var)], critic: f64| -> Tensor {
            let a = (p[0].1.as_tensor() * 0.4).expect("m").sum_all().expect("s");
            let c = (p[1].1.as_tensor() * critic)
                .expect("m")
                .sum_all()
                .expect("s");
            (a + c).expect("add")
        };
        let (calm, stormy) = (make(), make());
        let (mut a, mut b) = (Adam::new(&calm, 0.1), Adam::new(&stormy, 0.1));
        for critic in [1.0, 1000.0, 1.0] {
            a.step(&calm, &loss(&calm, 1.0).backward().expect("g"), 0.5)
                .expect("step");
            let norms = b
                .step(&stormy, &loss(&stormy, critic).backward().expect("g"), 0.5)
                .expect("step");
            assert!((norms.actor - 0.4 * 2f32.sqrt()).abs() < 1e-5, "{norms:?}");
        }
        let actor = |p: &[(String, Var)]| p[0].1.as_tensor().to_vec1::<f32>().expect("v");
        assert_eq!(actor(&calm), actor(&stormy));
    }
}
