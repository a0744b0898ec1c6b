//! Generalized advantage estimation with the CRM's transition reward inside the TD error
//! (paper, section III-B): `A_t = r_t + gamma V(u'_{t+1}) + R_T^{i->j} - V(u'_t)`, extended
//! to GAE(lambda) as PPO uses it.

use crate::error::{Error, Result};

/// One step of a trajectory, as the advantage needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepRecord {
    /// Intra-stage reward `r^(i)(u'_t, a_t)` (after the reward mode).
    pub intra: f32,
    /// Transition reward `R_T^{i->j}` (zero when no edge fired; after the reward mode).
    pub transition: f32,
    /// `V(u'_t)`, the value of the abstract state the action was taken in.
    pub value: f32,
    /// `V(u'_{t+1})`, the value of the next abstract state in the next stage.
    pub next_value: f32,
    /// The next stage is terminal: no value after it.
    pub terminal: bool,
    /// The trajectory ends after this step (terminal or truncated): no advantage flows back
    /// across it.
    pub last: bool,
}

/// Advantages and returns (`advantage + value`, the value target), in step order.
pub fn gae(steps: &[StepRecord], gamma: f32, lambda: f32) -> (Vec<f32>, Vec<f32>) {
    let mut advantages = vec![0.0; steps.len()];
    let mut running = 0.0f32;
    for (t, step) in steps.iter().enumerate().rev() {
        let bootstrap = if step.terminal {
            0.0
        } else {
            gamma * step.next_value
        };
        let delta = step.intra + step.transition + bootstrap - step.value;
        let carry = if step.last {
            0.0
        } else {
            gamma * lambda * running
        };
        running = delta + carry;
        advantages[t] = running;
    }
    let returns = advantages
        .iter()
        .zip(steps)
        .map(|(a, s)| a + s.value)
        .collect();
    (advantages, returns)
}

/// Normalizes advantages to zero mean and unit standard deviation (per minibatch in PPO).
pub fn normalize(values: &mut [f32]) -> Result<()> {
    if values.is_empty() {
        return Err(Error::Length {
            what: "advantages",
            expected: 1,
            got: 0,
        });
    }
    let n = values.len() as f32;
    let mean = values.iter().sum::<f32>() / n;
    let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / n;
    let std = var.sqrt() + 1e-8;
    for v in values.iter_mut() {
        *v = (*v - mean) / std;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(
        intra: f32,
        transition: f32,
        value: f32,
        next_value: f32,
        terminal: bool,
        last: bool,
    ) -> StepRecord {
        StepRecord {
            intra,
            transition,
            value,
            next_value,
            terminal,
            last,
        }
    }

    /// A three-step episode: approach, the `arrive` edge (+10), then success (+100, terminal).
    /// With gamma = 0.9 and lambda = 0.5:
    ///   delta_2 = -1 + 100 + 0          - 4 =  95
    ///   delta_1 = -1 +   0 + 0.9 * 4    - 3 = -0.4
    ///   delta_0 = -2 +  10 + 0.9 * 3    - 1 =  9.7
    ///   A_2 = 95
    ///   A_1 = -0.4 + 0.45 * 95    = 42.35
    ///   A_0 =  9.7 + 0.45 * 42.35 = 28.7575
    #[test]
    fn the_transition_reward_enters_the_td_error() {
        let steps = [
            step(-2.0, 10.0, 1.0, 3.0, false, false),
            step(-1.0, 0.0, 3.0, 4.0, false, false),
            step(-1.0, 100.0, 4.0, 7.0, true, true),
        ];
        let (advantages, returns) = gae(&steps, 0.9, 0.5);
        let expected = [28.7575, 42.35, 95.0];
        for (got, want) in advantages.iter().zip(expected) {
            assert!((got - want).abs() < 1e-4, "{advantages:?}");
        }
        assert!((returns[0] - 29.7575).abs() < 1e-4);
        assert!((returns[2] - 99.0).abs() < 1e-4);
    }

    #[test]
    fn lambda_one_gives_discounted_returns_and_episodes_do_not_leak() {
        // Two one-step episodes: the second must not flow into the first.
        let steps = [
            step(1.0, 2.0, 0.0, 5.0, true, true),
            step(0.5, 0.0, 0.0, 1.0, false, true),
        ];
        let (advantages, _) = gae(&steps, 0.99, 1.0);
        assert_eq!(advantages[0], 3.0);
        // Truncated: bootstrap from the next value, no carry.
        assert!((advantages[1] - (0.5 + 0.99)).abs() < 1e-6);
    }

    #[test]
    fn gae_matches_a_plain_loop_over_discounted_td_errors() {
        let steps: Vec<StepRecord> = (0..12)
            .map(|t| {
                let t = t as f32;
                step(
                    (t * 0.7).sin(),
                    if t == 4.0 { 5.0 } else { 0.0 },
                    (t * 0.3).cos(),
                    ((t + 1.0) * 0.3).cos(),
                    false,
                    t == 11.0,
                )
            })
            .collect();
        let (gamma, lambda) = (0.99, 0.95);
        let (advantages, _) = gae(&steps, gamma, lambda);
        for t in 0..steps.len() {
            let mut expected = 0.0;
            for (k, s) in steps[t..].iter().enumerate() {
                let delta = s.intra + s.transition + gamma * s.next_value - s.value;
                expected += (gamma * lambda).powi(k as i32) * delta;
            }
            assert!((advantages[t] - expected).abs() < 1e-4, "t = {t}");
        }
    }

    #[test]
    fn normalized_advantages_have_zero_mean_and_unit_spread() {
        let mut values = vec![1.0, 2.0, 3.0, 4.0];
        normalize(&mut values).expect("non-empty");
        let mean: f32 = values.iter().sum::<f32>() / 4.0;
        assert!(mean.abs() < 1e-6);
        let var: f32 = values.iter().map(|v| v * v).sum::<f32>() / 4.0;
        assert!((var - 1.0).abs() < 1e-4);
        assert!(normalize(&mut []).is_err());
    }
}
