//! The fused update against candle's autograd: losses and every gradient on random
//! minibatches, and a whole update's parameters.

use candle_core::Tensor;

use super::{Coefs, Columns, Engine};
use crate::network::{ActorCritic, Layout};
use crate::noise::Noise;
use crate::optim::Adam;
use crate::ppo::{Ppo, UpdateEngine, candle_loss};
use crate::rollout::Rollout;
use crm_api::PpoConfig;

/// The paper's grasping layout: 38 state features, 5 stages, 8 actions.
const LAYOUT: Layout = Layout {
    state_width: 38,
    stages: 5,
    actions: 8,
};

/// A stage's action mask: stage `s` uses the first `3 + s` dimensions.
fn mask(stage: usize) -> Vec<f32> {
    (0..LAYOUT.actions)
        .map(|j| if j < 3 + stage { 1.0 } else { 0.0 })
        .collect()
}

/// `n` random steps of a rollout under `net`'s policy; old log-probabilities are the
/// policy's own plus noise, so some ratios fall outside the clip range.
fn rollout(net: &ActorCritic, n: usize, seed: u64) -> Rollout {
    let mut noise = Noise::new(seed);
    let mut r = Rollout::default();
    for t in 0..n {
        let stage = (noise.next_u64() % LAYOUT.stages as u64) as usize;
        let len = LAYOUT.state_width - (noise.next_u64() % 4) as usize;
        let state: Vec<f32> = (0..len).map(|_| 2.0 * noise.normal()).collect();
        let next: Vec<f32> = state.iter().map(|x| x + 0.1 * noise.normal()).collect();
        r.states.push(state);
        r.stages.push(stage);
        r.next_states.push(next);
        r.next_stages.push(stage);
        r.masks.push(mask(stage));
        r.intra.push(0.1 * noise.normal());
        r.transition.push(if t % 17 == 0 { 1.0 } else { 0.0 });
        let end = t % 40 == 39;
        r.terminal.push(end);
        r.last.push(end || t + 1 == n);
        r.ended.push(end);
        r.env.push(0);
    }
    let input = net.input(&r.states, &r.stages).expect("input");
    let means: Vec<Vec<f32>> = net.mean(&input).expect("mean").to_vec2().expect("read");
    for mean in &means {
        r.actions
            .push(mean.iter().map(|m| m + 0.6 * noise.normal()).collect());
    }
    let log_probs = net
        .log_prob(
            &net.mean(&input).expect("mean"),
            &Tensor::from_vec(r.actions.concat(), (n, LAYOUT.actions), net.device()).expect("t"),
            &Tensor::from_vec(r.masks.concat(), (n, LAYOUT.actions), net.device()).expect("t"),
        )
        .expect("log prob")
        .to_vec1::<f32>()
        .expect("read");
    r.log_probs = log_probs
        .iter()
        .map(|lp| lp + 0.15 * noise.normal())
        .collect();
    r
}

fn net(seed: u64) -> ActorCritic {
    let net = ActorCritic::new(LAYOUT, &[256, 256], seed).expect("net");
    net.set_log_std(-0.5).expect("log std");
    net
}

/// `|a - b|_inf`.
fn max_difference(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()))
}

/// `|a - b|_inf / |b|_inf`.
fn relative(a: &[f32], b: &[f32]) -> f32 {
    let scale = b.iter().fold(0.0f32, |m, x| m.max(x.abs())).max(1e-12);
    max_difference(a, b) / scale
}

/// Two learners of `config` from the same seed, one per update engine: `(fused, candle)`.
fn engines(config: &PpoConfig) -> (Ppo, Ppo) {
    let make = |engine| {
        let mut ppo = Ppo::new(LAYOUT, config.clone(), 5).expect("ppo");
        ppo.set_engine(engine);
        ppo
    };
    (make(UpdateEngine::Fused), make(UpdateEngine::Candle))
}

#[test]
fn losses_and_every_gradient_match_candles_autograd() {
    let config = PpoConfig {
        ent_coef: 0.01,
        ..PpoConfig::default()
    };
    let coefs = Coefs {
        clip: config.clip_coef as f32,
        ent: config.ent_coef as f32,
        vf: config.vf_coef as f32,
        max_grad_norm: config.max_grad_norm as f32,
    };
    for (seed, rows) in [(1u64, 64usize), (2, 512), (3, 7)] {
        let net = net(seed);
        let r = rollout(&net, rows, seed + 100);
        let mut noise = Noise::new(seed + 200);
        let advantages: Vec<f32> = (0..rows).map(|_| noise.normal()).collect();
        let returns: Vec<f32> = (0..rows).map(|_| noise.normal()).collect();
        let input = net.input(&r.states, &r.stages).expect("input");
        let device = net.device();
        let columns = Columns {
            inputs: input.flatten_all().expect("f").to_vec1().expect("read"),
            actions: r.actions.concat(),
            masks: r.masks.concat(),
            old_log_probs: r.log_probs.clone(),
            advantages: advantages.clone(),
            returns: returns.clone(),
            width: LAYOUT.input_width(),
            action_width: LAYOUT.actions,
        };
        let batch = [
            input,
            Tensor::from_vec(r.actions.concat(), (rows, LAYOUT.actions), device).expect("t"),
            Tensor::from_vec(r.masks.concat(), (rows, LAYOUT.actions), device).expect("t"),
            Tensor::from_vec(r.log_probs.clone(), rows, device).expect("t"),
            Tensor::from_vec(advantages, rows, device).expect("t"),
            Tensor::from_vec(returns, rows, device).expect("t"),
        ];
        let reference = candle_loss(&net, &config, &batch).expect("loss");
        let grads = reference.loss.backward().expect("backward");

        let mut adam = Adam::new(net.params(), 1e-3);
        let mut engine = Engine::load(&net, &mut adam).expect("load");
        let (losses, fused) = engine.gradients(columns.slice(0, rows), coefs);
        let scalar = |t: &Tensor| t.to_scalar::<f32>().expect("scalar");
        let want = [
            scalar(&reference.policy_loss),
            scalar(&reference.value_loss),
            scalar(&reference.entropy),
        ];
        for (name, (got, want)) in ["policy", "value", "entropy"]
            .iter()
            .zip(losses.iter().zip(want))
        {
            assert!(
                (got - want).abs() <= 1e-4 * want.abs().max(1e-3),
                "{rows} rows: {name} loss {got} vs candle's {want}"
            );
        }
        // Some ratios are clipped, some not: both branches of the surrogate are exercised.
        let log_ratio: Vec<f32> = reference.log_ratio.to_vec1().expect("read");
        let clipped = log_ratio
            .iter()
            .filter(|l| (l.exp() - 1.0).abs() > 0.2)
            .count();
        if rows >= 64 {
            assert!(clipped > 0 && clipped < rows, "{clipped} of {rows} clipped");
        }
        let params = net.params();
        let order = params
            .iter()
            .filter(|(n, _)| n.starts_with("actor.") && n != "actor.log_std")
            .chain(params.iter().filter(|(n, _)| n.starts_with("critic.")))
            .chain(params.iter().filter(|(n, _)| n == "actor.log_std"));
        let mut checked = 0;
        for ((name, var), got) in order.zip(&fused) {
            let want: Vec<f32> = grads
                .get(var.as_tensor())
                .expect("candle gradient")
                .flatten_all()
                .expect("f")
                .to_vec1()
                .expect("read");
            let error = relative(got, &want);
            assert!(error < 1e-4, "{rows} rows: {name}: relative error {error}");
            checked += 1;
        }
        assert_eq!(checked, params.len());
    }
}

#[test]
fn one_update_gives_the_reference_paths_parameters() {
    for minibatch in [64usize, 512] {
        let config = PpoConfig {
            minibatch_size: minibatch,
            update_epochs: 4,
            ent_coef: 0.01,
            learning_rate: 3e-4,
            ..PpoConfig::default()
        };
        let (mut fused, mut candle) = engines(&config);
        let r = rollout(&fused.net, 1024, 9);
        let a = fused.update(&r, 0.0).expect("fused update");
        let b = candle.update(&r, 0.0).expect("candle update");
        assert_eq!(a.minibatches, b.minibatches);
        assert!(
            (a.policy_loss - b.policy_loss).abs() < 1e-4,
            "{a:?} vs {b:?}"
        );
        assert!((a.value_loss - b.value_loss).abs() < 1e-4 * b.value_loss.abs().max(1.0));
        let (pa, pb) = (
            fused.net.flat_params().expect("params"),
            candle.net.flat_params().expect("params"),
        );
        let start = net(5).flat_params().expect("params");
        let (worst, moved) = (max_difference(&pa, &pb), max_difference(&pb, &start));
        assert!(
            worst < 1e-5,
            "minibatch {minibatch}: parameters differ by {worst}"
        );
        assert!(
            moved > 1e-3,
            "the update moved the parameters by only {moved}"
        );
    }
}

#[test]
fn an_update_after_behaviour_cloning_gives_the_reference_paths_parameters() {
    let config = PpoConfig {
        rollout_steps: 64,
        ..PpoConfig::default()
    };
    let (mut fused, mut candle) = engines(&config);
    let demo = rollout(&fused.net, 60, 3);
    let demos = crate::Demos {
        states: demo.states.clone(),
        stages: demo.stages.clone(),
        actions: demo.actions.clone(),
        masks: demo.masks.clone(),
    };
    for ppo in [&mut fused, &mut candle] {
        ppo.imitate(&demos, 40, 1e-3).expect("imitate");
    }
    assert_eq!(
        fused.net.flat_params().expect("p"),
        candle.net.flat_params().expect("p")
    );
    let r = rollout(&fused.net, 64, 9);
    let a = fused.update(&r, 0.0).expect("fused update");
    let b = candle.update(&r, 0.0).expect("candle update");
    assert_eq!(a.minibatches, b.minibatches, "{a:?} vs {b:?}");
    let (pa, pb) = (
        fused.net.flat_params().expect("params"),
        candle.net.flat_params().expect("params"),
    );
    let worst = max_difference(&pa, &pb);
    assert!(worst < 1e-5, "parameters differ by {worst}: {a:?} vs {b:?}");
}
