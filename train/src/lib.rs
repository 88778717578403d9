//! Training for kumi: environments on the same rapier world the sim bridge runs, and the pure
//! reward terms they use.
//!
//! - [`reward`]: the low-level reaching reward (the paper's Eq. 4), term by term.
//! - [`arm_reach`]: the low-level environment, one fixed-base arm module reaching goals.

pub mod arm_reach;
pub mod body_reward;
pub mod env;
pub mod evaluate;
pub mod evaluate_body;
pub mod export;
pub mod nn;
pub mod noise;
pub mod ppo;
pub mod randomize;
pub mod replay;
pub mod reward;
pub mod whole_body;
