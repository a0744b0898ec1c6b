//! A short, seeded PPO run on an easy task learns: the success rate of the trained policy
//! beats the untrained one. The task is a one-dimensional reach through a two-stage machine,
//! so the test runs in a second and exercises the learner end to end through `crm::CrmEnv`.

use crm_api::SacConfig;
use crm_learn::{Actor, Layout, Ppo, PpoConfig, Sac, VecEnv};

const SPEC: &str = r#"{
  "name": "reach",
  "features": ["x", "dist"],
  "action_dims": ["dx"],
  "events": ["arrive"],
  "initial": "approach",
  "stages": [
    {"name": "approach", "actions": [{"dim": "dx", "scale": 0.1}], "abstraction": ["x", "dist"],
     "reward": [{"kind": "neg_exp_norm", "features": ["dist"], "coef": 0.1}]},
    {"name": "success", "terminal": true}
  ],
  "transitions": [{"from": "approach", "event": "arrive", "to": "success", "reward": 10.0}]
}"#;

const GOAL: f32 = 0.5;

struct Reach {
    x: f32,
    steps: usize,
}

impl Reach {
    fn observation(&self) -> Vec<f32> {
        vec![self.x, (self.x - GOAL).abs()]
    }
}

impl crm::Environment for Reach {
    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
        self.x = -1.0 + 0.5 * ((seed % 97) as f32 / 97.0);
        self.steps = 0;
        Ok(self.observation())
    }

    fn set_stage(&mut self, _stage: &str) {}

    fn step(&mut self, action: &[f32]) -> Result<crm::EnvStep, String> {
        self.x = (self.x + action[0]).clamp(-1.5, 1.5);
        self.steps += 1;
        let arrived = (self.x - GOAL).abs() < 0.1;
        Ok(crm::EnvStep {
            observation: self.observation(),
            events: if arrived { vec!["arrive"] } else { vec![] },
            truncated: self.steps >= 25,
        })
    }
}

fn env() -> crm::CrmEnv<Reach> {
    let spec = crm::Spec::from_json(SPEC, "reach").expect("spec");
    let machine = crm::Machine::from_spec(spec).expect("machine");
    crm::CrmEnv::new(machine, Reach { x: 0.0, steps: 0 }, crm::RewardMode::Crm)
}

fn success_rate(ppo: &mut impl Actor, episodes: u64) -> f64 {
    let mut env = env();
    let mut wins = 0;
    for seed in 0..episodes {
        let (mut stage, mut state) = env.reset(10_000 + seed).expect("reset");
        loop {
            let mask = env.machine().action_mask(stage);
            let (mut actions, _) = ppo
                .act_batch(&[state.clone()], &[stage], &[mask], true)
                .expect("act");
            let action = actions.pop().expect("one action");
            let step = env.step(&action).expect("step");
            if step.done {
                wins += 1;
                break;
            }
            if step.truncated {
                break;
            }
            (stage, state) = (step.stage, step.abstract_state);
        }
    }
    f64::from(wins) / episodes as f64
}

#[test]
fn a_short_seeded_run_on_an_easy_task_beats_the_untrained_policy() {
    let layout = Layout::of(env().machine());
    let config = PpoConfig {
        learning_rate: 3e-3,
        rollout_steps: 512,
        update_epochs: 4,
        hidden: vec![32],
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(layout, config, 1).expect("ppo");
    let before = success_rate(&mut ppo, 20);
    let mut envs = VecEnv::new((0..4).map(|_| env()).collect(), 1).expect("envs");
    let updates = 15;
    for k in 0..updates {
        let rollout = envs.collect(&mut ppo, 128).expect("rollout");
        assert_eq!(rollout.len(), 512);
        let stats = ppo
            .update(&rollout, k as f64 / updates as f64)
            .expect("update");
        assert!(stats.policy_loss.is_finite() && stats.value_loss.is_finite());
    }
    let after = success_rate(&mut ppo, 20);
    eprintln!("success rate before training {before}, after {after}");
    assert!(
        after >= before + 0.5,
        "success before {before}, after {after}"
    );
}

/// The same seed gives the same rollout and update bit for bit, whatever the thread count.
#[test]
fn rollouts_and_updates_are_bitwise_reproducible_across_thread_counts() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let layout = Layout::of(env().machine());
            let config = PpoConfig {
                learning_rate: 1e-3,
                rollout_steps: 128,
                update_epochs: 2,
                hidden: vec![16],
                ..PpoConfig::default()
            };
            let mut ppo = Ppo::new(layout, config, 9).expect("ppo");
            let mut envs = VecEnv::new((0..3).map(|_| env()).collect(), 5).expect("envs");
            let rollout = envs.collect(&mut ppo, 40).expect("rollout");
            let stats = ppo.update(&rollout, 0.0).expect("update");
            let mut bits: Vec<u32> = rollout
                .actions
                .iter()
                .flatten()
                .map(|v| v.to_bits())
                .collect();
            bits.extend(rollout.intra.iter().map(|v| v.to_bits()));
            bits.push(stats.policy_loss.to_bits());
            bits.push(stats.value_loss.to_bits());
            bits
        })
    };
    let one = run(1);
    assert_eq!(one, run(3));
    assert_eq!(one, run(1));
}

/// An ended episode carries its own intra-stage and transition returns, and nothing of the
/// episode still running when the rollout stops (per-episode means in the training log are
/// over ended episodes only).
#[test]
fn episodes_carry_their_own_reward_split() {
    let layout = Layout::of(env().machine());
    let config = PpoConfig {
        hidden: vec![8],
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(layout, config, 3).expect("ppo");
    let mut envs = VecEnv::new(vec![env()], 7).expect("envs");
    // 25-step episodes at most: 60 steps end at least two and leave one running.
    let rollout = envs.collect(&mut ppo, 60).expect("rollout");
    let (mut intra, mut transition) = (0.0f32, 0.0f32);
    let mut ended = Vec::new();
    for k in 0..rollout.len() {
        intra += rollout.intra[k];
        transition += rollout.transition[k];
        if rollout.ended[k] {
            ended.push((intra, transition));
            (intra, transition) = (0.0, 0.0);
        }
    }
    assert!(ended.len() >= 2 && !rollout.ended[rollout.len() - 1]);
    assert_ne!(
        intra, 0.0,
        "the running episode has rewards the ended ones must not carry"
    );
    assert_eq!(rollout.episodes.len(), ended.len());
    for (episode, (intra, transition)) in rollout.episodes.iter().zip(&ended) {
        assert_eq!(episode.intra_return, *intra);
        assert_eq!(episode.transition_return, *transition);
        assert_eq!(episode.total_return, intra + transition);
    }
}

#[test]
fn a_short_seeded_sac_run_on_an_easy_task_beats_the_untrained_policy() {
    let machine = env().machine().clone();
    let layout = Layout::of(&machine);
    let masks = (0..machine.stage_count())
        .map(|s| machine.action_mask(s))
        .collect();
    let config = SacConfig {
        batch_size: 64,
        learning_starts: 256,
        hidden: vec![32, 32],
        learning_rate: 1e-3,
        ..SacConfig::default()
    };
    let mut sac = Sac::new(layout, config, masks, 2).expect("sac");
    let before = success_rate(&mut sac, 20);
    let mut envs = VecEnv::new((0..4).map(|_| env()).collect(), 2).expect("envs");
    for _ in 0..12 {
        let rollout = envs.collect(&mut sac, 32).expect("rollout");
        sac.store(&rollout);
        let stats = sac.update(rollout.len()).expect("update");
        assert!(stats.critic_loss.is_finite() && stats.actor_loss.is_finite());
        assert!(stats.alpha > 0.0);
    }
    assert_eq!(sac.seen(), 12 * 128);
    let after = success_rate(&mut sac, 20);
    eprintln!("SAC success rate before training {before}, after {after}");
    assert!(
        after >= before + 0.5,
        "success before {before}, after {after}"
    );
}

#[test]
fn the_deterministic_action_folds_only_the_folded_dimensions() {
    let layout = Layout::of(env().machine());
    let config = PpoConfig {
        hidden: vec![16, 16],
        init_log_std: Some(-0.5),
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(layout, config, 4).expect("ppo");
    let (state, stage, mask) = (vec![-0.3, 0.8], 0, vec![1.0]);
    let (mean, _) = ppo.act(&state, stage, &mask, true).expect("act");
    let plain = ppo.act_folded(&state, stage, &mask, &[false]).expect("act");
    assert_eq!(plain, mean, "nothing folded: the Gaussian's mean");
    let folded = ppo.act_folded(&state, stage, &mask, &[true]).expect("act");
    let std = ppo.net.std().expect("std")[0];
    assert_eq!(folded, vec![crm_learn::folded::folded_mean(mean[0], std)]);
    assert!(
        folded[0] > mean[0].abs(),
        "the noise closes too: {folded:?} {mean:?}"
    );
    let masked = ppo.act_folded(&state, stage, &[0.0], &[true]).expect("act");
    assert_eq!(masked, vec![0.0], "outside the stage's action set");
}
