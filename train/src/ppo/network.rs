//! The actor-critic networks: MLPs with ELU activations whose parameters kumi initialises from
//! its own seeded generator (candle cannot seed its CPU generator), and a state-independent,
//! learned log standard deviation.

use candle_core::{DType, Device, Result, Tensor, Var};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// One dense layer's parameters as plain arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseParameters {
    /// Row-major [outputs][inputs].
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
    pub inputs: usize,
    pub outputs: usize,
}

/// A multilayer perceptron: `Linear -> ELU -> ... -> Linear` (no activation on the output).
pub struct Mlp {
    /// (weight [out, in], bias [out]) per layer.
    layers: Vec<(Var, Var)>,
}

impl Mlp {
    /// Layer sizes `[input, hidden.., output]`. Weights and biases are uniform in
    /// +-1/sqrt(fan_in) (PyTorch's default); the last layer's weights are scaled by
    /// `last_scale` (small for a policy mean, so initial actions stay near zero).
    pub fn new(
        sizes: &[usize],
        last_scale: f64,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> Result<Self> {
        let mut layers = Vec::with_capacity(sizes.len() - 1);
        for (k, pair) in sizes.windows(2).enumerate() {
            let (fan_in, fan_out) = (pair[0], pair[1]);
            let bound = 1.0 / (fan_in as f64).sqrt();
            let scale = if k == sizes.len() - 2 {
                last_scale
            } else {
                1.0
            };
            let w: Vec<f32> = (0..fan_in * fan_out)
                .map(|_| (rng.random_range(-bound..bound) * scale) as f32)
                .collect();
            let b: Vec<f32> = (0..fan_out)
                .map(|_| rng.random_range(-bound..bound) as f32)
                .collect();
            layers.push((
                Var::from_tensor(&Tensor::from_vec(w, (fan_out, fan_in), device)?)?,
                Var::from_tensor(&Tensor::from_vec(b, fan_out, device)?)?,
            ));
        }
        Ok(Self { layers })
    }

    /// `x` is [batch, input]; returns [batch, output].
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut h = x.clone();
        for (k, (w, b)) in self.layers.iter().enumerate() {
            h = h
                .matmul(&w.as_tensor().t()?)?
                .broadcast_add(b.as_tensor())?;
            if k + 1 < self.layers.len() {
                h = h.elu(1.0)?;
            }
        }
        Ok(h)
    }

    pub fn vars(&self) -> Vec<Var> {
        self.layers
            .iter()
            .flat_map(|(w, b)| [w.clone(), b.clone()])
            .collect()
    }

    /// The variables with stable names: `<prefix>.<layer>.weight` and `.bias`.
    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.layers
            .iter()
            .enumerate()
            .flat_map(|(k, (w, b))| {
                [
                    (format!("{prefix}.{k}.weight"), w.clone()),
                    (format!("{prefix}.{k}.bias"), b.clone()),
                ]
            })
            .collect()
    }

    /// The parameters as plain arrays, layer by layer (for export).
    pub fn parameters(&self) -> Result<Vec<DenseParameters>> {
        self.layers
            .iter()
            .map(|(w, b)| {
                let (outputs, inputs) = w.as_tensor().dims2()?;
                Ok(DenseParameters {
                    weight: w.as_tensor().flatten_all()?.to_vec1()?,
                    bias: b.as_tensor().to_vec1()?,
                    inputs,
                    outputs,
                })
            })
            .collect()
    }
}

/// A Gaussian policy (mean from the actor MLP, learned log-std) and a value function.
pub struct ActorCritic {
    pub actor: Mlp,
    pub critic: Mlp,
    /// [action_dim]
    pub log_std: Var,
}

impl ActorCritic {
    pub fn new(
        obs_dim: usize,
        action_dim: usize,
        hidden: &[usize],
        initial_log_std: f32,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> Result<Self> {
        let sizes = |out: usize| [&[obs_dim][..], hidden, &[out]].concat();
        Ok(Self {
            actor: Mlp::new(&sizes(action_dim), 0.01, rng, device)?,
            critic: Mlp::new(&sizes(1), 1.0, rng, device)?,
            log_std: Var::from_tensor(
                &Tensor::full(initial_log_std, action_dim, device)?.to_dtype(DType::F32)?,
            )?,
        })
    }

    /// Every variable with its stable name (for checkpoints).
    pub fn named_vars(&self) -> Vec<(String, Var)> {
        let mut v = self.actor.named_vars("actor");
        v.extend(self.critic.named_vars("critic"));
        v.push(("log_std".to_string(), self.log_std.clone()));
        v
    }

    pub fn vars(&self) -> Vec<Var> {
        let mut v = self.actor.vars();
        v.extend(self.critic.vars());
        v.push(self.log_std.clone());
        v
    }

    /// Value estimates [batch] for normalised observations [batch, obs_dim].
    pub fn value(&self, obs: &Tensor) -> Result<Tensor> {
        self.critic.forward(obs)?.squeeze(1)
    }
}
