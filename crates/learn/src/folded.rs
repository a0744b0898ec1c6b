//! The deterministic action of a dimension the environment folds: the scripted protocol's fingers
//! only close, by `|a|` of the policy's clipped action (the authors' `Dualenv.py`;
//! `docs/LEARNING.md`). A Gaussian policy trained there closes its fingers with the noise as much
//! as with the mean: a mean of 0 with a standard deviation of 0.6 closes a finger by 0.45 a step on
//! average. Taking the mean as the deterministic action would close it by nothing, so for a folded
//! dimension the deterministic action is what the sampled one does on average, `E[|clip(a, -1,
//! 1)|]` for `a ~ N(mean, std^2)` (`docs/LEARNING.md`, "The deterministic action", has what it
//! changes for the shipped model).

/// Simpson's rule over the standard normal's `[-8, 8]` in this many intervals (even).
const INTERVALS: usize = 512;
const HALF_WIDTH: f64 = 8.0;

/// `E[|clip(a, -1, 1)|]` for `a ~ N(mean, std^2)`: the step a folded dimension takes on
/// average when sampled. With `std` at 0 it is `|clip(mean, -1, 1)|`.
pub fn folded_mean(mean: f32, std: f32) -> f32 {
    let (mean, std) = (f64::from(mean), f64::from(std.max(0.0)));
    let folded = |z: f64| (mean + std * z).clamp(-1.0, 1.0).abs();
    if std == 0.0 {
        return folded(0.0) as f32;
    }
    let h = 2.0 * HALF_WIDTH / INTERVALS as f64;
    let mut sum = 0.0;
    for k in 0..=INTERVALS {
        let z = -HALF_WIDTH + h * k as f64;
        let weight = match k {
            0 => 1.0,
            k if k == INTERVALS => 1.0,
            k if k % 2 == 1 => 4.0,
            _ => 2.0,
        };
        sum += weight * folded(z) * (-0.5 * z * z).exp();
    }
    (sum * h / 3.0 / (2.0 * std::f64::consts::PI).sqrt()) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Noise;

    #[test]
    fn without_noise_it_is_the_clipped_magnitude() {
        assert_eq!(folded_mean(-0.3, 0.0), 0.3);
        assert_eq!(folded_mean(1.7, 0.0), 1.0);
    }

    #[test]
    fn at_a_zero_mean_it_is_the_half_normal_mean() {
        // E|a| = std * sqrt(2 / pi) while the clip at 1 is rarely reached.
        let std = 0.1f32;
        let expected = std * (2.0 / std::f32::consts::PI).sqrt();
        assert!((folded_mean(0.0, std) - expected).abs() < 1e-5);
        assert!(
            (folded_mean(0.0, 0.6) - 0.6 * 0.797_884_6).abs() > 0.01,
            "the clip counts"
        );
    }

    #[test]
    fn it_agrees_with_sampling() {
        let mut noise = Noise::new(7);
        for &(mean, std) in &[(0.0f32, 0.6f32), (0.4, 0.5), (-0.8, 0.3), (1.2, 0.9)] {
            let n = 200_000;
            let sampled: f64 = (0..n)
                .map(|_| f64::from((mean + std * noise.normal()).clamp(-1.0, 1.0).abs()))
                .sum::<f64>()
                / n as f64;
            let exact = f64::from(folded_mean(mean, std));
            assert!(
                (sampled - exact).abs() < 3e-3,
                "mean {mean} std {std}: sampled {sampled}, folded_mean {exact}"
            );
        }
    }
}
