//! PPO (Schulman et al. 2017) for goal-conditioned policies (the goal is part of the
//! observation, UVFA-style): pure maths in [`gae`], [`loss`] and [`normalizer`]; networks in
//! [`network`].

pub mod gae;
pub mod loss;
pub mod network;
pub mod normalizer;
pub mod trainer;
