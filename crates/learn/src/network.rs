//! The actor-critic networks: a Gaussian policy over the union action space with the stage's
//! action mask, and a value function on the stage's abstract state plus the stage.
//!
//! Both see `[phi_i(u) normalized and zero-padded to the widest abstraction, one-hot(stage)]`
//! (see `normalize.rs`; the statistics live with the networks and in their checkpoints).
//! Dimensions outside the stage's action set are neither sampled nor counted in
//! log-probabilities, so they receive no gradient. Weights start orthogonal (CleanRL's
//! `layer_init`: gain sqrt(2) for hidden layers, 0.01 for the policy's output, 1 for the
//! value's).

use candle_core::{D, Device, Tensor, Var};
use candle_nn::Linear;

use crate::error::{Error, Result};
use crate::layers::{Init, mlp_init};
pub(crate) use crate::layers::{mlp, run};
use crate::noise::Noise;
use crate::normalize::ObsNorm;

/// Input and output sizes of the networks, from a machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Layout {
    /// Width of the padded abstract state.
    pub state_width: usize,
    /// Number of stages (one-hot width).
    pub stages: usize,
    /// Width of the union action space.
    pub actions: usize,
}

impl Layout {
    pub fn of(machine: &crm::Machine) -> Self {
        Self {
            state_width: machine.max_abstract_len(),
            stages: machine.stage_count(),
            actions: machine.action_count(),
        }
    }

    pub fn input_width(&self) -> usize {
        self.state_width + self.stages
    }

    /// Refuses observation statistics of another shape than this layout's states.
    pub fn check_norm(&self, norm: &ObsNorm) -> Result<()> {
        if norm.stage_count() != self.stages || norm.width() != self.state_width {
            return Err(Error::Length {
                what: "observation statistics",
                expected: self.stages * self.state_width,
                got: norm.stage_count() * norm.width(),
            });
        }
        Ok(())
    }
}

/// The actor and the critic, with their parameters in a stable, named order.
pub struct ActorCritic {
    layout: Layout,
    hidden: Vec<usize>,
    device: Device,
    actor: Vec<Linear>,
    critic: Vec<Linear>,
    log_std: Var,
    params: Vec<(String, Var)>,
    norm: ObsNorm,
}

/// The network input `[phi_i(u) zero-padded to state_width, one-hot(stage)]` for a batch.
pub fn encode(
    layout: Layout,
    states: &[Vec<f32>],
    stages: &[usize],
    device: &Device,
) -> Result<Tensor> {
    encode_normalized(layout, states, stages, None, device)
}

/// [`encode`] with each state normalized by `norm` first.
pub fn encode_normalized(
    layout: Layout,
    states: &[Vec<f32>],
    stages: &[usize],
    norm: Option<&ObsNorm>,
    device: &Device,
) -> Result<Tensor> {
    let data = encode_rows(layout, states, stages, norm)?;
    Ok(Tensor::from_vec(
        data,
        (states.len(), layout.input_width()),
        device,
    )?)
}

/// [`encode_normalized`] into a host buffer, `[states, input_width]` row-major.
pub(crate) fn encode_rows(
    layout: Layout,
    states: &[Vec<f32>],
    stages: &[usize],
    norm: Option<&ObsNorm>,
) -> Result<Vec<f32>> {
    if states.len() != stages.len() {
        return Err(Error::Length {
            what: "stages",
            expected: states.len(),
            got: stages.len(),
        });
    }
    let width = layout.input_width();
    let mut data = vec![0.0f32; states.len() * width];
    for (row, (state, &stage)) in states.iter().zip(stages).enumerate() {
        if state.len() > layout.state_width {
            return Err(Error::Length {
                what: "abstract state",
                expected: layout.state_width,
                got: state.len(),
            });
        }
        if stage >= layout.stages {
            return Err(Error::Length {
                what: "stage index",
                expected: layout.stages,
                got: stage,
            });
        }
        let base = row * width;
        let slot = &mut data[base..base + state.len()];
        match norm {
            Some(norm) => norm.normalize_into(state, stage, slot),
            None => slot.copy_from_slice(state),
        }
        data[base + layout.state_width + stage] = 1.0;
    }
    Ok(data)
}

impl std::fmt::Debug for ActorCritic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ActorCritic")
            .field("layout", &self.layout)
            .field("hidden", &self.hidden)
            .finish_non_exhaustive()
    }
}

impl ActorCritic {
    /// New networks for `layout` with hidden widths `hidden`, initialized from `seed`.
    pub fn new(layout: Layout, hidden: &[usize], seed: u64) -> Result<Self> {
        let device = Device::Cpu;
        let mut noise = Noise::new(seed);
        let mut params = Vec::new();
        let mut widths = vec![layout.input_width()];
        widths.extend_from_slice(hidden);
        let mut actor_widths = widths.clone();
        actor_widths.push(layout.actions);
        let mut critic_widths = widths;
        critic_widths.push(1);
        let hidden_init = Init::Orthogonal(std::f32::consts::SQRT_2);
        let actor = mlp_init(
            &mut noise,
            &device,
            "actor",
            &actor_widths,
            &mut params,
            hidden_init,
            Init::Orthogonal(0.01),
        )?;
        let critic = mlp_init(
            &mut noise,
            &device,
            "critic",
            &critic_widths,
            &mut params,
            hidden_init,
            Init::Orthogonal(1.0),
        )?;
        // CleanRL's continuous PPO starts at log std 0; `Ppo::new` sets the configured one.
        let log_std = Var::from_vec(vec![0.0f32; layout.actions], layout.actions, &device)?;
        params.push(("actor.log_std".to_string(), log_std.clone()));
        Ok(Self {
            layout,
            hidden: hidden.to_vec(),
            device,
            actor,
            critic,
            log_std,
            params,
            norm: ObsNorm::new(layout.stages, layout.state_width),
        })
    }

    /// The observation statistics the inputs are normalized with.
    pub fn norm(&self) -> &ObsNorm {
        &self.norm
    }

    /// Folds a batch of raw abstract states into the observation statistics.
    pub fn update_norm(&mut self, states: &[Vec<f32>], stages: &[usize]) {
        self.norm.update(states, stages);
    }

    /// Replaces the observation statistics (checkpoints, resuming); they must fit the layout.
    pub fn set_norm(&mut self, norm: ObsNorm) -> Result<()> {
        self.layout.check_norm(&norm)?;
        self.norm = norm;
        Ok(())
    }

    /// Sets every log standard deviation to `value`.
    pub fn set_log_std(&self, value: f32) -> Result<()> {
        let n = self.layout.actions;
        self.log_std
            .set(&Tensor::from_vec(vec![value; n], n, &self.device)?)?;
        Ok(())
    }

    pub fn layout(&self) -> Layout {
        self.layout
    }

    pub fn hidden(&self) -> &[usize] {
        &self.hidden
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Parameters in a stable order, named for checkpoints.
    pub fn params(&self) -> &[(String, Var)] {
        &self.params
    }

    /// Builds the network input from abstract states (each at most `state_width` long) and
    /// their stages.
    pub fn input(&self, states: &[Vec<f32>], stages: &[usize]) -> Result<Tensor> {
        encode_normalized(self.layout, states, stages, Some(&self.norm), &self.device)
    }

    /// [`Self::input`] into a host buffer, `[states, input_width]` row-major.
    pub(crate) fn input_rows(&self, states: &[Vec<f32>], stages: &[usize]) -> Result<Vec<f32>> {
        encode_rows(self.layout, states, stages, Some(&self.norm))
    }

    /// Policy means `[batch, actions]`.
    pub fn mean(&self, input: &Tensor) -> Result<Tensor> {
        run(&self.actor, input)
    }

    /// Values `[batch]`.
    pub fn value(&self, input: &Tensor) -> Result<Tensor> {
        Ok(run(&self.critic, input)?.squeeze(1)?)
    }

    /// `log pi(a | u')` summed over the live dimensions only: `[batch]`.
    pub fn log_prob(&self, mean: &Tensor, actions: &Tensor, mask: &Tensor) -> Result<Tensor> {
        let log_std = self
            .log_std
            .as_tensor()
            .unsqueeze(0)?
            .broadcast_as(mean.shape())?;
        let z = ((actions - mean)? / log_std.exp()?)?;
        let half_log_two_pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
        let per_dim = ((z.sqr()? * -0.5)? - log_std)?.affine(1.0, -half_log_two_pi)?;
        Ok((per_dim * mask)?.sum(D::Minus1)?)
    }

    /// Entropy of the policy over the live dimensions: `[batch]`.
    pub fn entropy(&self, mask: &Tensor) -> Result<Tensor> {
        let per_dim = self
            .log_std
            .as_tensor()
            .affine(1.0, 0.5 + 0.5 * (2.0 * std::f64::consts::PI).ln())?;
        Ok(mask.broadcast_mul(&per_dim.unsqueeze(0)?)?.sum(D::Minus1)?)
    }

    /// Every parameter value in [`Self::params`] order, flattened (for comparisons and
    /// inspection).
    pub fn flat_params(&self) -> Result<Vec<f32>> {
        let mut out = Vec::new();
        for (_, var) in &self.params {
            out.extend(var.as_tensor().flatten_all()?.to_vec1::<f32>()?);
        }
        Ok(out)
    }

    /// The policy's standard deviations, per union dimension.
    pub fn std(&self) -> Result<Vec<f32>> {
        Ok(self.log_std.as_tensor().exp()?.to_vec1()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> Layout {
        Layout {
            state_width: 4,
            stages: 3,
            actions: 5,
        }
    }

    #[test]
    fn the_same_seed_gives_bitwise_identical_networks() {
        let a = ActorCritic::new(layout(), &[16, 16], 7).expect("net");
        let b = ActorCritic::new(layout(), &[16, 16], 7).expect("net");
        let c = ActorCritic::new(layout(), &[16, 16], 8).expect("net");
        let flat = |net: &ActorCritic| -> Vec<u32> {
            net.flat_params()
                .expect("params")
                .into_iter()
                .map(f32::to_bits)
                .collect()
        };
        assert_eq!(flat(&a), flat(&b));
        assert_ne!(flat(&a), flat(&c));
    }

    #[test]
    fn masked_dimensions_get_no_gradient_and_do_not_count() {
        let net = ActorCritic::new(layout(), &[16], 3).expect("net");
        let input = net
            .input(&[vec![0.1, -0.2, 0.3], vec![0.5, 0.0, 0.0, 1.0]], &[0, 1])
            .expect("input");
        let mean = net.mean(&input).expect("mean");
        let actions = Tensor::new(
            &[[0.3f32, -0.1, 0.2, 0.9, -0.7], [0.0, 0.4, -0.2, 0.1, 0.5]],
            net.device(),
        )
        .expect("t");
        // Stage 0 uses dimensions 0-2; stage 1 uses all five.
        let mask = Tensor::new(
            &[[1.0f32, 1.0, 1.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 1.0]],
            net.device(),
        )
        .expect("t");
        let log_prob = net.log_prob(&mean, &actions, &mask).expect("log prob");
        let loss = log_prob
            .narrow(0, 0, 1)
            .expect("row")
            .sum_all()
            .expect("sum");
        let grads = loss.backward().expect("backward");
        let out = net
            .params()
            .iter()
            .find(|(n, _)| n == "actor.1.weight")
            .map(|(_, v)| v)
            .expect("output layer");
        let grad = grads
            .get(out.as_tensor())
            .expect("gradient")
            .to_vec2::<f32>()
            .expect("vec");
        // Rows 3 and 4 of the output layer produce the masked dimensions.
        for (row, values) in grad.iter().enumerate().skip(3) {
            assert!(values.iter().all(|&g| g == 0.0), "row {row}: {values:?}");
        }
        assert!(grad[0].iter().any(|&g| g != 0.0));
        let std_grad = grads
            .get(
                net.params()
                    .last()
                    .map(|(_, v)| v.as_tensor())
                    .expect("log_std"),
            )
            .expect("grad")
            .to_vec1::<f32>()
            .expect("vec");
        assert_eq!(&std_grad[3..], &[0.0, 0.0]);

        // Changing a masked action changes nothing.
        let other = Tensor::new(
            &[[0.3f32, -0.1, 0.2, -5.0, 5.0], [0.0, 0.4, -0.2, 0.1, 0.5]],
            net.device(),
        )
        .expect("t");
        let again = net
            .log_prob(&mean, &other, &mask)
            .expect("log prob")
            .to_vec1::<f32>()
            .expect("vec");
        assert_eq!(again, log_prob.to_vec1::<f32>().expect("vec"));
    }

    #[test]
    fn the_log_prob_is_the_gaussian_density() {
        let net = ActorCritic::new(
            Layout {
                state_width: 1,
                stages: 1,
                actions: 1,
            },
            &[4],
            1,
        )
        .expect("net");
        let mean = Tensor::new(&[[0.5f32]], net.device()).expect("t");
        let action = Tensor::new(&[[1.0f32]], net.device()).expect("t");
        let mask = Tensor::new(&[[1.0f32]], net.device()).expect("t");
        let got = net
            .log_prob(&mean, &action, &mask)
            .expect("lp")
            .to_vec1::<f32>()
            .expect("v")[0];
        let std = 1.0f32;
        let want =
            -0.5 * ((1.0 - 0.5) / std).powi(2) - std.ln() - 0.5 * (2.0 * std::f32::consts::PI).ln();
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
    }

    #[test]
    fn inputs_are_checked() {
        let net = ActorCritic::new(layout(), &[8], 1).expect("net");
        assert!(net.input(&[vec![0.0; 5]], &[0]).is_err());
        assert!(net.input(&[vec![0.0; 2]], &[3]).is_err());
        assert!(net.input(&[vec![0.0; 2]], &[]).is_err());
        let input = net
            .input(&[vec![1.0, 2.0]], &[2])
            .expect("input")
            .to_vec2::<f32>()
            .expect("v");
        assert_eq!(input[0], vec![1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    }
}
