//! The losses at the networks' outputs and their gradients there: the masked diagonal
//! Gaussian's log-probability, PPO's clipped surrogate and the entropy bonus (the actor), and
//! the squared value error (the critic). The formulas are `network.rs`'s and `ppo.rs`'s; the
//! gradients are written out by hand (see each line), ties of the surrogate's minimum split
//! as candle's autograd splits them.

use super::mlp::Param;
use super::{Coefs, Minibatch};

/// `0.5 ln(2 pi)`.
const HALF_LOG_TWO_PI: f32 = 0.918_938_5;

/// The actor's part of a minibatch's loss.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PolicyLoss {
    /// `-mean(min(r A, clip(r) A))`.
    pub loss: f32,
    /// The mean entropy over the live dimensions.
    pub entropy: f32,
}

/// The surrogate's loss at `means` (`[rows, actions]`) with `log_std`: sets `d_mean` to the
/// loss's gradient at the means, `log_std.grad` to its gradient at the log std (the entropy
/// bonus included), and `log_ratio` to each row's `log pi - log pi_old`.
pub(crate) fn policy_head(
    means: &[f32],
    log_std: &mut Param,
    batch: Minibatch<'_>,
    coefs: Coefs,
    d_mean: &mut Vec<f32>,
    log_ratio: &mut Vec<f32>,
) -> PolicyLoss {
    let (rows, width) = (batch.rows, batch.action_width);
    let inv_rows = 1.0 / rows.max(1) as f32;
    let std: Vec<f32> = log_std.value.iter().map(|s| s.exp()).collect();
    d_mean.clear();
    d_mean.resize(rows * width, 0.0);
    log_ratio.clear();
    let d_log_std = &mut log_std.grad;
    d_log_std.fill(0.0);
    let (low, high) = (1.0 - coefs.clip, 1.0 + coefs.clip);
    let (mut loss, mut entropy) = (0.0f32, 0.0f32);
    for i in 0..rows {
        let span = i * width..(i + 1) * width;
        let (mean, action, mask) = (
            &means[span.clone()],
            &batch.actions[span.clone()],
            &batch.masks[span.clone()],
        );
        // log pi = sum_j m_j (-z_j^2 / 2 - s_j - ln(2 pi) / 2), z_j = (a_j - mu_j) / e^{s_j}.
        let mut log_prob = 0.0f32;
        for j in 0..width {
            let z = (action[j] - mean[j]) / std[j];
            log_prob += mask[j] * ((-0.5 * z * z - log_std.value[j]) - HALF_LOG_TWO_PI);
        }
        let lr = log_prob - batch.old_log_probs[i];
        log_ratio.push(lr);
        let ratio = lr.exp();
        let advantage = batch.advantages[i];
        let unclipped = ratio * advantage;
        let clipped = ratio.clamp(low, high) * advantage;
        loss += unclipped.min(clipped);
        // d min / d ratio: the smaller side's slope (the clipped side's is 0 outside the
        // range); a tie gives each side half, as candle's `minimum` does.
        let inside = if ratio > low && ratio < high {
            1.0
        } else {
            0.0
        };
        let slope = if unclipped < clipped {
            advantage
        } else if unclipped > clipped {
            advantage * inside
        } else {
            0.5 * advantage * (1.0 + inside)
        };
        // d loss / d log pi = -(1 / rows) slope ratio.
        let g = -inv_rows * slope * ratio;
        let d_row = &mut d_mean[span];
        for j in 0..width {
            let z = (action[j] - mean[j]) / std[j];
            // d log pi / d mu_j = m_j z_j / sigma_j; d log pi / d s_j = m_j (z_j^2 - 1).
            d_row[j] = g * mask[j] * z / std[j];
            d_log_std[j] += g * mask[j] * (z * z - 1.0);
            // The entropy, sum_j m_j (s_j + (1 + ln 2 pi) / 2), enters as -ent_coef * mean.
            entropy += mask[j] * (log_std.value[j] + 0.5 + HALF_LOG_TWO_PI);
            d_log_std[j] -= coefs.ent * inv_rows * mask[j];
        }
    }
    PolicyLoss {
        loss: -loss * inv_rows,
        entropy: entropy * inv_rows,
    }
}

/// The value loss `mean((v - R)^2)` at `values` (`[rows, 1]`); sets `d_value` to the
/// gradient of `vf_coef` times it.
pub(crate) fn value_head(
    values: &[f32],
    batch: Minibatch<'_>,
    vf_coef: f32,
    d_value: &mut Vec<f32>,
) -> f32 {
    let inv_rows = 1.0 / batch.rows.max(1) as f32;
    d_value.clear();
    let mut loss = 0.0f32;
    for (&v, &r) in values.iter().zip(batch.returns) {
        let diff = v - r;
        loss += diff * diff;
        d_value.push(vf_coef * 2.0 * diff * inv_rows);
    }
    loss * inv_rows
}
