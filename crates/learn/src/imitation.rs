//! Behaviour cloning: fitting the policy's mean to demonstrated actions (the scripted oracle's,
//! in the worker) before PPO, a warm start for the long-horizon holds PPO finds slowly. The
//! loss is the squared error over each step's live action dimensions only (the stage's
//! mask), so masked dimensions get no gradient, as in the PPO update.

use candle_core::Tensor;

use crate::error::{Error, Result};
use crate::ppo::Ppo;

/// Demonstrations: abstract states, stages, union-space actions in `[-1, 1]` and the stages'
/// action masks, one row per control step.
#[derive(Clone, Debug, Default)]
pub struct Demos {
    pub states: Vec<Vec<f32>>,
    pub stages: Vec<usize>,
    pub actions: Vec<Vec<f32>>,
    pub masks: Vec<Vec<f32>>,
}

impl Demos {
    pub fn len(&self) -> usize {
        self.states.len()
    }

    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    pub fn extend(&mut self, other: Demos) {
        self.states.extend(other.states);
        self.stages.extend(other.stages);
        self.actions.extend(other.actions);
        self.masks.extend(other.masks);
    }
}

impl Ppo {
    /// `epochs` passes of minibatch regression of the policy mean onto `demos` with the
    /// learner's optimizer at `learning_rate`; returns the last epoch's mean loss.
    pub fn imitate(&mut self, demos: &Demos, epochs: usize, learning_rate: f64) -> Result<f32> {
        self.imitate_with(demos, epochs, learning_rate, |_, _| true)
    }

    /// [`Self::imitate`], calling `on_epoch(epochs done, mean loss)` after each epoch; it
    /// stops early (with the loss so far) when `on_epoch` answers `false`.
    pub fn imitate_with(
        &mut self,
        demos: &Demos,
        epochs: usize,
        learning_rate: f64,
        mut on_epoch: impl FnMut(usize, f32) -> bool,
    ) -> Result<f32> {
        let n = demos.len();
        let width = self.net.layout().actions;
        if demos.stages.len() != n || demos.actions.len() != n || demos.masks.len() != n {
            return Err(Error::Length {
                what: "demonstration columns",
                expected: n,
                got: demos
                    .actions
                    .len()
                    .min(demos.masks.len())
                    .min(demos.stages.len()),
            });
        }
        let device = self.net.device().clone();
        if self.config.norm_obs {
            // The policy sees normalized inputs: the demonstrations set the statistics.
            self.net.update_norm(&demos.states, &demos.stages);
        }
        let saved_rate = self.optimizer_mut().learning_rate;
        self.optimizer_mut().learning_rate = learning_rate;
        let mut last = 0.0;
        for epoch in 0..epochs {
            let order = self.noise_mut().shuffle(n);
            let (mut total, mut batches) = (0.0f32, 0usize);
            for chunk in order.chunks(self.config.minibatch_size.max(1)) {
                let rows = |v: &Vec<Vec<f32>>| -> Result<Tensor> {
                    let flat: Vec<f32> = chunk.iter().flat_map(|&i| v[i].iter().copied()).collect();
                    Ok(Tensor::from_vec(flat, (chunk.len(), width), &device)?)
                };
                let states: Vec<Vec<f32>> =
                    chunk.iter().map(|&i| demos.states[i].clone()).collect();
                let stages: Vec<usize> = chunk.iter().map(|&i| demos.stages[i]).collect();
                let (targets, masks) = (rows(&demos.actions)?, rows(&demos.masks)?);
                let mean = self.net.mean(&self.net.input(&states, &stages)?)?;
                let live = masks.sum_all()?.to_scalar::<f32>()?.max(1.0);
                let loss = (((mean - targets)?.sqr()? * masks)?.sum_all()? / f64::from(live))?;
                let grads = loss.backward()?;
                let max_norm = self.config.max_grad_norm as f32;
                let params = self.net.params().to_vec();
                self.optimizer_mut().step(&params, &grads, max_norm)?;
                total += loss.to_scalar::<f32>()?;
                batches += 1;
            }
            last = total / batches.max(1) as f32;
            if !on_epoch(epoch + 1, last) {
                break;
            }
        }
        self.optimizer_mut().learning_rate = saved_rate;
        Ok(last)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::Layout;

    #[test]
    fn cloning_fits_the_live_dimensions_and_leaves_masked_ones() {
        let layout = Layout {
            stages: 2,
            state_width: 2,
            actions: 2,
        };
        let mut ppo = Ppo::new(layout, crm_api::PpoConfig::default(), 3).expect("ppo");
        // Stage 0 pushes dimension 0 to +0.8 where the state's first value is positive, -0.8
        // where it is negative; dimension 1 is masked (its target is nonsense).
        let mut demos = Demos::default();
        for k in 0..256 {
            let x = if k % 2 == 0 { 1.0 } else { -1.0 };
            demos.states.push(vec![x, 0.5]);
            demos.stages.push(0);
            demos.actions.push(vec![0.8 * x, 99.0]);
            demos.masks.push(vec![1.0, 0.0]);
        }
        let before = ppo.imitate(&demos, 1, 1e-3).expect("imitate");
        let after = ppo.imitate(&demos, 60, 1e-3).expect("imitate");
        assert!(after < before * 0.05, "{before} -> {after}");
        let input = ppo
            .net
            .input(&[vec![1.0, 0.5], vec![-1.0, 0.5]], &[0, 0])
            .expect("input");
        let mean: Vec<Vec<f32>> = ppo.net.mean(&input).expect("mean").to_vec2().expect("rows");
        assert!(
            (mean[0][0] - 0.8).abs() < 0.1 && (mean[1][0] + 0.8).abs() < 0.1,
            "{mean:?}"
        );
        // The masked dimension was never pulled towards 99.
        assert!(mean[0][1].abs() < 5.0, "{mean:?}");
    }
}
