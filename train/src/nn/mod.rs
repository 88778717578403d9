//! A small neural-network kernel for PPO: dense ELU networks with a hand-written backward pass
//! ([`mlp`]), Adam ([`adam`]) and the one matrix product everything uses ([`matmul`], on the
//! `gemm` crate). Generic over [`Real`] so that the gradient tests can run in `f64`
//! against finite differences; training runs in `f32`.

pub mod adam;
pub mod matmul;
pub mod mlp;

pub use matmul::Real;
