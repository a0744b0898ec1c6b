//! PPO inside a Contextual Reward Machine (paper, section III-B), read top to bottom:
//! rollout through `crm::CrmEnv`, GAE with the transition reward in the TD error, then the
//! minibatch loop with the clipped surrogate on abstract states, the value loss, gradient-norm
//! clipping and the paper's learning-rate steps. The reward mode picks CRM-PPO (`crm`), LPPO
//! (`dense`) or IPPO (`sparse`) on the same machine.

use candle_core::Tensor;
use candle_nn::{AdamW, Optimizer, ParamsAdamW};

use crate::config::PpoConfig;
use crate::error::Result;
use crate::gae::{StepRecord, gae, normalize};
use crate::network::{ActorCritic, Layout};

/// A deterministic normal sampler (SplitMix64 and Box-Muller), so rollouts are bitwise
/// reproducible from a seed.
#[derive(Clone, Debug)]
pub struct Noise(u64);

impl Noise {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// One standard normal sample.
    pub fn normal(&mut self) -> f32 {
        let (u, v) = (self.uniform(), self.uniform());
        ((-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()) as f32
    }

    /// A permutation of `0..n`.
    pub fn shuffle(&mut self, n: usize) -> Vec<usize> {
        let mut order: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = (self.next_u64() % (i as u64 + 1)) as usize;
            order.swap(i, j);
        }
        order
    }
}

/// Collected experience of one rollout.
#[derive(Clone, Debug, Default)]
pub struct Rollout {
    pub states: Vec<Vec<f32>>,
    pub stages: Vec<usize>,
    pub next_states: Vec<Vec<f32>>,
    pub next_stages: Vec<usize>,
    /// Sampled union-space actions (before the environment clips them).
    pub actions: Vec<Vec<f32>>,
    pub masks: Vec<Vec<f32>>,
    pub log_probs: Vec<f32>,
    pub intra: Vec<f32>,
    pub transition: Vec<f32>,
    pub terminal: Vec<bool>,
    pub last: Vec<bool>,
    /// Episodes that ended in this rollout: (success, length, return).
    pub episodes: Vec<(bool, usize, f32)>,
}

impl Rollout {
    pub fn len(&self) -> usize {
        self.states.len()
    }

    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }
}

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

    /// Samples (or, `deterministic`, takes the mean of) the policy at one abstract state;
    /// returns the union-space action and its log-probability under the stage's mask.
    pub fn act(
        &mut self,
        state: &[f32],
        stage: usize,
        mask: &[f32],
        deterministic: bool,
    ) -> Result<(Vec<f32>, f32)> {
        let input = self.net.input(&[state.to_vec()], &[stage])?;
        let mean: Vec<f32> = self.net.mean(&input)?.squeeze(0)?.to_vec1()?;
        let std = self.net.std()?;
        let action: Vec<f32> = if deterministic {
            mean.clone()
        } else {
            mean.iter()
                .zip(&std)
                .map(|(m, s)| m + s * self.noise.normal())
                .collect()
        };
        let device = self.net.device();
        let log_prob = self
            .net
            .log_prob(
                &Tensor::from_vec(mean, (1, action.len()), device)?,
                &Tensor::from_vec(action.clone(), (1, action.len()), device)?,
                &Tensor::from_vec(mask.to_vec(), (1, mask.len()), device)?,
            )?
            .to_vec1::<f32>()?[0];
        Ok((action, log_prob))
    }

    /// Collects `steps` transitions from `env`, resetting with `next_seed()` when an episode
    /// ends.
    pub fn collect<E: crm::Environment>(
        &mut self,
        env: &mut crm::CrmEnv<E>,
        steps: usize,
        next_seed: &mut dyn FnMut() -> u64,
    ) -> Result<Rollout> {
        let mut rollout = Rollout::default();
        let (mut stage, mut state) = env.reset(next_seed()).map_err(crm_error)?;
        let mut episode_return = 0.0f32;
        let mut episode_length = 0usize;
        for _ in 0..steps {
            let mask = env.machine().action_mask(stage);
            let (action, log_prob) = self.act(&state, stage, &mask, false)?;
            let step = env.step(&action).map_err(crm_error)?;
            episode_return += step.intra_reward + step.transition_reward;
            episode_length += 1;
            let last = step.done || step.truncated;
            rollout.states.push(state);
            rollout.stages.push(stage);
            rollout.next_states.push(step.abstract_state.clone());
            rollout.next_stages.push(step.stage);
            rollout.actions.push(action);
            rollout.masks.push(mask);
            rollout.log_probs.push(log_prob);
            rollout.intra.push(step.intra_reward);
            rollout.transition.push(step.transition_reward);
            rollout.terminal.push(step.done);
            rollout.last.push(last);
            if last {
                let success = step.done && env.machine().stage_name(step.stage) == "success";
                rollout
                    .episodes
                    .push((success, episode_length, episode_return));
                episode_return = 0.0;
                episode_length = 0;
                (stage, state) = env.reset(next_seed()).map_err(crm_error)?;
            } else {
                (stage, state) = (step.stage, step.abstract_state);
            }
        }
        // The rollout's cut is a trajectory end too: bootstrap from the value there.
        if let Some(last) = rollout.last.last_mut() {
            *last = true;
        }
        Ok(rollout)
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

fn crm_error(err: crm::Error) -> crate::error::Error {
    crate::error::Error::Env(err.to_string())
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
