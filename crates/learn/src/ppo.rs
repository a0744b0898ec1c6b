//! PPO inside a Contextual Reward Machine (paper, section III-B), read top to bottom:
//! a rollout (see `rollout.rs`), reward scaling, GAE with the transition reward in the TD
//! error, then the minibatch epochs with the clipped surrogate on normalized abstract states,
//! the value loss, per-network gradient clipping in a fused Adam (`optim.rs`), the KL guard
//! and the paper's learning-rate steps; last, the rollout's states join the observation
//! statistics. The reward mode picks CRM-PPO (`crm`), LPPO (`dense`) or IPPO (`sparse`) on
//! the same machine.
//!
//! Speed: the rollout is encoded once per update; each epoch permutes it with one gather per
//! column and the minibatches are contiguous row ranges of that. Training runs the epochs on
//! the fused engine (`fused/`: hand-written passes, the two networks on two cores); candle's
//! autograd (`UpdateEngine::Candle`) is the reference it is tested against.

use std::time::Instant;

use candle_core::Tensor;

use crate::error::{Error, Result};
use crate::fused::{self, Coefs, Columns, Engine, kl_and_clipfrac};
use crate::gae::{StepRecord, gae, normalize};
use crate::network::{ActorCritic, Layout};
use crate::noise::Noise;
use crate::normalize::RewardScaler;
use crate::optim::Adam;
use crate::rollout::{Actor, Rollout};
use crm_api::PpoConfig;

/// What one update reports (CleanRL's names).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UpdateStats {
    pub policy_loss: f32,
    pub value_loss: f32,
    pub entropy: f32,
    pub approx_kl: f32,
    pub clipfrac: f32,
    pub learning_rate: f64,
    /// Minibatches run before the KL guard stopped the update (all of them when it did not).
    pub minibatches: usize,
    /// The reward scale applied to this rollout (1 without reward scaling).
    pub reward_scale: f32,
    /// Where the update's wall time went (seconds).
    pub timing: UpdateTiming,
}

/// Wall time of an update's phases (seconds), for `crm bench learn`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateTiming {
    /// Values, reward scaling, GAE and encoding the rollout into tensors.
    pub prepare: f64,
    /// The per-epoch permutation gathers.
    pub shuffle: f64,
    /// Forward passes, losses and backward passes.
    pub forward_backward: f64,
    /// The fused Adam steps (gradient reads, norms, moments, parameter writes).
    pub optimizer: f64,
    /// Reading the statistics back (KL, clip fraction, losses) and the observation statistics.
    pub bookkeeping: f64,
}

/// What a PPO learner carries from one update to the next besides its weights and
/// observation statistics: Adam's step and moments, the reward scaler (each environment's
/// running return and the returns' statistics) and the minibatch shuffles' generator.
#[derive(Clone, Debug, PartialEq)]
pub struct PpoState {
    pub adam_step: i32,
    pub adam_m: Vec<Vec<f32>>,
    pub adam_v: Vec<Vec<f32>>,
    pub noise: u64,
    pub returns: Vec<f64>,
    pub return_stats: crate::normalize::RunningMeanStd,
}

/// The learner: networks, optimizer, reward scaler and its noise source.
pub struct Ppo {
    pub net: ActorCritic,
    pub config: PpoConfig,
    optimizer: Adam,
    scaler: RewardScaler,
    noise: Noise,
    engine: UpdateEngine,
}

/// How an update computes its gradients.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpdateEngine {
    /// Hand-written passes over host buffers, the two networks on two cores (`fused`).
    #[default]
    Fused,
    /// candle's autograd, one tensor op at a time: the reference the fused path is tested
    /// against.
    Candle,
}

const HALF_LOG_TWO_PI: f32 = 0.918_938_5;

impl Ppo {
    pub fn new(layout: Layout, config: PpoConfig, seed: u64) -> Result<Self> {
        config.validate()?;
        let net = ActorCritic::new(layout, &config.hidden, seed)?;
        let log_std = config
            .init_log_std
            .unwrap_or(crm_api::config::DEFAULT_LOG_STD);
        net.set_log_std(log_std as f32)?;
        let optimizer = Adam::new(net.params(), config.learning_rate);
        Ok(Self {
            scaler: RewardScaler::new(config.gamma as f32),
            net,
            config,
            optimizer,
            noise: Noise::new(seed ^ 0xA5A5_5A5A),
            engine: UpdateEngine::default(),
        })
    }

    /// Chooses how updates compute their gradients (the same result within float rounding).
    pub fn set_engine(&mut self, engine: UpdateEngine) {
        self.engine = engine;
    }

    pub fn engine(&self) -> UpdateEngine {
        self.engine
    }

    pub(crate) fn optimizer_mut(&mut self) -> &mut Adam {
        &mut self.optimizer
    }

    pub(crate) fn noise_mut(&mut self) -> &mut Noise {
        &mut self.noise
    }

    /// Copies the weights and observation statistics of `other` (same layout and widths)
    /// into this learner's networks, keeping the optimizer bound to them: how a run resumes
    /// from a checkpoint.
    pub fn load_weights(&mut self, other: &ActorCritic) -> Result<()> {
        if other.layout() != self.net.layout() || other.hidden() != self.net.hidden() {
            return Err(Error::Config {
                field: "hidden",
                message: format!(
                    "checkpoint network {:?} {:?} does not match {:?} {:?}",
                    other.layout(),
                    other.hidden(),
                    self.net.layout(),
                    self.net.hidden()
                ),
            });
        }
        for ((_, mine), (_, theirs)) in self.net.params().iter().zip(other.params()) {
            mine.set(theirs.as_tensor())?;
        }
        self.net.set_norm(other.norm().clone())?;
        Ok(())
    }

    /// Everything but the weights that the next update depends on ([`PpoState`]).
    pub fn state(&self) -> PpoState {
        let (adam_step, m, v) = self.optimizer.state();
        let (returns, return_stats) = self.scaler.state();
        PpoState {
            adam_step,
            adam_m: m.to_vec(),
            adam_v: v.to_vec(),
            noise: self.noise.state(),
            returns,
            return_stats,
        }
    }

    /// Goes on from a [`PpoState`] (with the weights loaded by [`Self::load_weights`]).
    pub fn restore(&mut self, state: PpoState) -> Result<()> {
        self.optimizer
            .restore(state.adam_step, state.adam_m, state.adam_v)?;
        self.scaler.restore(state.returns, state.return_stats);
        self.noise = Noise::new(state.noise);
        Ok(())
    }

    /// Samples (or, `deterministic`, takes the means of) the policy at a batch of abstract
    /// states; returns the union-space actions and their log-probabilities under the masks.
    /// Noise is drawn row by row in order, so a batch gives the same actions as its rows one
    /// by one.
    pub fn act_batch(
        &mut self,
        states: &[Vec<f32>],
        stages: &[usize],
        masks: &[Vec<f32>],
        deterministic: bool,
    ) -> Result<(Vec<Vec<f32>>, Vec<f32>)> {
        let noise = (!deterministic).then_some(&mut self.noise);
        sample_policy(&self.net, states, stages, masks, noise)
    }

    /// The deterministic action at one abstract state: the Gaussian's mean, and on the
    /// dimensions marked in `folded` (those the environment takes the magnitude of) the
    /// sampled action's mean magnitude ([`crate::folded::folded_mean`]). Zero outside `mask`.
    pub fn act_folded(
        &self,
        state: &[f32],
        stage: usize,
        mask: &[f32],
        folded: &[bool],
    ) -> Result<Vec<f32>> {
        let (means, _) = sample_policy(
            &self.net,
            &[state.to_vec()],
            &[stage],
            &[mask.to_vec()],
            None,
        )?;
        let std = self.net.std()?;
        Ok(means
            .first()
            .map(Vec::as_slice)
            .unwrap_or_default()
            .iter()
            .enumerate()
            .map(|(k, &m)| {
                let live = mask.get(k).copied().unwrap_or(0.0);
                if folded.get(k).copied().unwrap_or(false) {
                    live * crate::folded::folded_mean(m, std.get(k).copied().unwrap_or(0.0))
                } else {
                    live * m
                }
            })
            .collect())
    }

    /// [`Self::act_batch`] for one state.
    pub fn act(
        &mut self,
        state: &[f32],
        stage: usize,
        mask: &[f32],
        deterministic: bool,
    ) -> Result<(Vec<f32>, f32)> {
        let (mut actions, log_probs) =
            self.act_batch(&[state.to_vec()], &[stage], &[mask.to_vec()], deterministic)?;
        Ok((actions.pop().unwrap_or_default(), log_probs[0]))
    }

    /// The reward scale for this rollout: the running return statistics with its rewards
    /// folded in (environment by environment, in time order).
    fn reward_scale(&mut self, rollout: &Rollout) -> f32 {
        if !self.config.norm_reward {
            return 1.0;
        }
        for t in 0..rollout.len() {
            let reward = rollout.intra[t] + rollout.transition[t];
            self.scaler
                .observe(rollout.env[t], reward, rollout.ended[t]);
        }
        self.scaler.factor()
    }

    /// One PPO update on a rollout at training `progress` in `[0, 1]`.
    pub fn update(&mut self, rollout: &Rollout, progress: f64) -> Result<UpdateStats> {
        let started = Instant::now();
        let n = rollout.len();
        let width = self.net.layout().actions;
        let device = self.net.device().clone();
        let inputs = self.net.input_rows(&rollout.states, &rollout.stages)?;
        let next_inputs = self
            .net
            .input_rows(&rollout.next_states, &rollout.next_stages)?;
        let [values, next_values] = match self.engine {
            UpdateEngine::Fused => fused::values(&self.net, [&inputs, &next_inputs])?,
            UpdateEngine::Candle => {
                let value = |rows: Vec<f32>| -> Result<Vec<f32>> {
                    let rows =
                        Tensor::from_vec(rows, (n, self.net.layout().input_width()), &device)?;
                    Ok(self.net.value(&rows)?.to_vec1()?)
                };
                [value(inputs.clone())?, value(next_inputs)?]
            }
        };
        let scale = self.reward_scale(rollout);
        let records: Vec<StepRecord> = (0..n)
            .map(|t| StepRecord {
                intra: rollout.intra[t] * scale,
                transition: rollout.transition[t] * scale,
                value: values[t],
                next_value: next_values[t],
                terminal: rollout.terminal[t],
                last: rollout.last[t],
            })
            .collect();
        let (mut advantages, returns) = gae(
            &records,
            self.config.gamma as f32,
            self.config.gae_lambda as f32,
        );
        // Normalized once over the rollout (CleanRL and SB3 do it per minibatch; with
        // minibatches of hundreds the two differ only by sampling noise).
        if n > 1 {
            normalize(&mut advantages)?;
        }
        let learning_rate = self.config.learning_rate_at(progress);
        self.optimizer.learning_rate = learning_rate;
        let mut stats = UpdateStats {
            learning_rate,
            reward_scale: scale,
            ..UpdateStats::default()
        };
        match self.engine {
            UpdateEngine::Fused => {
                let columns = Columns {
                    inputs,
                    actions: rollout.actions.concat(),
                    masks: rollout.masks.concat(),
                    old_log_probs: rollout.log_probs.clone(),
                    advantages,
                    returns,
                    width: self.net.layout().input_width(),
                    action_width: width,
                };
                stats.timing.prepare = started.elapsed().as_secs_f64();
                self.epochs_fused(&columns, &mut stats)?;
            }
            UpdateEngine::Candle => {
                let rows = |v: &[Vec<f32>]| -> Result<Tensor> {
                    Ok(Tensor::from_vec(v.concat(), (n, width), &device)?)
                };
                let columns = [
                    Tensor::from_vec(inputs, (n, self.net.layout().input_width()), &device)?,
                    rows(&rollout.actions)?,
                    rows(&rollout.masks)?,
                    Tensor::from_vec(rollout.log_probs.clone(), n, &device)?,
                    Tensor::from_vec(advantages, n, &device)?,
                    Tensor::from_vec(returns, n, &device)?,
                ];
                stats.timing.prepare = started.elapsed().as_secs_f64();
                self.epochs_candle(&columns, n, &mut stats)?;
            }
        }
        let scale = 1.0 / stats.minibatches.max(1) as f32;
        stats.policy_loss *= scale;
        stats.value_loss *= scale;
        stats.entropy *= scale;
        stats.approx_kl *= scale;
        stats.clipfrac *= scale;
        let norm_start = Instant::now();
        if self.config.norm_obs {
            self.net.update_norm(&rollout.states, &rollout.stages);
        }
        stats.timing.bookkeeping += norm_start.elapsed().as_secs_f64();
        Ok(stats)
    }

    /// The minibatch epochs with the fused engine: the networks on the host for the whole
    /// update, written back once at its end.
    fn epochs_fused(&mut self, columns: &Columns, stats: &mut UpdateStats) -> Result<()> {
        let n = columns.len();
        let coefs = Coefs {
            clip: self.config.clip_coef as f32,
            ent: self.config.ent_coef as f32,
            vf: self.config.vf_coef as f32,
            max_grad_norm: self.config.max_grad_norm as f32,
        };
        let mut engine = Engine::load(&self.net, &mut self.optimizer)?;
        let mut shuffled = Columns::default();
        let minibatch = self.config.minibatch_size.min(n).max(1);
        'epochs: for _ in 0..self.config.update_epochs {
            let order = self.noise.shuffle(n);
            let shuffle_start = Instant::now();
            columns.gather(&order, &mut shuffled);
            stats.timing.shuffle += shuffle_start.elapsed().as_secs_f64();
            for start in (0..n).step_by(minibatch) {
                let started = Instant::now();
                let len = minibatch.min(n - start);
                let step = self.optimizer.next_step();
                let mb = engine.minibatch(shuffled.slice(start, len), coefs, step);
                let secs = started.elapsed().as_secs_f64();
                stats.timing.optimizer += mb.optimizer_secs;
                stats.timing.forward_backward += secs - mb.optimizer_secs;
                stats.policy_loss += mb.policy_loss;
                stats.value_loss += mb.value_loss;
                stats.entropy += mb.entropy;
                stats.approx_kl += mb.approx_kl;
                stats.clipfrac += mb.clipfrac;
                stats.minibatches += 1;
                let target_kl = self.config.target_kl as f32;
                if target_kl > 0.0 && mb.approx_kl > 1.5 * target_kl {
                    break 'epochs;
                }
            }
        }
        let write_back = Instant::now();
        engine.store(&self.net, &mut self.optimizer)?;
        stats.timing.optimizer += write_back.elapsed().as_secs_f64();
        Ok(())
    }

    /// The minibatch epochs with candle's autograd (the reference path) over the columns
    /// `[inputs, actions, masks, old log-probs, advantages, returns]`.
    fn epochs_candle(
        &mut self,
        columns: &[Tensor],
        n: usize,
        stats: &mut UpdateStats,
    ) -> Result<()> {
        let device = self.net.device().clone();
        let minibatch = self.config.minibatch_size.min(n).max(1);
        'epochs: for _ in 0..self.config.update_epochs {
            let order: Vec<u32> = self
                .noise
                .shuffle(n)
                .into_iter()
                .map(|i| i as u32)
                .collect();
            let order = Tensor::from_vec(order, n, &device)?;
            let shuffle_start = Instant::now();
            let shuffled = columns
                .iter()
                .map(|c| c.index_select(&order, 0))
                .collect::<candle_core::Result<Vec<_>>>()?;
            stats.timing.shuffle += shuffle_start.elapsed().as_secs_f64();
            for start in (0..n).step_by(minibatch) {
                let len = minibatch.min(n - start);
                let batch = shuffled
                    .iter()
                    .map(|c| c.narrow(0, start, len))
                    .collect::<candle_core::Result<Vec<_>>>()?;
                let kl = self.minibatch(&batch, stats)?;
                let target_kl = self.config.target_kl as f32;
                if target_kl > 0.0 && kl > 1.5 * target_kl {
                    break 'epochs;
                }
            }
        }
        Ok(())
    }

    /// One gradient step on a minibatch `[inputs, actions, masks, old log-probs, advantages,
    /// returns]`; adds its losses to `stats` and returns its approximate KL.
    fn minibatch(&mut self, batch: &[Tensor], stats: &mut UpdateStats) -> Result<f32> {
        let started = Instant::now();
        let CandleLoss {
            loss,
            policy_loss,
            value_loss,
            entropy,
            log_ratio,
        } = candle_loss(&self.net, &self.config, batch)?;
        let grads = loss.backward()?;
        let stepped = Instant::now();
        stats.timing.forward_backward += (stepped - started).as_secs_f64();
        self.optimizer
            .step(self.net.params(), &grads, self.config.max_grad_norm as f32)?;
        let read = Instant::now();
        stats.timing.optimizer += (read - stepped).as_secs_f64();

        let log_ratio: Vec<f32> = log_ratio.to_vec1()?;
        let (approx_kl, clipfrac) = kl_and_clipfrac(&log_ratio, self.config.clip_coef as f32);
        stats.policy_loss += policy_loss.to_scalar::<f32>()?;
        stats.value_loss += value_loss.to_scalar::<f32>()?;
        stats.entropy += entropy.to_scalar::<f32>()?;
        stats.approx_kl += approx_kl;
        stats.clipfrac += clipfrac;
        stats.minibatches += 1;
        stats.timing.bookkeeping += read.elapsed().as_secs_f64();
        Ok(approx_kl)
    }
}

/// A minibatch's PPO loss as candle tensors (the reference path), with its parts.
pub(crate) struct CandleLoss {
    pub loss: Tensor,
    pub policy_loss: Tensor,
    pub value_loss: Tensor,
    pub entropy: Tensor,
    pub log_ratio: Tensor,
}

/// The PPO loss of `net` on a minibatch `[inputs, actions, masks, old log-probs, advantages,
/// returns]`: the clipped surrogate, `vf_coef` times the squared value error, minus
/// `ent_coef` times the entropy.
pub(crate) fn candle_loss(
    net: &ActorCritic,
    config: &PpoConfig,
    batch: &[Tensor],
) -> Result<CandleLoss> {
    let [input, actions, masks, old_log_probs, advantages, returns] = batch else {
        return Err(Error::Length {
            what: "minibatch columns",
            expected: 6,
            got: batch.len(),
        });
    };
    let log_probs = net.log_prob(&net.mean(input)?, actions, masks)?;
    let log_ratio = (&log_probs - old_log_probs)?;
    let ratio = log_ratio.exp()?;
    let eps = f64::from(config.clip_coef as f32);
    let unclipped = (&ratio * advantages)?;
    let clipped = (ratio.clamp(1.0 - eps, 1.0 + eps)? * advantages)?;
    let policy_loss = unclipped.minimum(&clipped)?.mean_all()?.neg()?;
    let value_loss = (net.value(input)? - returns)?.sqr()?.mean_all()?;
    let entropy = net.entropy(masks)?.mean_all()?;
    let loss = ((&policy_loss + (&value_loss * config.vf_coef)?)? - (&entropy * config.ent_coef)?)?;
    Ok(CandleLoss {
        loss,
        policy_loss,
        value_loss,
        entropy,
        log_ratio,
    })
}

/// The policy of `net` at a batch of abstract states: Gaussian actions around its means (the
/// means themselves without `noise`) and their log-probabilities over the live dimensions of
/// `masks`; noise drawn row by row in order. The log standard deviations are taken as
/// ln(std) rather than the stored log std: the log-probabilities keep the bits the shipped
/// model and the seeded tests were trained with.
fn sample_policy(
    net: &ActorCritic,
    states: &[Vec<f32>],
    stages: &[usize],
    masks: &[Vec<f32>],
    mut noise: Option<&mut Noise>,
) -> Result<(Vec<Vec<f32>>, Vec<f32>)> {
    let means: Vec<Vec<f32>> = net.mean(&net.input(states, stages)?)?.to_vec2()?;
    let log_std: Vec<f32> = net.std()?.iter().map(|s| s.ln()).collect();
    let mut actions = Vec::with_capacity(means.len());
    let mut log_probs = Vec::with_capacity(means.len());
    for (row, mask) in means.iter().zip(masks) {
        let mut action = Vec::with_capacity(row.len());
        let mut log_prob = 0.0f32;
        for ((&m, &ls), &live) in row.iter().zip(&log_std).zip(mask) {
            let z = noise.as_mut().map_or(0.0, |n| n.normal());
            action.push(m + ls.exp() * z);
            log_prob += live * (-0.5 * z * z - ls - HALF_LOG_TWO_PI);
        }
        actions.push(action);
        log_probs.push(log_prob);
    }
    Ok((actions, log_probs))
}

impl Actor for Ppo {
    fn acts_alone(&self) -> bool {
        true
    }

    fn act_one(
        &self,
        state: &[f32],
        stage: usize,
        mask: &[f32],
        noise: &mut Noise,
    ) -> Result<(Vec<f32>, f32)> {
        let (mut actions, log_probs) = sample_policy(
            &self.net,
            &[state.to_vec()],
            &[stage],
            &[mask.to_vec()],
            Some(noise),
        )?;
        Ok((actions.pop().unwrap_or_default(), log_probs[0]))
    }

    fn act_batch(
        &mut self,
        states: &[Vec<f32>],
        stages: &[usize],
        masks: &[Vec<f32>],
        deterministic: bool,
    ) -> Result<(Vec<Vec<f32>>, Vec<f32>)> {
        Ppo::act_batch(self, states, stages, masks, deterministic)
    }
}
