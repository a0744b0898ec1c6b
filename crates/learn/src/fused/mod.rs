//! The PPO update without a tensor library's per-op cost: the actor-critic's forward and
//! backward passes, the clipped surrogate, the value loss and the entropy written as a few
//! passes over buffers allocated once per update, the matrix products handed to `gemm`
//! (`matmul.rs`), and Adam applied in place (`optim.rs`'s arithmetic, so the two paths agree).
//!
//! The actor (with its log std) and the critic share no parameter and are clipped as separate
//! groups, so each minibatch runs the two networks' forward, backward, norm and Adam step on
//! the two cores at once (`rayon::join`); the result does not depend on the thread count.
//! The candle path (`UpdateEngine::Candle`, `ppo::candle_loss`) stays as the reference: `tests`
//! checks losses and every gradient against candle's autograd, and one update's parameters
//! against that path's.

mod heads;
pub(crate) mod matmul;
pub(crate) mod mlp;
#[cfg(test)]
mod tests;

use std::time::Instant;

use candle_core::Tensor;

use crate::error::{Error, Result};
use crate::network::ActorCritic;
use crate::optim::{Adam, AdamStep, clip_scale, is_critic};
use heads::{PolicyLoss, policy_head, value_head};
use mlp::{Layer, Mlp, Param};

/// A rollout's training columns on the host, row-major.
#[derive(Clone, Debug, Default)]
pub(crate) struct Columns {
    /// Normalized network inputs, `[n, width]`.
    pub inputs: Vec<f32>,
    pub actions: Vec<f32>,
    pub masks: Vec<f32>,
    pub old_log_probs: Vec<f32>,
    pub advantages: Vec<f32>,
    pub returns: Vec<f32>,
    pub width: usize,
    pub action_width: usize,
}

impl Columns {
    pub fn len(&self) -> usize {
        self.old_log_probs.len()
    }

    /// Rows `order` of `self` into `into` (reusing its buffers).
    pub fn gather(&self, order: &[usize], into: &mut Columns) {
        fn rows(from: &[f32], width: usize, order: &[usize], into: &mut Vec<f32>) {
            into.clear();
            for &i in order {
                into.extend_from_slice(&from[i * width..(i + 1) * width]);
            }
        }
        rows(&self.inputs, self.width, order, &mut into.inputs);
        rows(&self.actions, self.action_width, order, &mut into.actions);
        rows(&self.masks, self.action_width, order, &mut into.masks);
        rows(&self.old_log_probs, 1, order, &mut into.old_log_probs);
        rows(&self.advantages, 1, order, &mut into.advantages);
        rows(&self.returns, 1, order, &mut into.returns);
        into.width = self.width;
        into.action_width = self.action_width;
    }

    /// Rows `start..start + len`.
    pub fn slice(&self, start: usize, len: usize) -> Minibatch<'_> {
        let (w, a) = (self.width, self.action_width);
        Minibatch {
            rows: len,
            inputs: &self.inputs[start * w..(start + len) * w],
            actions: &self.actions[start * a..(start + len) * a],
            masks: &self.masks[start * a..(start + len) * a],
            old_log_probs: &self.old_log_probs[start..start + len],
            advantages: &self.advantages[start..start + len],
            returns: &self.returns[start..start + len],
            action_width: a,
        }
    }
}

/// A minibatch: contiguous rows of [`Columns`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Minibatch<'a> {
    pub rows: usize,
    pub inputs: &'a [f32],
    pub actions: &'a [f32],
    pub masks: &'a [f32],
    pub old_log_probs: &'a [f32],
    pub advantages: &'a [f32],
    pub returns: &'a [f32],
    pub action_width: usize,
}

/// The loss coefficients of a PPO update (CleanRL's names).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Coefs {
    pub clip: f32,
    pub ent: f32,
    pub vf: f32,
    pub max_grad_norm: f32,
}

/// What one minibatch reports.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct MinibatchStats {
    pub policy_loss: f32,
    pub value_loss: f32,
    pub entropy: f32,
    pub approx_kl: f32,
    pub clipfrac: f32,
    /// Seconds spent in the Adam steps (the slower of the two networks').
    pub optimizer_secs: f64,
}

/// The actor (layers and log std) and the critic on the host, with their Adam moments, for
/// the length of one update.
#[derive(Debug)]
pub(crate) struct Engine {
    actor: Mlp,
    log_std: Param,
    critic: Mlp,
    /// Per-minibatch buffers of the policy head.
    d_mean: Vec<f32>,
    d_value: Vec<f32>,
    log_ratio: Vec<f32>,
}

/// A parameter's place in [`ActorCritic::params`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    Actor,
    Critic,
    LogStd,
}

fn slot(name: &str) -> Slot {
    if name == "actor.log_std" {
        Slot::LogStd
    } else if is_critic(name) {
        Slot::Critic
    } else {
        Slot::Actor
    }
}

impl Engine {
    /// Copies the networks' parameters to the host and takes their Adam moments from
    /// `adam`; [`Self::store`] puts both back.
    pub fn load(net: &ActorCritic, adam: &mut Adam) -> Result<Self> {
        let actor = host_layers(net, Slot::Actor, |k| adam.take_moments(k))?;
        let critic = host_layers(net, Slot::Critic, |k| adam.take_moments(k))?;
        let (k, (_, var)) = net
            .params()
            .iter()
            .enumerate()
            .find(|(_, (name, _))| slot(name) == Slot::LogStd)
            .ok_or(Error::Length {
                what: "log std parameter",
                expected: 1,
                got: 0,
            })?;
        let (m, v) = adam.take_moments(k);
        let log_std = Param::new(var.as_tensor().flatten_all()?.to_vec1::<f32>()?, m, v);
        Ok(Self {
            actor: Mlp::new(actor),
            log_std,
            critic: Mlp::new(critic),
            d_mean: Vec::new(),
            d_value: Vec::new(),
            log_ratio: Vec::new(),
        })
    }

    /// Writes the parameters back into `net`'s variables and the moments into `adam`.
    pub fn store(self, net: &ActorCritic, adam: &mut Adam) -> Result<()> {
        let Self {
            mut actor,
            log_std,
            mut critic,
            ..
        } = self;
        let mut actor_params = actor.params_mut();
        let mut critic_params = critic.params_mut();
        let mut log_std = Some(log_std);
        for (k, (name, var)) in net.params().iter().enumerate() {
            let param = match slot(name) {
                Slot::Actor => actor_params.next().map(std::mem::take),
                Slot::Critic => critic_params.next().map(std::mem::take),
                Slot::LogStd => log_std.take(),
            }
            .ok_or(Error::Length {
                what: "host parameters",
                expected: k + 1,
                got: k,
            })?;
            var.set(&Tensor::from_vec(param.value, var.shape(), var.device())?)?;
            adam.put_moments(k, param.m, param.v);
        }
        Ok(())
    }

    /// One gradient step on `batch`: both networks' passes and Adam steps, one network per
    /// core.
    pub fn minibatch(
        &mut self,
        batch: Minibatch<'_>,
        coefs: Coefs,
        adam: AdamStep,
    ) -> MinibatchStats {
        let Self {
            actor,
            log_std,
            critic,
            d_mean,
            d_value,
            log_ratio,
        } = self;
        let (policy, (value_loss, critic_secs)) = rayon::join(
            || {
                let loss = actor_gradients(actor, log_std, batch, coefs, d_mean, log_ratio);
                let secs = step_group(actor, Some(log_std), coefs.max_grad_norm, adam);
                (loss, secs)
            },
            || {
                let loss = critic_gradients(critic, batch, coefs, d_value);
                let secs = step_group(critic, None, coefs.max_grad_norm, adam);
                (loss, secs)
            },
        );
        let (PolicyLoss { loss, entropy }, actor_secs) = policy;
        let (approx_kl, clipfrac) = kl_and_clipfrac(log_ratio, coefs.clip);
        MinibatchStats {
            policy_loss: loss,
            value_loss,
            entropy,
            approx_kl,
            clipfrac,
            optimizer_secs: actor_secs.max(critic_secs),
        }
    }
}

/// The critic's values at two batches of inputs (`[rows, width]` each: a rollout's states and
/// its next states), one batch per core, each in chunks of [`VALUE_CHUNK`] rows.
pub(crate) fn values(net: &ActorCritic, inputs: [&[f32]; 2]) -> Result<[Vec<f32>; 2]> {
    let layers = host_layers(net, Slot::Critic, |_| (Vec::new(), Vec::new()))?;
    let width = net.layout().input_width();
    let run = |mut critic: Mlp, input: &[f32]| {
        let mut out = Vec::with_capacity(input.len() / width.max(1));
        for chunk in input.chunks(VALUE_CHUNK * width) {
            critic.forward(chunk, chunk.len() / width);
            out.extend_from_slice(critic.output());
        }
        out
    };
    let critic = Mlp::new(layers);
    let (a, b) = rayon::join(
        || run(critic.clone(), inputs[0]),
        || run(critic.clone(), inputs[1]),
    );
    Ok([a, b])
}

/// The layers of one network (`want`: the actor's or the critic's) copied to the host, in
/// order, each parameter with the Adam moments `moments(k)` gives for its index `k` in
/// [`ActorCritic::params`].
fn host_layers(
    net: &ActorCritic,
    want: Slot,
    mut moments: impl FnMut(usize) -> (Vec<f32>, Vec<f32>),
) -> Result<Vec<Layer>> {
    let mut layers = Vec::new();
    let mut pending: Option<(Param, usize, usize)> = None;
    for (k, (name, var)) in net.params().iter().enumerate() {
        if slot(name) != want {
            continue;
        }
        let (m, v) = moments(k);
        let param = Param::new(var.as_tensor().flatten_all()?.to_vec1::<f32>()?, m, v);
        match (pending.take(), var.as_tensor().dims()) {
            (None, &[outputs, inputs]) => pending = Some((param, outputs, inputs)),
            (Some((weight, outputs, inputs)), _) => layers.push(Layer {
                weight,
                bias: param,
                inputs,
                outputs,
            }),
            (None, _) => {
                return Err(Error::Length {
                    what: "weight before bias",
                    expected: 2,
                    got: 1,
                });
            }
        }
    }
    Ok(layers)
}

/// Rows per forward pass in [`values`]: a few hundred kilobytes of activations per layer.
const VALUE_CHUNK: usize = 512;

/// The actor's forward pass, surrogate loss and backward pass: every actor gradient set.
fn actor_gradients(
    actor: &mut Mlp,
    log_std: &mut Param,
    batch: Minibatch<'_>,
    coefs: Coefs,
    d_mean: &mut Vec<f32>,
    log_ratio: &mut Vec<f32>,
) -> PolicyLoss {
    actor.forward(batch.inputs, batch.rows);
    let loss = policy_head(actor.output(), log_std, batch, coefs, d_mean, log_ratio);
    actor.backward(batch.inputs, batch.rows, d_mean);
    loss
}

/// The critic's forward pass, value loss and backward pass: every critic gradient set.
fn critic_gradients(
    critic: &mut Mlp,
    batch: Minibatch<'_>,
    coefs: Coefs,
    d_value: &mut Vec<f32>,
) -> f32 {
    critic.forward(batch.inputs, batch.rows);
    let loss = value_head(critic.output(), batch, coefs.vf, d_value);
    critic.backward(batch.inputs, batch.rows, d_value);
    loss
}

#[cfg(test)]
impl Engine {
    /// The losses `(policy, value, entropy)` of `batch` and every gradient, in
    /// [`ActorCritic::params`] order (actor layers, critic layers, log std), without a step.
    pub fn gradients(&mut self, batch: Minibatch<'_>, coefs: Coefs) -> ([f32; 3], Vec<Vec<f32>>) {
        let policy = actor_gradients(
            &mut self.actor,
            &mut self.log_std,
            batch,
            coefs,
            &mut self.d_mean,
            &mut self.log_ratio,
        );
        let value = critic_gradients(&mut self.critic, batch, coefs, &mut self.d_value);
        let grads = self
            .actor
            .params()
            .chain(self.critic.params())
            .chain([&self.log_std])
            .map(|p| p.grad.clone())
            .collect();
        ([policy.loss, value, policy.entropy], grads)
    }
}

/// Clips a group's gradient to `max_norm` and takes its Adam step; returns the seconds spent.
fn step_group(net: &mut Mlp, extra: Option<&mut Param>, max_norm: f32, adam: AdamStep) -> f64 {
    let started = Instant::now();
    let mut squares = 0.0f64;
    for param in net.params() {
        squares += param.grad_squares();
    }
    if let Some(param) = extra.as_deref() {
        squares += param.grad_squares();
    }
    let scale = clip_scale(squares.sqrt() as f32, max_norm);
    for param in net.params_mut().chain(extra) {
        let Param { value, grad, m, v } = param;
        adam.apply(value, grad, scale, m, v);
    }
    started.elapsed().as_secs_f64()
}

/// A minibatch's approximate KL, `mean((ratio - 1) - log ratio)`, and the fraction of its
/// ratios outside `1 +- clip`, from its log ratios on the host (CleanRL's two statistics).
pub(crate) fn kl_and_clipfrac(log_ratio: &[f32], clip: f32) -> (f32, f32) {
    let count = log_ratio.len().max(1) as f32;
    let approx_kl = log_ratio.iter().map(|&l| (l.exp() - 1.0) - l).sum::<f32>() / count;
    let clipfrac = log_ratio
        .iter()
        .filter(|&&l| (l.exp() - 1.0).abs() > clip)
        .count() as f32
        / count;
    (approx_kl, clipfrac)
}
