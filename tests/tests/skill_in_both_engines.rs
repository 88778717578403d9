//! The shipped arm skill reaches goals alike in both engines: over 1000 goals of the paper's
//! protocol (through the policy runtime), the mean final errors differ by at most 0.01 m and
//! 0.03 rad.
#![cfg(feature = "mujoco")]

use kumi_policies::skill::ArmSkill;
use kumi_runtime::{BackendChoice, SkillPolicy};
use kumi_train::arm_reach::ArmReachConfig;
use kumi_train::evaluate::{evaluate, Evaluation};
use kumi_worlds::{Engine, SimConfig};

fn evaluate_in(engine: Engine) -> Evaluation {
    let model = kumi_tests::shipped_model("arm");
    let skill = ArmSkill::new(&model.modules[0], SimConfig::for_model(&model).control_hz).unwrap();
    let path = kumi_runtime::shipped_arm_policy();
    evaluate(
        model,
        ArmReachConfig {
            engine,
            ..ArmReachConfig::default()
        },
        1000,
        1,
        || {
            let mut policy = SkillPolicy::load(&path, &skill, BackendChoice::Tract)
                .map_err(|e| e.to_string())?;
            Ok(move |obs: &_| policy.act(obs).map_err(|e| e.to_string()))
        },
    )
    .unwrap()
}

#[test]
fn the_shipped_skill_scores_alike_in_rapier_and_mujoco() {
    let r = evaluate_in(Engine::Rapier);
    let m = evaluate_in(Engine::Mujoco);
    assert_eq!((r.engine.as_str(), m.engine.as_str()), ("rapier", "mujoco"));
    let dp = m.position_error_m.mean - r.position_error_m.mean;
    let dr = m.orientation_error_rad.mean - r.orientation_error_rad.mean;
    println!(
        "rapier {:.4} m / {:.4} rad, mujoco {:.4} m / {:.4} rad",
        r.position_error_m.mean,
        r.orientation_error_rad.mean,
        m.position_error_m.mean,
        m.orientation_error_rad.mean
    );
    assert!(dp.abs() <= 0.01, "position means differ by {dp} m");
    assert!(dr.abs() <= 0.03, "orientation means differ by {dr} rad");
}
