//! PPO configuration with the paper's defaults (section V-B-2) and CleanRL's names.
//!
//! Every real-valued setting is an `f64`, as JSON gives it, so a bound is checked on the
//! value sent (`1.0000000000000002` is not a `gamma` of 1, as an `f32` would read it); the
//! learners compute in `f32` and convert where they read a setting.

/// A configuration value out of its domain; names the field.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("invalid config field {field}: {message}")]
pub struct ConfigError {
    pub field: &'static str,
    pub message: String,
}

use serde::{Deserialize, Serialize};

/// Knobs of PPO with the CRM (paper, section III-B).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PpoConfig {
    /// Initial learning rate. Paper V-B-2: 3e-5.
    pub learning_rate: f64,
    /// Discount. Paper V-B-2: 0.99.
    pub gamma: f64,
    /// GAE lambda. Paper V-B-2: 0.95.
    pub gae_lambda: f64,
    /// Minibatch size. Paper V-B-2: "a batch size of 64".
    pub minibatch_size: usize,
    /// Surrogate clip range epsilon. Not given in the paper; 0.2, stable-baselines3's default,
    /// which the authors' code used.
    pub clip_coef: f64,
    /// Entropy bonus coefficient. Not given in the paper; 0.0, stable-baselines3's default.
    pub ent_coef: f64,
    /// Value loss coefficient. Not given in the paper; 0.5, stable-baselines3's default.
    pub vf_coef: f64,
    /// Gradient norm clip, applied to the actor's and the critic's gradients separately (so
    /// the value loss cannot shrink the policy's step). Not given in the paper; 0.5,
    /// stable-baselines3's and CleanRL's value.
    pub max_grad_norm: f64,
    /// Passes over each rollout. Not given in the paper; 10, stable-baselines3's default.
    pub update_epochs: usize,
    /// Environment steps per rollout (over all environments). stable-baselines3's 2048.
    pub rollout_steps: usize,
    /// Hidden layer widths of the policy and value networks.
    pub hidden: Vec<usize>,
    /// Early stop when the last `early_stop_window` episodes succeed at this rate or more.
    /// Paper V-B-2: 99% over the most recent 100 episodes.
    pub early_stop_success: f64,
    pub early_stop_window: usize,
    /// KL guard: an update stops its epochs at the first minibatch whose approximate KL
    /// exceeds 1.5 x this (stable-baselines3's `target_kl` rule); 0 turns it off. 0.02, our
    /// value (SB3 leaves the guard off by default).
    pub target_kl: f64,
    /// Every log standard deviation of the policy at the run's start, the one noise knob:
    /// absent, fresh weights start at [`DEFAULT_LOG_STD`] and a fine-tune keeps the
    /// checkpoint's own; a resumed run always keeps its own. PPO learns it on from there. A
    /// narrower noise on a fine-tune keeps sampled actions on grasps that the learned noise
    /// breaks (docs/notebook/worlds.md, "Sampled actions").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub init_log_std: Option<f64>,
    /// Running observation normalization (SB3 `VecNormalize`, which the authors used).
    pub norm_obs: bool,
    /// Reward scaling by the running std of the discounted return (SB3 `VecNormalize`), one
    /// factor for both reward parts.
    pub norm_reward: bool,
    /// How the learning rate falls over the run's steps: the paper's steps (default),
    /// CleanRL's linear anneal, or constant (Stable-Baselines3's default).
    pub lr_schedule: LrSchedule,
}

/// The learning rate's course over a run (see [`PpoConfig::learning_rate_at`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LrSchedule {
    /// The paper's steps: 100% for the first 40% of the steps, 90% until 70%, 80% after
    /// (section V-B-2).
    #[default]
    Paper,
    /// Linear to zero at the run's last step: CleanRL's `anneal_lr` (its default for PPO).
    Linear,
    /// The same rate throughout: Stable-Baselines3's default (a float `learning_rate`).
    Constant,
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            learning_rate: 3e-5,
            gamma: 0.99,
            gae_lambda: 0.95,
            minibatch_size: 64,
            clip_coef: 0.2,
            ent_coef: 0.0,
            vf_coef: 0.5,
            max_grad_norm: 0.5,
            update_epochs: 10,
            rollout_steps: 2048,
            hidden: vec![256, 256],
            early_stop_success: 0.99,
            early_stop_window: 100,
            target_kl: 0.02,
            init_log_std: None,
            norm_obs: true,
            norm_reward: true,
            lr_schedule: LrSchedule::Paper,
        }
    }
}

impl PpoConfig {
    /// The learning rate at a point of training (`progress` in `[0, 1]`, the share of the
    /// run's steps done once the rollout being learned from was collected), per
    /// [`LrSchedule`]: the paper's 100% for the first 40%, 90% until 70%, and 80% for the rest
    /// (section V-B-2); or `1 - progress` of it (CleanRL's `anneal_lr`, which computes its
    /// fraction before the rollout, so its last update keeps `1 / iterations` where ours
    /// takes none); or all of it.
    pub fn learning_rate_at(&self, progress: f64) -> f64 {
        let factor = match self.lr_schedule {
            LrSchedule::Paper if progress < 0.4 => 1.0,
            LrSchedule::Paper if progress < 0.7 => 0.9,
            LrSchedule::Paper => 0.8,
            LrSchedule::Linear => (1.0 - progress).clamp(0.0, 1.0),
            LrSchedule::Constant => 1.0,
        };
        self.learning_rate * factor
    }

    /// Refuses values out of their domain, naming the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_common(&Common {
            learning_rate: self.learning_rate,
            gamma: self.gamma,
            hidden: &self.hidden,
            early_stop_success: self.early_stop_success,
            early_stop_window: self.early_stop_window,
        })?;
        if !(0.0..=1.0).contains(&self.gae_lambda) {
            return bad("gae_lambda", "must be in [0, 1]");
        }
        within("minibatch_size", self.minibatch_size, 1, MAX_BATCH)?;
        if !(self.clip_coef > 0.0 && self.clip_coef < 1.0) {
            return bad("clip_coef", "must be in (0, 1)");
        }
        if !(self.ent_coef >= 0.0 && self.vf_coef >= 0.0) {
            return bad("ent_coef", "coefficients must be non-negative");
        }
        if self.max_grad_norm.is_nan() || self.max_grad_norm <= 0.0 {
            return bad("max_grad_norm", "must be positive");
        }
        if !(0.0..=1000.0).contains(&self.target_kl) {
            return bad("target_kl", "must be in [0, 1000] (0 turns the guard off)");
        }
        if self.init_log_std.is_some_and(|v| !in_log_std_range(v)) {
            let (low, high) = LOG_STD_RANGE;
            return bad("init_log_std", &format!("must be in [{low}, {high}]"));
        }
        within("update_epochs", self.update_epochs, 1, MAX_EPOCHS)?;
        within("rollout_steps", self.rollout_steps, 1, MAX_BATCH)
    }
}

/// Most rows in one batch: PPO's rollout and minibatch, SAC's batch and rollout (the bounds
/// keep a job's memory within a worker's; the paper's and anchors' values are far below).
pub const MAX_BATCH: usize = 1 << 20;
/// Most passes over one rollout.
pub const MAX_EPOCHS: usize = 1000;
/// Most hidden layers, and the widest one.
pub const MAX_LAYERS: usize = 8;
pub const MAX_WIDTH: usize = 4096;
/// Longest early-stop window, in episodes.
pub const MAX_WINDOW: usize = 10_000_000;
/// Largest SAC replay buffer, in transitions (SB3's default is 1,000,000).
pub const MAX_BUFFER: usize = 10_000_000;

/// A fresh policy's log standard deviation where `init_log_std` is absent: CleanRL's
/// continuous PPO and Stable-Baselines3's `log_std_init`, 0.
pub const DEFAULT_LOG_STD: f64 = 0.0;

/// Lowest and highest log standard deviation a policy may start a run with (`init_log_std`,
/// and a job's `start_log_std`, its older name).
pub const LOG_STD_RANGE: (f64, f64) = (-5.0, 2.0);

/// Whether `value` is a finite log standard deviation within [`LOG_STD_RANGE`].
pub fn in_log_std_range(value: f64) -> bool {
    let (low, high) = LOG_STD_RANGE;
    value.is_finite() && (low..=high).contains(&value)
}

/// `value` in `[min, max]`, or an error naming `field` and the range.
fn within(field: &'static str, value: usize, min: usize, max: usize) -> Result<(), ConfigError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        bad(field, &format!("must be between {min} and {max}"))
    }
}

fn bad(field: &'static str, message: &str) -> Result<(), ConfigError> {
    Err(ConfigError {
        field,
        message: message.to_string(),
    })
}

/// The settings PPO and SAC share, checked alike.
struct Common<'a> {
    learning_rate: f64,
    gamma: f64,
    hidden: &'a [usize],
    early_stop_success: f64,
    early_stop_window: usize,
}

fn check_common(c: &Common<'_>) -> Result<(), ConfigError> {
    if !(c.learning_rate.is_finite() && c.learning_rate > 0.0) {
        return bad("learning_rate", "must be positive");
    }
    if !(0.0..=1.0).contains(&c.gamma) {
        return bad("gamma", "must be in [0, 1]");
    }
    if c.hidden.is_empty()
        || c.hidden.len() > MAX_LAYERS
        || c.hidden.iter().any(|w| !(1..=MAX_WIDTH).contains(w))
    {
        return bad(
            "hidden",
            &format!("1 to {MAX_LAYERS} layers, each 1 to {MAX_WIDTH} wide"),
        );
    }
    if !(0.0..=1.0).contains(&c.early_stop_success) {
        return bad("early_stop_success", "must be in [0, 1]");
    }
    within("early_stop_window", c.early_stop_window, 1, MAX_WINDOW)
}

/// Knobs of SAC inside the CRM (the paper's CRM-SAC baseline, section V-A). The paper gives
/// no SAC settings; defaults are stable-baselines3's, which the authors' code used, except
/// where noted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SacConfig {
    /// Adam learning rate of the actor, the critics and the temperature. sb3: 3e-4.
    pub learning_rate: f64,
    /// Discount. Paper V-B-2 (as for PPO): 0.99.
    pub gamma: f64,
    /// Polyak factor of the target critics. sb3: 0.005.
    pub tau: f64,
    /// Minibatch size. sb3: 256.
    pub batch_size: usize,
    /// Replay buffer capacity in transitions. sb3: 1,000,000.
    pub buffer_size: usize,
    /// Uniformly random actions for this many steps before learning. sb3: 100; 1,000 here, as
    /// the grasping episodes are long.
    pub learning_starts: usize,
    /// Gradient steps per environment step. sb3: 1.
    pub updates_per_step: f64,
    /// Environment steps per iteration (between progress reports).
    pub rollout_steps: usize,
    /// Hidden layer widths of the actor and each critic. sb3: [256, 256].
    pub hidden: Vec<usize>,
    /// Target entropy per live action dimension (automatic temperature tuning). sb3: -1.
    pub target_entropy_per_dim: f64,
    /// Early stop as for PPO. Paper V-B-2: 99% over the most recent 100 episodes.
    pub early_stop_success: f64,
    pub early_stop_window: usize,
    /// Running observation normalization per stage and feature, as for PPO (SB3
    /// `VecNormalize`, which the authors used; SB3's replay buffer stores raw observations
    /// and normalizes them with the current statistics when it samples, as here). On.
    pub norm_obs: bool,
}

impl Default for SacConfig {
    fn default() -> Self {
        Self {
            learning_rate: 3e-4,
            gamma: 0.99,
            tau: 0.005,
            batch_size: 256,
            buffer_size: 1_000_000,
            learning_starts: 1_000,
            updates_per_step: 1.0,
            rollout_steps: 1_024,
            hidden: vec![256, 256],
            target_entropy_per_dim: -1.0,
            early_stop_success: 0.99,
            early_stop_window: 100,
            norm_obs: true,
        }
    }
}

impl SacConfig {
    /// Refuses values out of their domain, naming the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_common(&Common {
            learning_rate: self.learning_rate,
            gamma: self.gamma,
            hidden: &self.hidden,
            early_stop_success: self.early_stop_success,
            early_stop_window: self.early_stop_window,
        })?;
        if !(self.tau > 0.0 && self.tau <= 1.0) {
            return bad("tau", "must be in (0, 1]");
        }
        // A batch larger than the buffer's content takes all of it (`Sac::update`).
        within("batch_size", self.batch_size, 1, MAX_BATCH)?;
        within("buffer_size", self.buffer_size, 1, MAX_BUFFER)?;
        if !(self.updates_per_step > 0.0 && self.updates_per_step <= 1000.0) {
            return bad("updates_per_step", "must be in (0, 1000]");
        }
        within("rollout_steps", self.rollout_steps, 1, MAX_BATCH)?;
        if !(-100.0..=100.0).contains(&self.target_entropy_per_dim) {
            return bad("target_entropy_per_dim", "must be in [-100, 100]");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_learning_rate_follows_the_papers_steps() {
        let config = PpoConfig::default();
        assert_eq!(config.learning_rate_at(0.0), 3e-5);
        assert_eq!(config.learning_rate_at(0.399), 3e-5);
        assert!((config.learning_rate_at(0.4) - 2.7e-5).abs() < 1e-12);
        assert!((config.learning_rate_at(0.69) - 2.7e-5).abs() < 1e-12);
        assert!((config.learning_rate_at(0.7) - 2.4e-5).abs() < 1e-12);
        assert!((config.learning_rate_at(1.0) - 2.4e-5).abs() < 1e-12);
    }

    #[test]
    fn the_linear_schedule_anneals_to_zero_and_is_read_from_json() {
        let config: PpoConfig =
            serde_json::from_str(r#"{"learning_rate": 3e-4, "lr_schedule": "linear"}"#)
                .expect("a linear schedule parses");
        assert_eq!(config.lr_schedule, LrSchedule::Linear);
        assert_eq!(config.learning_rate_at(0.0), 3e-4);
        assert!((config.learning_rate_at(0.25) - 2.25e-4).abs() < 1e-12);
        assert_eq!(config.learning_rate_at(1.0), 0.0);
        let constant: PpoConfig =
            serde_json::from_str(r#"{"learning_rate": 3e-4, "lr_schedule": "constant"}"#)
                .expect("a constant schedule parses");
        assert_eq!(constant.learning_rate_at(0.99), 3e-4);
        let err = serde_json::from_str::<PpoConfig>(r#"{"lr_schedule": "cosine"}"#)
            .expect_err("an unknown schedule is refused")
            .to_string();
        assert!(err.contains("cosine"), "{err}");
    }

    #[test]
    fn invalid_configs_name_the_field() {
        let config = PpoConfig {
            gamma: 1.5,
            ..PpoConfig::default()
        };
        let err = config
            .validate()
            .expect_err("gamma out of range")
            .to_string();
        assert!(err.contains("gamma"), "{err}");
        assert!(PpoConfig::default().validate().is_ok());
        for (config, field) in [
            (
                SacConfig {
                    tau: 2.0,
                    ..SacConfig::default()
                },
                "tau",
            ),
            (
                SacConfig {
                    gamma: -0.1,
                    ..SacConfig::default()
                },
                "gamma",
            ),
            (
                SacConfig {
                    hidden: vec![],
                    ..SacConfig::default()
                },
                "hidden",
            ),
            (
                SacConfig {
                    batch_size: 0,
                    ..SacConfig::default()
                },
                "batch_size",
            ),
            (
                SacConfig {
                    hidden: vec![64; 9],
                    ..SacConfig::default()
                },
                "hidden",
            ),
            (
                SacConfig {
                    buffer_size: MAX_BUFFER + 1,
                    ..SacConfig::default()
                },
                "buffer_size",
            ),
        ] {
            assert_eq!(config.validate().expect_err(field).field, field);
        }
        assert!(SacConfig::default().validate().is_ok());
        // A batch larger than the buffer is fine: it takes the whole buffer.
        let small = SacConfig {
            buffer_size: 10,
            ..SacConfig::default()
        };
        assert!(small.validate().is_ok());
        let wide = PpoConfig {
            hidden: vec![MAX_WIDTH + 1],
            ..PpoConfig::default()
        };
        assert_eq!(wide.validate().expect_err("too wide").field, "hidden");
    }
}
