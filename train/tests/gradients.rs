//! The hand-written backward pass of the PPO update is checked twice, in f64: against central
//! finite differences of the loss, and against candle's reverse-mode autodiff of the same loss
//! written with candle's operations. Both over a minibatch that spans several parallel blocks.

use candle_core::{DType, Device, Tensor, Var, D};
use kumi_train::ppo::loss::{gaussian_log_prob, LossCoefficients, Samples};
use kumi_train::ppo::network::{ActorCritic, Gradient, Minibatch, BLOCK_ROWS};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const OBS: usize = 5;
const ACT: usize = 3;
const HIDDEN: [usize; 2] = [8, 6];
/// Spans three blocks, the last one partial.
const ROWS: usize = 2 * BLOCK_ROWS + 37;

const COEFFICIENTS: LossCoefficients = LossCoefficients {
    clip: 0.2,
    value: 0.5,
    entropy: 0.01,
    bound: 0.3,
};

struct Data {
    observations: Vec<f64>,
    actions: Vec<f64>,
    old_log_prob: Vec<f64>,
    advantages: Vec<f64>,
    returns: Vec<f64>,
}

impl Data {
    fn batch(&self) -> Minibatch<'_, f64> {
        Minibatch {
            observations: &self.observations,
            samples: Samples {
                actions: &self.actions,
                old_log_prob: &self.old_log_prob,
                advantages: &self.advantages,
                returns: &self.returns,
            },
        }
    }
}

/// A network with non-trivial parameters and a batch whose probability ratios spread over and
/// beyond the clipping range (so that both branches of the clipped objective are exercised).
fn fixture() -> (ActorCritic<f64>, Data) {
    fixture_reading(OBS)
}

/// [`fixture`] with an actor that reads the leading `actor_obs` of the `OBS` values the critic
/// reads.
fn fixture_reading(actor_obs: usize) -> (ActorCritic<f64>, Data) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut net = ActorCritic::<f64>::asymmetric(OBS, actor_obs, ACT, &HIDDEN, -0.3, &mut rng);
    // A last actor layer of ordinary size, so that means and their gradients are not tiny.
    net.actor
        .params
        .iter_mut()
        .for_each(|p| *p = rng.random_range(-0.6..0.6));
    // Output biases that put many means past the clip range of +-1, where the bound loss acts.
    let biases = net.actor.params.len() - ACT;
    net.actor.params[biases..].copy_from_slice(&[1.0, -1.1, 0.2]);
    net.log_std = vec![-0.4, 0.1, -0.7];
    let mut r = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
        (0..n).map(|_| rng.random_range(lo..hi)).collect()
    };
    let observations = r(-2.0, 2.0, ROWS * OBS);
    let actions = r(-1.5, 1.5, ROWS * ACT);
    let advantages = r(-2.0, 2.0, ROWS);
    let returns = r(-1.0, 1.0, ROWS);
    let shifts = r(-0.4, 0.4, ROWS);
    let now = gaussian_log_prob(&actions, &net.mean(&observations), &net.log_std);
    let old_log_prob = now.iter().zip(&shifts).map(|(l, s)| l + s).collect();
    (
        net,
        Data {
            observations,
            actions,
            old_log_prob,
            advantages,
            returns,
        },
    )
}

fn flat(g: &Gradient<f64>) -> Vec<f64> {
    g.groups().concat()
}

fn parameters_mut(net: &mut ActorCritic<f64>) -> Vec<&mut f64> {
    net.groups_mut()
        .into_iter()
        .flat_map(|g| g.iter_mut())
        .collect()
}

#[test]
fn gradients_match_finite_differences_to_1e_5() {
    let (net, data) = fixture();
    assert_matches_finite_differences(&net, &data);
}

#[test]
fn an_asymmetric_critics_gradients_match_finite_differences_and_the_actor_reads_its_part() {
    let (net, data) = fixture_reading(3);
    assert_eq!((net.actor.inputs(), net.critic.inputs()), (3, OBS));
    assert_matches_finite_differences(&net, &data);
    // What only the critic sees (the last two values of each row) moves the values, never the
    // means.
    let mut moved = data.observations.clone();
    moved
        .chunks_mut(OBS)
        .for_each(|row| row[3..].iter_mut().for_each(|v| *v += 0.7));
    assert_eq!(net.mean(&moved), net.mean(&data.observations));
    let (before, after) = (net.value(&data.observations), net.value(&moved));
    assert!(before.iter().zip(&after).all(|(b, a)| b != a));
}

fn assert_matches_finite_differences(net: &ActorCritic<f64>, data: &Data) {
    // Some means lie past the clip range, so the bound loss is part of what is checked.
    let means = net.mean(&data.observations);
    let past = means.iter().filter(|m| m.abs() > 1.0).count();
    assert!(
        past > means.len() / 20 && past < means.len(),
        "{past} of {} means past +-1",
        means.len()
    );
    let (_, gradient) = net.loss_and_gradient(&data.batch(), &COEFFICIENTS);
    let analytic = flat(&gradient);
    let h = 1e-6;
    let loss_at = |k: usize, delta: f64| {
        let mut moved = net.clone();
        *parameters_mut(&mut moved).swap_remove(k) += delta;
        moved
            .loss_and_gradient(&data.batch(), &COEFFICIENTS)
            .0
            .total
    };
    let mut worst: f64 = 0.0;
    for (k, a) in analytic.iter().enumerate() {
        let numeric = (loss_at(k, h) - loss_at(k, -h)) / (2.0 * h);
        worst = worst.max((numeric - a).abs());
    }
    let scale = analytic.iter().fold(0.0_f64, |m, g| m.max(g.abs()));
    assert!(
        scale > 1e-2,
        "a gradient worth checking: largest entry {scale}"
    );
    assert!(
        worst < 1e-5,
        "hand-written gradient differs from finite differences by {worst:e}"
    );
}

/// The same loss in candle's operations (the reference the trainer used before).
fn candle_loss(
    layers: &[(Var, Var)],
    critic: &[(Var, Var)],
    log_std: &Var,
    data: &Data,
) -> candle_core::Result<Tensor> {
    let dev = Device::Cpu;
    let obs = Tensor::from_vec(data.observations.clone(), (ROWS, OBS), &dev)?;
    let mlp = |net: &[(Var, Var)], x: &Tensor| -> candle_core::Result<Tensor> {
        let mut h = x.clone();
        for (k, (w, b)) in net.iter().enumerate() {
            h = h
                .matmul(&w.as_tensor().t()?)?
                .broadcast_add(b.as_tensor())?;
            if k + 1 < net.len() {
                h = h.elu(1.0)?;
            }
        }
        Ok(h)
    };
    let mean = mlp(layers, &obs)?;
    let ls = log_std.as_tensor();
    let actions = Tensor::from_vec(data.actions.clone(), (ROWS, ACT), &dev)?;
    let z = actions.sub(&mean)?.broadcast_div(&ls.exp()?)?;
    let half_ln_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
    let log_prob = (z.sqr()? * -0.5)?
        .broadcast_sub(ls)?
        .affine(1.0, -half_ln_2pi)?
        .sum(D::Minus1)?;
    let old = Tensor::from_vec(data.old_log_prob.clone(), ROWS, &dev)?;
    let adv = Tensor::from_vec(data.advantages.clone(), ROWS, &dev)?;
    let ratio = log_prob.sub(&old)?.exp()?;
    let c = COEFFICIENTS;
    let clipped = ratio.clamp(1.0 - c.clip, 1.0 + c.clip)?.mul(&adv)?;
    let policy = ratio.mul(&adv)?.minimum(&clipped)?.mean_all()?.neg()?;
    let returns = Tensor::from_vec(data.returns.clone(), ROWS, &dev)?;
    let value = mlp(critic, &obs)?
        .squeeze(1)?
        .sub(&returns)?
        .sqr()?
        .mean_all()?;
    let entropy = ls
        .sum_all()?
        .affine(1.0, ACT as f64 * (0.5 + half_ln_2pi))?;
    let over = mean.affine(1.0, -1.0)?.relu()?;
    let under = mean.affine(-1.0, -1.0)?.relu()?;
    let bound = (over.sqr()? + under.sqr()?)?.sum(D::Minus1)?.mean_all()?;
    policy
        .add(&(value * c.value)?)?
        .sub(&(entropy * c.entropy)?)?
        .add(&(bound * c.bound)?)
}

/// Candle variables holding a network's parameters, layer by layer.
fn candle_layers(net: &kumi_train::ppo::network::Mlp<f64>) -> Vec<(Var, Var)> {
    let sizes = net.sizes();
    let mut at = 0;
    sizes
        .windows(2)
        .map(|pair| {
            let (i, o) = (pair[0], pair[1]);
            let w = Tensor::from_vec(net.params[at..at + i * o].to_vec(), (o, i), &Device::Cpu);
            let b = Tensor::from_vec(
                net.params[at + i * o..at + i * o + o].to_vec(),
                o,
                &Device::Cpu,
            );
            at += i * o + o;
            (
                Var::from_tensor(&w.unwrap()).unwrap(),
                Var::from_tensor(&b.unwrap()).unwrap(),
            )
        })
        .collect()
}

#[test]
fn gradients_match_candle_autodiff() {
    let (net, data) = fixture();
    let (loss, gradient) = net.loss_and_gradient(&data.batch(), &COEFFICIENTS);
    let (actor, critic) = (candle_layers(&net.actor), candle_layers(&net.critic));
    let log_std =
        Var::from_tensor(&Tensor::new(net.log_std.as_slice(), &Device::Cpu).unwrap()).unwrap();
    let total = candle_loss(&actor, &critic, &log_std, &data).unwrap();
    assert_eq!(total.dtype(), DType::F64);
    let candle_total = total.to_scalar::<f64>().unwrap();
    assert!(
        (candle_total - loss.total).abs() < 1e-12,
        "loss {candle_total} vs {}",
        loss.total
    );
    let grads = total.backward().unwrap();
    let mut reference = Vec::new();
    for layers in [&actor, &critic] {
        for (w, b) in layers {
            for v in [w, b] {
                let g = grads
                    .get(v.as_tensor())
                    .expect("every parameter has a gradient");
                reference.extend(g.flatten_all().unwrap().to_vec1::<f64>().unwrap());
            }
        }
    }
    reference.extend(
        grads
            .get(log_std.as_tensor())
            .unwrap()
            .to_vec1::<f64>()
            .unwrap(),
    );
    let mine = flat(&gradient);
    assert_eq!(mine.len(), reference.len());
    let worst = mine
        .iter()
        .zip(&reference)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0_f64, f64::max);
    assert!(worst < 1e-10, "differs from candle's autodiff by {worst:e}");
}

#[test]
fn training_precision_agrees_with_f64() {
    // The trainer computes in f32: its gradient stays within 1e-5 of the f64 one (relative to
    // the largest entry).
    let (net, data) = fixture();
    let (_, g64) = net.loss_and_gradient(&data.batch(), &COEFFICIENTS);
    let to32 = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<f32>>();
    let mut net32 =
        ActorCritic::<f32>::new(OBS, ACT, &HIDDEN, -0.3, &mut ChaCha8Rng::seed_from_u64(0));
    net32.actor.params = to32(&net.actor.params);
    net32.critic.params = to32(&net.critic.params);
    net32.log_std = to32(&net.log_std);
    let (obs, act, old, adv, ret) = (
        to32(&data.observations),
        to32(&data.actions),
        to32(&data.old_log_prob),
        to32(&data.advantages),
        to32(&data.returns),
    );
    let batch = Minibatch {
        observations: &obs,
        samples: Samples {
            actions: &act,
            old_log_prob: &old,
            advantages: &adv,
            returns: &ret,
        },
    };
    let (_, g32) = net32.loss_and_gradient(&batch, &COEFFICIENTS);
    let (a, b) = (flat(&g64), g32.groups().concat());
    let scale = a.iter().fold(0.0_f64, |m, g| m.max(g.abs()));
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - f64::from(*y)).abs())
        .fold(0.0_f64, f64::max);
    assert!(
        worst / scale < 1e-5,
        "f32 gradient off by {:e} (relative)",
        worst / scale
    );
}
