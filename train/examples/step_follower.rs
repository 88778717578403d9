//! A step follower as a skill file: an ONNX policy of the skill's contract (format
//! `kumi-skill/arm-reach/4`) whose action is GAIN times the observed joint step
//! (`kumi_policies::kinematics::damped_step_rad`) over the largest increment, a linear map and
//! nothing learnt. Every command that takes a skill runs it (`kumi eval arm --policy`,
//! `kumi sim --skill`, the arm node), so what the step alone does through the physics is
//! measured by the same measures as a trained skill: the floor a learnt skill should beat.
//!
//! `cargo run --release -p kumi-train --example step_follower -- GAIN OUT.onnx`

use kumi_model::{assemble, load_morphology, ModuleLibrary};
use kumi_policies::observation::{JOINTS, OBSERVATION_DIM};
use kumi_policies::skill::ArmSkill;
use kumi_train::arm_reach::step_prior;
use kumi_train::export::{actor_model, encode};
use kumi_train::nn::mlp::DenseParameters;
use kumi_train::ppo::normalizer::RunningNorm;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: step_follower GAIN OUT.onnx";
    let gain: f64 = args.get(1).ok_or(usage)?.parse()?;
    let out = args.get(2).ok_or(usage)?;
    let library = ModuleLibrary::shipped();
    let model = assemble(&load_morphology("arm", &library)?, &library);
    let skill = ArmSkill::new(&model.modules[0], 30.0)?;
    // A network that outputs zeros, and the follower as the prior training's `[action]
    // step_prior_gain` adds (kumi_train::arm_reach::step_prior).
    let layer = DenseParameters {
        weight: vec![0.0; JOINTS * OBSERVATION_DIM],
        bias: vec![0.0; JOINTS],
        inputs: OBSERVATION_DIM,
        outputs: JOINTS,
    };
    let prior = step_prior(gain, &skill);
    // The identity normaliser: mean 0, variance 1.
    let mut norm = RunningNorm::new(OBSERVATION_DIM);
    norm.mean.fill(0.0);
    norm.var.fill(1.0);
    let metadata = skill.metadata(OBSERVATION_DIM, &format!("step-follower-gain-{gain}"), 0);
    std::fs::write(
        out,
        encode(&actor_model(&norm, &[layer], Some(&prior), &metadata)),
    )?;
    println!("step follower, gain {gain}: {out}");
    Ok(())
}
