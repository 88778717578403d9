//! A dense network `Linear -> ELU -> ... -> Linear` (no activation on the output) with its
//! forward pass, a forward pass that keeps what the backward pass needs, and the backward pass
//! (reverse-mode differentiation written out by hand, checked against finite differences and
//! candle's autodiff in `train/tests/gradients.rs`).
//!
//! Batches are row-major `[rows, features]`. Parameters are one flat array, layer after layer:
//! the weight `[outputs, inputs]` (row-major, PyTorch's and ONNX Gemm's `transB` layout), then
//! the bias `[outputs]`.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::matmul::{matmul, Mat, Real};

/// One dense layer's parameters as plain arrays (what the ONNX exporter writes).
#[derive(Debug, Clone, PartialEq)]
pub struct DenseParameters {
    /// Row-major [outputs][inputs].
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
    pub inputs: usize,
    pub outputs: usize,
}

/// A multilayer perceptron with ELU (alpha 1) between layers.
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp<T> {
    /// `[input, hidden.., output]`.
    sizes: Vec<usize>,
    /// Every layer's weight then bias, in layer order.
    pub params: Vec<T>,
}

/// Each layer's output for one batch (after its activation), kept for the backward pass.
#[derive(Debug, Clone)]
pub struct Trace<T> {
    pub rows: usize,
    /// `layers[0]` is the input; the last is the network's output.
    pub layers: Vec<Vec<T>>,
}

impl<T> Trace<T> {
    /// The network's output, `[rows, outputs]`.
    pub fn output(&self) -> &[T] {
        self.layers.last().expect("a trace has its input")
    }
}

/// ELU's derivative written in terms of its output `h`: 1 where `h > 0`, else `exp(z) = h + 1`.
fn elu_slope<T: Real>(h: T) -> T {
    if h > T::zero() {
        T::one()
    } else {
        h + T::one()
    }
}

impl<T: Real> Mlp<T> {
    /// Layer sizes `[input, hidden.., output]`. Weights and biases are uniform in
    /// +-1/sqrt(fan_in) (PyTorch's default); the last layer's weights are scaled by
    /// `last_scale` (small for a policy mean, so that initial actions stay near zero).
    pub fn new(sizes: &[usize], last_scale: f64, rng: &mut ChaCha8Rng) -> Self {
        assert!(sizes.len() >= 2, "a network has an input and an output");
        let mut params = Vec::new();
        for (k, pair) in sizes.windows(2).enumerate() {
            let (fan_in, fan_out) = (pair[0], pair[1]);
            let bound = 1.0 / (fan_in as f64).sqrt();
            let scale = if k == sizes.len() - 2 {
                last_scale
            } else {
                1.0
            };
            params.extend(
                (0..fan_in * fan_out).map(|_| T::of(rng.random_range(-bound..bound) * scale)),
            );
            params.extend((0..fan_out).map(|_| T::of(rng.random_range(-bound..bound))));
        }
        Self {
            sizes: sizes.to_vec(),
            params,
        }
    }

    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    pub fn inputs(&self) -> usize {
        self.sizes[0]
    }

    pub fn outputs(&self) -> usize {
        *self.sizes.last().expect("sizes has at least two entries")
    }

    /// (offset of the weight, inputs, outputs) of each layer in [`Self::params`].
    fn layout(&self) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        self.sizes.windows(2).scan(0, |offset, pair| {
            let at = *offset;
            *offset += pair[0] * pair[1] + pair[1];
            Some((at, pair[0], pair[1]))
        })
    }

    /// `[rows, inputs]` to `[rows, outputs]`.
    pub fn forward(&self, x: &[T], rows: usize) -> Vec<T> {
        self.forward_trace(x, rows)
            .layers
            .pop()
            .expect("a trace has its output")
    }

    /// The forward pass, keeping every layer's output for [`Self::backward`].
    pub fn forward_trace(&self, x: &[T], rows: usize) -> Trace<T> {
        assert_eq!(x.len(), rows * self.inputs(), "input is not [rows, inputs]");
        let last = self.sizes.len() - 2;
        let mut layers = vec![x.to_vec()];
        for (k, (at, inputs, outputs)) in self.layout().enumerate() {
            let (weight, bias) = self.params[at..].split_at(inputs * outputs);
            // Start from the bias, then add h W^T.
            let mut z = Vec::with_capacity(rows * outputs);
            for _ in 0..rows {
                z.extend_from_slice(&bias[..outputs]);
            }
            let h = &layers[k];
            matmul(
                Mat::new(h, rows, inputs),
                Mat::new(weight, outputs, inputs).t(),
                &mut z,
                true,
            );
            if k < last {
                T::elu_in_place(&mut z);
            }
            layers.push(z);
        }
        Trace { rows, layers }
    }

    /// Adds to `grad` (shaped like [`Self::params`]) the gradient of a loss whose derivative
    /// with respect to the network's output is `d_output` (`[rows, outputs]`).
    pub fn backward(&self, trace: &Trace<T>, d_output: &[T], grad: &mut [T]) {
        let rows = trace.rows;
        assert_eq!(d_output.len(), rows * self.outputs(), "d_output shape");
        assert_eq!(grad.len(), self.params.len(), "gradient shape");
        let layout: Vec<_> = self.layout().collect();
        let mut delta = d_output.to_vec();
        for (k, &(at, inputs, outputs)) in layout.iter().enumerate().rev() {
            let below = &trace.layers[k];
            let (g_weight, g_bias) =
                grad[at..at + inputs * outputs + outputs].split_at_mut(inputs * outputs);
            // dL/dW += delta^T h_below; dL/db += column sums of delta.
            matmul(
                Mat::new(&delta, rows, outputs).t(),
                Mat::new(below, rows, inputs),
                g_weight,
                true,
            );
            for row in delta.chunks_exact(outputs) {
                g_bias.iter_mut().zip(row).for_each(|(g, d)| *g += *d);
            }
            if k == 0 {
                break;
            }
            // dL/dh_below = delta W, through the activation below.
            let weight = &self.params[at..at + inputs * outputs];
            let mut down = vec![T::zero(); rows * inputs];
            matmul(
                Mat::new(&delta, rows, outputs),
                Mat::new(weight, outputs, inputs),
                &mut down,
                false,
            );
            down.iter_mut()
                .zip(below)
                .for_each(|(d, h)| *d = *d * elu_slope(*h));
            delta = down;
        }
    }

    /// The parameters layer by layer, in `f32` (for export).
    pub fn parameters(&self) -> Vec<DenseParameters> {
        let f = |v: &[T]| v.iter().map(|x| x.to_f32().unwrap_or(f32::NAN)).collect();
        self.layout()
            .map(|(at, inputs, outputs)| DenseParameters {
                weight: f(&self.params[at..at + inputs * outputs]),
                bias: f(&self.params[at + inputs * outputs..at + inputs * outputs + outputs]),
                inputs,
                outputs,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_two_layer_network_by_hand() {
        // 2 -> 2 -> 1 with W1 = [[1, -1], [0.5, 0]], b1 = [0, -1], W2 = [[2, 1]], b2 = [0.5]
        let mut net = Mlp::<f64>::new(&[2, 2, 1], 1.0, &mut ChaCha8Rng::seed_from_u64(0));
        net.params = vec![1.0, -1.0, 0.5, 0.0, 0.0, -1.0, 2.0, 1.0, 0.5];
        // x = [1, 2]: z1 = [-1, -0.5], h1 = [e^-1 - 1, e^-0.5 - 1], y = 2 h1_0 + h1_1 + 0.5
        let y = net.forward(&[1.0, 2.0], 1)[0];
        let h = [(-1.0_f64).exp_m1(), (-0.5_f64).exp_m1()];
        assert!((y - (2.0 * h[0] + h[1] + 0.5)).abs() < 1e-15);
        // dy/dW2 = h1, dy/db2 = 1, dy/db1 = W2 * elu'(z1) = [2 e^-1, e^-0.5]
        let mut g = vec![0.0; 9];
        net.backward(&net.forward_trace(&[1.0, 2.0], 1), &[1.0], &mut g);
        assert!((g[6] - h[0]).abs() < 1e-15 && (g[7] - h[1]).abs() < 1e-15);
        assert_eq!(g[8], 1.0);
        assert!((g[4] - 2.0 * (-1.0_f64).exp()).abs() < 1e-15);
        assert!((g[5] - (-0.5_f64).exp()).abs() < 1e-15);
        // dy/dW1[0] = dy/db1[0] * x = 2 e^-1 [1, 2]
        assert!((g[1] - 4.0 * (-1.0_f64).exp()).abs() < 1e-15);
    }

    #[test]
    fn dense_parameters_follow_the_layer_layout() {
        let net = Mlp::<f32>::new(&[3, 4, 2], 0.01, &mut ChaCha8Rng::seed_from_u64(1));
        let layers = net.parameters();
        assert_eq!(layers.len(), 2);
        assert_eq!((layers[0].inputs, layers[0].outputs), (3, 4));
        assert_eq!(layers[1].weight.len(), 8);
        assert_eq!(layers[1].bias, net.params[12 + 4 + 8..].to_vec());
        // the last layer is scaled down: |w| <= 0.01 / sqrt(4)
        assert!(layers[1].weight.iter().all(|w| w.abs() <= 0.005));
    }
}
