//! PPO inside a Contextual Reward Machine (paper, section III-B), read top to bottom:
//! a rollout (see `rollout.rs`), GAE with the transition reward in the TD error, then the
//! minibatch loop with the clipped surrogate on abstract states, the value loss, gradient-norm
//! clipping and the paper's learning-rate steps. The reward mode picks CRM-PPO (`crm`), LPPO
//! (`dense`) or IPPO (`sparse`) on the same machine.

use candle_core::Tensor;
use candle_nn::{AdamW, Optimizer, ParamsAdamW};

use crate::error::{Error, Result};
use crate::gae::{StepRecord, gae, normalize};
use crate::network::{ActorCritic, Layout};
use crate::noise::Noise;
use crate::rollout::Rollout;
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
}

/// The learner: networks, optimizer and its noise source.
pub struct Ppo {
    pub net: ActorCritic,
    pub config: PpoConfig,
    optimizer: AdamW,
    noise: Noise,
}

impl Ppo {
    pub fn new(layout: Layout, config: PpoConfig, seed: u64) -> Result<Self> {
        config.validate()?;
        let net = ActorCritic::new(layout, &config.hidden, seed)?;
        let vars = net.params().iter().map(|(_, v)| v.clone()).collect();
        let optimizer = AdamW::new(
            vars,
            ParamsAdamW {
                lr: config.learning_rate,
                weight_decay: 0.0,
                ..ParamsAdamW::default()
            },
        )?;
        Ok(Self {
            net,
            config,
            optimizer,
            noise: Noise::new(seed ^ 0xA5A5_5A5A),
        })
    }

    pub(crate) fn optimizer_mut(&mut self) -> &mut AdamW {
        &mut self.optimizer
    }

    pub(crate) fn noise_mut(&mut self) -> &mut Noise {
        &mut self.noise
    }

    /// Copies the weights of `other` (same layout and widths) into this learner's networks,
    /// keeping the optimizer bound to them: how a run resumes from a checkpoint.
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
        let rows = states.len();
        let width = self.net.layout().actions;
        let input = self.net.input(states, stages)?;
        let mean = self.net.mean(&input)?;
        let means: Vec<Vec<f32>> = mean.to_vec2()?;
        let std = self.net.std()?;
        let actions: Vec<Vec<f32>> = means
            .iter()
            .map(|row| {
                if deterministic {
                    row.clone()
                } else {
                    row.iter()
                        .zip(&std)
                        .map(|(m, s)| m + s * self.noise.normal())
                        .collect()
                }
            })
            .collect();
        let device = self.net.device();
        let log_probs = self
            .net
            .log_prob(
                &mean,
                &Tensor::from_vec(actions.concat(), (rows, width), device)?,
                &Tensor::from_vec(masks.concat(), (rows, width), device)?,
            )?
            .to_vec1::<f32>()?;
        Ok((actions, log_probs))
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

    /// One PPO update on a rollout at training `progress` in `[0, 1]`.
    pub fn update(&mut self, rollout: &Rollout, progress: f64) -> Result<UpdateStats> {
        let n = rollout.len();
        let width = self.net.layout().actions;
        let device = self.net.device().clone();
        let values: Vec<f32> = self
            .net
            .value(&self.net.input(&rollout.states, &rollout.stages)?)?
            .to_vec1()?;
        let next_values: Vec<f32> = self
            .net
            .value(&self.net.input(&rollout.next_states, &rollout.next_stages)?)?
            .to_vec1()?;
        let records: Vec<StepRecord> = (0..n)
            .map(|t| StepRecord {
                intra: rollout.intra[t],
                transition: rollout.transition[t],
                value: values[t],
                next_value: next_values[t],
                terminal: rollout.terminal[t],
                last: rollout.last[t],
            })
            .collect();
        let (advantages, returns) = gae(&records, self.config.gamma, self.config.gae_lambda);

        let learning_rate = self.config.learning_rate_at(progress);
        self.optimizer.set_learning_rate(learning_rate);
        let mut stats = UpdateStats {
            learning_rate,
            ..UpdateStats::default()
        };
        let mut batches = 0usize;
        for _ in 0..self.config.update_epochs {
            let order = self.noise.shuffle(n);
            for chunk in order.chunks(self.config.minibatch_size) {
                let pick =
                    |v: &Vec<Vec<f32>>| chunk.iter().map(|&i| v[i].clone()).collect::<Vec<_>>();
                let states = pick(&rollout.states);
                let stages: Vec<usize> = chunk.iter().map(|&i| rollout.stages[i]).collect();
                let flat = |rows: Vec<Vec<f32>>| -> Result<Tensor> {
                    let len = rows.len();
                    Ok(Tensor::from_vec(rows.concat(), (len, width), &device)?)
                };
                let actions = flat(pick(&rollout.actions))?;
                let masks = flat(pick(&rollout.masks))?;
                let old_log_probs = Tensor::from_vec(
                    chunk
                        .iter()
                        .map(|&i| rollout.log_probs[i])
                        .collect::<Vec<_>>(),
                    chunk.len(),
                    &device,
                )?;
                let mut batch_advantages: Vec<f32> = chunk.iter().map(|&i| advantages[i]).collect();
                if batch_advantages.len() > 1 {
                    normalize(&mut batch_advantages)?;
                }
                let batch_advantages = Tensor::from_vec(batch_advantages, chunk.len(), &device)?;
                let batch_returns = Tensor::from_vec(
                    chunk.iter().map(|&i| returns[i]).collect::<Vec<_>>(),
                    chunk.len(),
                    &device,
                )?;

                let input = self.net.input(&states, &stages)?;
                let log_probs = self
                    .net
                    .log_prob(&self.net.mean(&input)?, &actions, &masks)?;
                let log_ratio = (&log_probs - &old_log_probs)?;
                let ratio = log_ratio.exp()?;
                let eps = f64::from(self.config.clip_coef);
                let unclipped = (&ratio * &batch_advantages)?;
                let clipped = (ratio.clamp(1.0 - eps, 1.0 + eps)? * &batch_advantages)?;
                let policy_loss = unclipped.minimum(&clipped)?.mean_all()?.neg()?;
                let value_loss = (self.net.value(&input)? - &batch_returns)?
                    .sqr()?
                    .mean_all()?;
                let entropy = self.net.entropy(&masks)?.mean_all()?;
                let loss = ((&policy_loss + (&value_loss * f64::from(self.config.vf_coef))?)?
                    - (&entropy * f64::from(self.config.ent_coef))?)?;

                let mut grads = loss.backward()?;
                clip_grad_norm(&self.net, &mut grads, self.config.max_grad_norm)?;
                self.optimizer.step(&grads)?;

                // approx_kl = mean((ratio - 1) - log ratio), as CleanRL.
                let approx_kl = ((&ratio - 1.0)? - &log_ratio)?
                    .mean_all()?
                    .to_scalar::<f32>()?;
                let clipfrac = ((&ratio - 1.0)?
                    .abs()?
                    .gt(eps)?
                    .to_dtype(candle_core::DType::F32)?)
                .mean_all()?
                .to_scalar::<f32>()?;
                stats.policy_loss += policy_loss.to_scalar::<f32>()?;
                stats.value_loss += value_loss.to_scalar::<f32>()?;
                stats.entropy += entropy.to_scalar::<f32>()?;
                stats.approx_kl += approx_kl;
                stats.clipfrac += clipfrac;
                batches += 1;
            }
        }
        let scale = 1.0 / batches.max(1) as f32;
        stats.policy_loss *= scale;
        stats.value_loss *= scale;
        stats.entropy *= scale;
        stats.approx_kl *= scale;
        stats.clipfrac *= scale;
        Ok(stats)
    }
}

/// Scales all gradients so their global L2 norm is at most `max_norm`; returns the norm before.
pub fn clip_grad_norm(
    net: &ActorCritic,
    grads: &mut candle_core::backprop::GradStore,
    max_norm: f32,
) -> Result<f32> {
    let mut total = 0.0f32;
    for (_, var) in net.params() {
        if let Some(grad) = grads.get(var.as_tensor()) {
            total += grad.sqr()?.sum_all()?.to_scalar::<f32>()?;
        }
    }
    let norm = total.sqrt();
    if norm > max_norm {
        let factor = f64::from(max_norm / (norm + 1e-6));
        for (_, var) in net.params() {
            if let Some(grad) = grads.get(var.as_tensor()) {
                let scaled = (grad * factor)?;
                grads.insert(var.as_tensor(), scaled);
            }
        }
    }
    Ok(norm)
}
