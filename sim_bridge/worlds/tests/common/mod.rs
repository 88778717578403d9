//! Helpers shared by the simulator tests.
#![allow(dead_code)]

use std::sync::Arc;

use kumi_model::{assemble, load_morphology, ActuatorMode, ModuleLibrary, RobotModel};
use kumi_worlds::{Engine, SimConfig, SimWorld};

pub fn model(name: &str) -> Arc<RobotModel> {
    let library = ModuleLibrary::shipped();
    Arc::new(assemble(
        &load_morphology(name, &library).unwrap(),
        &library,
    ))
}

/// Every engine this build has: rapier, and MuJoCo with the `mujoco` feature (CI builds it,
/// and `engines_under_test` fails there if it is missing).
pub fn engines() -> Vec<Engine> {
    kumi_worlds::available_engines()
}

pub fn world(engine: Engine, name: &str) -> Box<dyn SimWorld> {
    let model = model(name);
    kumi_worlds::build(engine, model.clone(), SimConfig::for_model(&model)).unwrap()
}

/// SplitMix64: a tiny seeded generator, so command sequences are reproducible.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Sends every arm a random target within its joint limits and every wheel module a random
/// velocity within its limit.
pub fn random_commands(world: &mut dyn SimWorld, rng: &mut Rng) {
    let model = world.model().clone();
    for m in &model.modules {
        let positions: Vec<f64> = m
            .actuators
            .iter()
            .filter(|a| a.mode == ActuatorMode::Position)
            .map(|a| rng.uniform(a.lower, a.upper))
            .collect();
        if !positions.is_empty() {
            world.set_position_targets(&m.name, &positions).unwrap();
        }
        if let Some(w) = m
            .actuators
            .iter()
            .find(|a| a.mode == ActuatorMode::Velocity)
        {
            let v = rng.uniform(-w.velocity_limit, w.velocity_limit);
            world.set_wheel_velocity(&m.name, v).unwrap();
        }
    }
}

/// Every number that describes the world's state, as bits: for exact comparisons.
pub fn state_bits(world: &dyn SimWorld) -> Vec<u64> {
    let mut bits: Vec<u64> = world
        .joint_positions()
        .into_iter()
        .chain(world.joint_velocities())
        .map(f64::to_bits)
        .collect();
    for (_, pose) in world.body_poses() {
        bits.extend(pose.translation.vector.iter().map(|x| x.to_bits()));
        bits.extend(pose.rotation.coords.iter().map(|x| x.to_bits()));
    }
    bits
}
