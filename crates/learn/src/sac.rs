//! SAC inside the CRM (the paper's CRM-SAC baseline): a tanh-squashed Gaussian actor with a
//! state-dependent scale, twin Q critics with Polyak-averaged targets, automatic entropy
//! temperature, and a replay buffer; ReLU hidden layers, as Stable-Baselines3's SAC (the
//! authors' library). The reward is the CRM's (intra-stage plus transition).
//! Dimensions outside the stage's action set are zero in every action, left out of
//! log-probabilities, and the entropy target counts only the live ones.

use std::collections::HashMap;

use candle_core::{D, Device, Tensor, Var};
use candle_nn::Linear;
use crm_api::SacConfig;

use crate::error::Result;
use crate::layers::{Activation, run_with};
use crate::network::{Layout, encode_normalized, mlp};
use crate::noise::Noise;
use crate::normalize::ObsNorm;
use crate::optim::Adam;
use crate::replay::{Replay, Transition};
use crate::rollout::{Actor, Rollout};
use crate::state::{self, SacRecord};

/// Adam's epsilon for SAC: PyTorch's default, which Stable-Baselines3's SAC keeps.
const SAC_ADAM_EPS: f64 = 1e-8;

/// One fused Adam with the parameters it updates.
type Optimizer = (Adam, Vec<(String, Var)>);

const LOG_STD_MIN: f64 = -5.0;
const LOG_STD_MAX: f64 = 2.0;

/// The actor and critics, with their parameters in a stable, named order.
pub struct SacNets {
    pub layout: Layout,
    pub hidden: Vec<usize>,
    actor: Vec<Linear>,
    q1: Vec<Linear>,
    q2: Vec<Linear>,
    q1_target: Vec<Linear>,
    q2_target: Vec<Linear>,
    log_alpha: Var,
    /// `(name, var)`: actor, critics, targets, temperature.
    pub params: Vec<(String, Var)>,
    device: Device,
    /// The observation statistics the inputs are normalized with (stored in checkpoints).
    norm: ObsNorm,
}

impl SacNets {
    pub fn new(layout: Layout, hidden: &[usize], seed: u64) -> Result<Self> {
        let device = Device::Cpu;
        let mut noise = Noise::new(seed);
        let mut params = Vec::new();
        let mut widths = vec![layout.input_width()];
        widths.extend_from_slice(hidden);
        widths.push(2 * layout.actions);
        let actor = mlp(&mut noise, &device, "actor", &widths, &mut params)?;
        let mut q_widths = vec![layout.input_width() + layout.actions];
        q_widths.extend_from_slice(hidden);
        q_widths.push(1);
        let q1 = mlp(&mut noise, &device, "q1", &q_widths, &mut params)?;
        let q2 = mlp(&mut noise, &device, "q2", &q_widths, &mut params)?;
        let q1_target = mlp(&mut noise, &device, "q1_target", &q_widths, &mut params)?;
        let q2_target = mlp(&mut noise, &device, "q2_target", &q_widths, &mut params)?;
        let log_alpha = Var::from_vec(vec![0.2f32.ln()], 1, &device)?;
        params.push(("log_alpha".into(), log_alpha.clone()));
        let nets = Self {
            layout,
            hidden: hidden.to_vec(),
            actor,
            q1,
            q2,
            q1_target,
            q2_target,
            log_alpha,
            params,
            device,
            norm: ObsNorm::new(layout.stages, layout.state_width),
        };
        // Targets start as copies of the critics.
        nets.polyak(1.0)?;
        Ok(nets)
    }

    /// The named parameters of one network (`actor`, `q1`, ...).
    fn named(&self, prefix: &str) -> Vec<(String, Var)> {
        self.params
            .iter()
            .filter(|(name, _)| name.split('.').next() == Some(prefix))
            .cloned()
            .collect()
    }

    /// Moves the targets `tau` of the way to the critics: `tau * critic + (1 - tau) *
    /// target`, in one host pass per parameter (the same f32 arithmetic as the tensor form).
    fn polyak(&self, tau: f64) -> Result<()> {
        let (keep, take) = ((1.0 - tau) as f32, tau as f32);
        for (critic, target) in [("q1", "q1_target"), ("q2", "q2_target")] {
            for ((_, src), (_, dst)) in self.named(critic).iter().zip(self.named(target)) {
                let src_values = src.as_tensor().flatten_all()?.to_vec1::<f32>()?;
                let mut values = dst.as_tensor().flatten_all()?.to_vec1::<f32>()?;
                for (d, s) in values.iter_mut().zip(&src_values) {
                    *d = *s * take + *d * keep;
                }
                dst.set(&Tensor::from_vec(values, dst.shape(), dst.device())?)?;
            }
        }
        Ok(())
    }

    /// The network input: normalized abstract states (see `normalize.rs`) and the one-hot
    /// stage.
    pub fn input(&self, states: &[Vec<f32>], stages: &[usize]) -> Result<Tensor> {
        encode_normalized(self.layout, states, stages, Some(&self.norm), &self.device)
    }

    /// The observation statistics the inputs are normalized with.
    pub fn norm(&self) -> &ObsNorm {
        &self.norm
    }

    /// Folds a batch of raw abstract states into the observation statistics.
    pub fn update_norm(&mut self, states: &[Vec<f32>], stages: &[usize]) {
        self.norm.update(states, stages);
    }

    /// Replaces the observation statistics (checkpoints); they must fit the layout.
    pub fn set_norm(&mut self, norm: ObsNorm) -> Result<()> {
        self.layout.check_norm(&norm)?;
        self.norm = norm;
        Ok(())
    }

    /// Pre-squash means and clamped log standard deviations `[batch, actions]` each.
    fn head(&self, input: &Tensor) -> Result<(Tensor, Tensor)> {
        let out = run_with(&self.actor, input, Activation::Relu)?;
        let n = self.layout.actions;
        let mean = out.narrow(1, 0, n)?;
        let log_std = out.narrow(1, n, n)?.clamp(LOG_STD_MIN, LOG_STD_MAX)?;
        Ok((mean, log_std))
    }

    /// The deterministic action `tanh(mean) * mask`.
    pub fn mean_action(&self, input: &Tensor, mask: &Tensor) -> Result<Tensor> {
        Ok((self.head(input)?.0.tanh()? * mask)?)
    }

    /// A sampled action `tanh(mean + std * eps) * mask` for standard normal `eps` `[batch,
    /// actions]` (evaluations that sample the policy).
    pub fn sample_action(&self, input: &Tensor, mask: &Tensor, eps: &Tensor) -> Result<Tensor> {
        Ok(self.sample(input, mask, eps)?.0)
    }

    /// A reparameterized sample `tanh(mean + std * eps) * mask` and its log-probability over
    /// the live dimensions (with the tanh correction).
    fn sample(&self, input: &Tensor, mask: &Tensor, eps: &Tensor) -> Result<(Tensor, Tensor)> {
        let (mean, log_std) = self.head(input)?;
        let pre = (mean + (log_std.exp()? * eps)?)?;
        let action = pre.tanh()?;
        let half_log_two_pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
        let gaussian = ((eps.sqr()? * -0.5)? - &log_std)?.affine(1.0, -half_log_two_pi)?;
        let squash = (action.sqr()?.affine(-1.0, 1.0 + 1e-6)?).log()?;
        let log_prob = ((gaussian - squash)? * mask)?.sum(D::Minus1)?;
        Ok(((action * mask)?, log_prob))
    }

    fn q(layers: &[Linear], input: &Tensor, action: &Tensor) -> Result<Tensor> {
        let input = Tensor::cat(&[input, action], 1)?;
        Ok(run_with(layers, &input, Activation::Relu)?.squeeze(1)?)
    }

    /// A critic whose weights are constants to backpropagation: the actor's loss needs the
    /// gradient through the critic to the action, not the critic's own.
    fn frozen(layers: &[Linear]) -> Vec<Linear> {
        layers
            .iter()
            .map(|l| Linear::new(l.weight().detach(), l.bias().map(Tensor::detach)))
            .collect()
    }

    /// The smaller of two critics' values of an action: `[batch]`.
    fn min_of(q1: &[Linear], q2: &[Linear], input: &Tensor, action: &Tensor) -> Result<Tensor> {
        Ok(Self::q(q1, input, action)?.minimum(&Self::q(q2, input, action)?)?)
    }

    /// `min(Q1, Q2)` of an action: `[batch]`.
    pub fn min_q(&self, input: &Tensor, action: &Tensor) -> Result<Tensor> {
        Self::min_of(&self.q1, &self.q2, input, action)
    }

    /// [`Self::min_q`] with the critics' weights held constant.
    fn frozen_min_q(&self, input: &Tensor, action: &Tensor) -> Result<Tensor> {
        Self::min_of(
            &Self::frozen(&self.q1),
            &Self::frozen(&self.q2),
            input,
            action,
        )
    }

    pub fn alpha(&self) -> Result<f32> {
        Ok(self.log_alpha.as_tensor().exp()?.to_vec1::<f32>()?[0])
    }
}

/// What one iteration of updates reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct SacStats {
    pub critic_loss: f32,
    pub actor_loss: f32,
    pub alpha: f32,
    pub entropy: f32,
    pub updates: usize,
}

/// The learner: networks, optimizers, replay buffer and noise.
pub struct Sac {
    pub nets: SacNets,
    pub config: SacConfig,
    /// One fused Adam per loss, with the parameters it updates (no gradient clipping, as
    /// Stable-Baselines3's SAC).
    actor_opt: Optimizer,
    critic_opt: Optimizer,
    alpha_opt: Optimizer,
    buffer: Replay,
    noise: Noise,
    /// Masks of the machine's stages: a stored transition's masks follow from its stages.
    stage_masks: Vec<Vec<f32>>,
}

impl Sac {
    /// `stage_masks[s]` is the action mask of stage `s`.
    pub fn new(
        layout: Layout,
        config: SacConfig,
        stage_masks: Vec<Vec<f32>>,
        seed: u64,
    ) -> Result<Self> {
        config.validate()?;
        let capacity = config.buffer_size;
        let nets = SacNets::new(layout, &config.hidden, seed)?;
        let adam = |params: Vec<(String, Var)>| {
            let adam = Adam::new(&params, config.learning_rate).with_eps(SAC_ADAM_EPS);
            (adam, params)
        };
        let mut critics = nets.named("q1");
        critics.extend(nets.named("q2"));
        Ok(Self {
            actor_opt: adam(nets.named("actor")),
            critic_opt: adam(critics),
            alpha_opt: adam(nets.named("log_alpha")),
            nets,
            config,
            buffer: Replay::new(capacity),
            noise: Noise::new(seed ^ 0x5AC5_AC5A),
            stage_masks,
        })
    }

    /// Copies the networks of `other` (same layout and widths), keeping the optimizers bound
    /// to this learner's: how a run resumes from a checkpoint (with [`Self::restore`] for the
    /// rest of its training state; without, the replay buffer starts empty).
    pub fn load_weights(&mut self, other: &SacNets) -> Result<()> {
        if other.layout != self.nets.layout || other.hidden != self.nets.hidden {
            return Err(crate::Error::Config {
                field: "hidden",
                message: "checkpoint networks do not match this learner's".into(),
            });
        }
        for ((_, mine), (_, theirs)) in self.nets.params.iter().zip(&other.params) {
            mine.set(theirs.as_tensor())?;
        }
        self.nets.set_norm(other.norm().clone())
    }

    /// Everything but the weights that the next update depends on: the header's part and
    /// the tensors (the three optimizers' moments, the replay buffer; `crate::state`).
    pub fn state(&self) -> Result<(SacRecord, Vec<(String, Tensor)>)> {
        let layout = self.nets.layout;
        let (replay, mut tensors) = self.buffer.to_state(layout.state_width, layout.actions)?;
        let mut adam_steps = Vec::new();
        for (name, (adam, _)) in self.optimizers() {
            let (step, m, v) = adam.state();
            adam_steps.push(step);
            tensors.extend(state::moment_tensors(&format!("sac.{name}"), m, v)?);
        }
        let record = SacRecord {
            adam_steps,
            noise: self.noise.state(),
            replay,
        };
        Ok((record, tensors))
    }

    /// Goes on from a state of [`Self::state`] (with the weights loaded by
    /// [`Self::load_weights`]).
    pub fn restore(&mut self, record: &SacRecord, tensors: &HashMap<String, Tensor>) -> Result<()> {
        if record.adam_steps.len() != 3 {
            return Err(crate::Error::Length {
                what: "CRM-SAC's optimizer steps",
                expected: 3,
                got: record.adam_steps.len(),
            });
        }
        let names = ["actor", "critic", "alpha"];
        for ((name, step), opt) in names.iter().zip(&record.adam_steps).zip([
            &mut self.actor_opt,
            &mut self.critic_opt,
            &mut self.alpha_opt,
        ]) {
            let (m, v) = state::moments(&format!("sac.{name}"), opt.1.len(), tensors)?;
            opt.0.restore(*step, m, v)?;
        }
        self.buffer = Replay::from_state(self.config.buffer_size, &record.replay, tensors)?;
        self.noise = Noise::new(record.noise);
        Ok(())
    }

    fn optimizers(&self) -> [(&'static str, &Optimizer); 3] {
        [
            ("actor", &self.actor_opt),
            ("critic", &self.critic_opt),
            ("alpha", &self.alpha_opt),
        ]
    }

    /// The action mask of stage `stage` (none live past the machine's stages).
    fn stage_mask(&self, stage: usize) -> Vec<f32> {
        self.stage_masks
            .get(stage)
            .cloned()
            .unwrap_or_else(|| vec![0.0; self.nets.layout.actions])
    }

    /// Transitions stored so far (over the whole run).
    pub fn seen(&self) -> usize {
        self.buffer.seen()
    }

    fn normals(&mut self, rows: usize) -> Result<Tensor> {
        let n = self.nets.layout.actions;
        let data: Vec<f32> = (0..rows * n).map(|_| self.noise.normal()).collect();
        Ok(Tensor::from_vec(data, (rows, n), &self.nets.device)?)
    }

    /// Stores a rollout's transitions (the CRM reward: intra-stage plus transition), raw, and
    /// folds its states into the observation statistics (`norm_obs`).
    pub fn store(&mut self, rollout: &Rollout) {
        if self.config.norm_obs {
            self.nets.update_norm(&rollout.states, &rollout.stages);
        }
        for t in 0..rollout.len() {
            self.buffer.push(Transition {
                state: rollout.states[t].clone(),
                stage: rollout.stages[t],
                action: rollout.actions[t].clone(),
                reward: rollout.intra[t] + rollout.transition[t],
                next_state: rollout.next_states[t].clone(),
                next_stage: rollout.next_stages[t],
                terminal: rollout.terminal[t],
            });
        }
    }

    /// Gradient steps for `env_steps` new environment steps (none before `learning_starts`).
    pub fn update(&mut self, env_steps: usize) -> Result<SacStats> {
        let mut stats = SacStats::default();
        if self.buffer.seen() < self.config.learning_starts || self.buffer.is_empty() {
            stats.alpha = self.nets.alpha()?;
            return Ok(stats);
        }
        let steps = ((env_steps as f32) * self.config.updates_per_step as f32).ceil() as usize;
        for _ in 0..steps {
            let s = self.step()?;
            stats.critic_loss += s.critic_loss / steps as f32;
            stats.actor_loss += s.actor_loss / steps as f32;
            stats.entropy += s.entropy / steps as f32;
        }
        stats.updates = steps;
        stats.alpha = self.nets.alpha()?;
        Ok(stats)
    }

    /// One Adam step of `loss` on the optimizer's parameters.
    fn descend(opt: &mut Optimizer, loss: &Tensor) -> Result<()> {
        let grads = loss.backward()?;
        opt.0.step(&opt.1, &grads, f32::INFINITY)?;
        Ok(())
    }

    fn step(&mut self) -> Result<SacStats> {
        let batch = self.config.batch_size.min(self.buffer.len());
        let picks: Vec<usize> = (0..batch)
            .map(|_| {
                (self.noise.unit_f32() * self.buffer.len() as f32) as usize % self.buffer.len()
            })
            .collect();
        let rows = |f: &dyn Fn(&Transition) -> Vec<f32>| -> Vec<Vec<f32>> {
            picks.iter().map(|&i| f(self.buffer.get(i))).collect()
        };
        let device = self.nets.device.clone();
        let n = self.nets.layout.actions;
        let matrix = |data: Vec<Vec<f32>>| -> Result<Tensor> {
            Ok(Tensor::from_vec(data.concat(), (batch, n), &device)?)
        };
        let states = rows(&|s| s.state.clone());
        let next_states = rows(&|s| s.next_state.clone());
        let stages: Vec<usize> = picks.iter().map(|&i| self.buffer.get(i).stage).collect();
        let next_stages: Vec<usize> = picks
            .iter()
            .map(|&i| self.buffer.get(i).next_stage)
            .collect();
        let actions = matrix(rows(&|s| s.action.clone()))?;
        let masks = matrix(rows(&|s| self.stage_mask(s.stage)))?;
        let next_masks = matrix(rows(&|s| self.stage_mask(s.next_stage)))?;
        let rewards: Vec<f32> = picks.iter().map(|&i| self.buffer.get(i).reward).collect();
        let alive: Vec<f32> = picks
            .iter()
            .map(|&i| {
                if self.buffer.get(i).terminal {
                    0.0
                } else {
                    1.0
                }
            })
            .collect();
        let rewards = Tensor::from_vec(rewards, batch, &device)?;
        let alive = Tensor::from_vec(alive, batch, &device)?;
        let input = self.nets.input(&states, &stages)?;
        let next_input = self.nets.input(&next_states, &next_stages)?;
        let alpha = self.nets.log_alpha.as_tensor().exp()?.detach();

        // Critics: y = r + gamma * alive * (min Q_target(s', a') - alpha * log pi(a'|s')).
        let eps = self.normals(batch)?;
        let (next_action, next_log_prob) = self.nets.sample(&next_input, &next_masks, &eps)?;
        let next_q = SacNets::min_of(
            &self.nets.q1_target,
            &self.nets.q2_target,
            &next_input,
            &next_action,
        )?;
        let soft = (next_q - next_log_prob.broadcast_mul(&alpha)?)?;
        let target = (rewards + (alive * soft)?.affine(self.config.gamma, 0.0)?)?.detach();
        let q1 = SacNets::q(&self.nets.q1, &input, &actions)?;
        let q2 = SacNets::q(&self.nets.q2, &input, &actions)?;
        let critic_loss =
            ((q1 - &target)?.sqr()?.mean_all()? + (q2 - &target)?.sqr()?.mean_all()?)?;
        Self::descend(&mut self.critic_opt, &critic_loss)?;

        // Actor: minimize alpha * log pi(a|s) - min Q(s, a) with a reparameterized sample.
        let eps = self.normals(batch)?;
        let (action, log_prob) = self.nets.sample(&input, &masks, &eps)?;
        let actor_loss = (log_prob.broadcast_mul(&alpha)?
            - self.nets.frozen_min_q(&input, &action)?)?
        .mean_all()?;
        Self::descend(&mut self.actor_opt, &actor_loss)?;

        // Temperature: keep the entropy near the target for the live dimensions.
        let live = masks.sum(D::Minus1)?;
        let target_entropy = live.affine(self.config.target_entropy_per_dim, 0.0)?;
        let gap = (log_prob.detach() + target_entropy)?;
        let alpha_loss =
            (self.nets.log_alpha.as_tensor().broadcast_mul(&gap)? * -1.0)?.mean_all()?;
        Self::descend(&mut self.alpha_opt, &alpha_loss)?;
        self.nets.polyak(f64::from(self.config.tau as f32))?;
        Ok(SacStats {
            critic_loss: critic_loss.to_scalar::<f32>()?,
            actor_loss: actor_loss.to_scalar::<f32>()?,
            alpha: 0.0,
            entropy: -log_prob.mean_all()?.to_scalar::<f32>()?,
            updates: 1,
        })
    }
}

impl Actor for Sac {
    fn act_batch(
        &mut self,
        states: &[Vec<f32>],
        stages: &[usize],
        masks: &[Vec<f32>],
        deterministic: bool,
    ) -> Result<(Vec<Vec<f32>>, Vec<f32>)> {
        let rows = states.len();
        let n = self.nets.layout.actions;
        let mask = Tensor::from_vec(masks.concat(), (rows, n), &self.nets.device)?;
        if !deterministic && self.buffer.seen() < self.config.learning_starts {
            // Uniform exploration before learning starts.
            let data: Vec<f32> = (0..rows * n)
                .map(|_| 2.0 * self.noise.unit_f32() - 1.0)
                .collect();
            let action = (Tensor::from_vec(data, (rows, n), &self.nets.device)? * mask)?;
            return Ok((action.to_vec2()?, vec![0.0; rows]));
        }
        let input = self.nets.input(states, stages)?;
        let action = if deterministic {
            self.nets.mean_action(&input, &mask)?
        } else {
            let eps = self.normals(rows)?;
            self.nets.sample(&input, &mask, &eps)?.0
        };
        Ok((action.to_vec2()?, vec![0.0; rows]))
    }
}
