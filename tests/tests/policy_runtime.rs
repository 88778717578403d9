//! The policy runtime: both backends reproduce the training network, and a policy that does
//! not fit its module (metadata, shapes, file) is refused with a message naming the problem.

use std::collections::BTreeMap;
use std::sync::Once;

use kumi_policies::metadata;
use kumi_policies::observation::OBSERVATION_DIM;
use kumi_policies::skill::ArmSkill;
use kumi_runtime::{Backend, BackendChoice, RuntimeError, SkillPolicy};
use kumi_train::export::{actor_model, encode};
use kumi_train::ppo::network::Mlp;
use kumi_train::ppo::normalizer::RunningNorm;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn arm_skill(control_hz: f64) -> ArmSkill {
    ArmSkill::new(&kumi_tests::shipped_model("arm").modules[0], control_hz).unwrap()
}

/// A random policy with `obs_dim` inputs, its statistics and its ONNX bytes.
fn random_policy(
    obs_dim: usize,
    metadata: &BTreeMap<String, String>,
) -> (Mlp<f32>, RunningNorm, Vec<u8>) {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let net = Mlp::new(&[obs_dim, 64, 32, 7], 1.0, &mut rng);
    let mut norm = RunningNorm::new(obs_dim);
    let rows: Vec<Vec<f32>> = (0..200)
        .map(|_| {
            (0..obs_dim)
                .map(|j| rng.random_range(-2.0..2.0) + j as f32 * 0.1)
                .collect()
        })
        .collect();
    norm.update(&rows.iter().map(|r| r.as_slice()).collect::<Vec<_>>());
    let bytes = encode(&actor_model(&norm, &net.parameters(), None, metadata));
    (net, norm, bytes)
}

fn use_onnxruntime() {
    static SET: Once = Once::new();
    SET.call_once(|| std::env::set_var("ORT_DYLIB_PATH", kumi_tests::onnxruntime_library()));
}

#[test]
fn skills_of_the_first_formats_read_the_leading_21_28_or_34_values() {
    use kumi_policies::observation::{BASE_DIM, LEAD_DIM, TOOL_DIM};
    use_onnxruntime();
    let skill = arm_skill(30.0);
    for prefix in [BASE_DIM, LEAD_DIM, TOOL_DIM] {
        reads_the_leading(prefix, &skill);
    }
}

fn reads_the_leading(prefix: usize, skill: &ArmSkill) {
    let (net, norm, bytes) = random_policy(prefix, &skill.metadata(prefix, "test", 0));
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    for choice in [BackendChoice::Tract, BackendChoice::OnnxRuntime] {
        let mut policy =
            SkillPolicy::from_bytes(bytes.clone(), "prefix.onnx", skill, choice).unwrap();
        assert_eq!(policy.observation_dim(), prefix);
        let observations: Vec<[f32; OBSERVATION_DIM]> = (0..5)
            .map(|_| std::array::from_fn(|_| rng.random_range(-3.0..3.0)))
            .collect();
        let batch = policy.act_batch(&observations).unwrap();
        for (obs, batched) in observations.iter().zip(&batch) {
            let got = policy.act(obs).unwrap();
            let want = net.forward(&norm.apply(&obs[..prefix]), 1);
            for ((g, b), w) in got.iter().zip(batched).zip(&want) {
                assert!(
                    (g - w).abs() <= 1e-5 && (g - b).abs() <= 1e-6,
                    "{choice:?}: {g}, batched {b} vs {w}"
                );
            }
        }
    }
}

#[test]
fn both_backends_reproduce_the_training_network() {
    use_onnxruntime();
    let skill = arm_skill(30.0);
    let (net, norm, bytes) =
        random_policy(OBSERVATION_DIM, &skill.metadata(OBSERVATION_DIM, "test", 0));
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for choice in [BackendChoice::Tract, BackendChoice::OnnxRuntime] {
        let mut policy =
            SkillPolicy::from_bytes(bytes.clone(), "test.onnx", &skill, choice).unwrap();
        assert_eq!(
            policy.backend(),
            if choice == BackendChoice::Tract {
                Backend::Tract
            } else {
                Backend::OnnxRuntime
            }
        );
        for _ in 0..20 {
            let obs: [f32; OBSERVATION_DIM] = std::array::from_fn(|_| rng.random_range(-3.0..3.0));
            let got = policy.act(&obs).unwrap();
            let want = net.forward(&norm.apply(&obs), 1);
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() <= 1e-5, "{choice:?}: {g} vs {w}");
            }
        }
    }
    // With the library named, `auto` means ONNX Runtime.
    assert_eq!(BackendChoice::Auto.resolve(), Backend::OnnxRuntime);
}

#[test]
fn a_policy_for_another_control_rate_is_refused() {
    let trained = arm_skill(60.0).metadata(OBSERVATION_DIM, "test", 0);
    let (_, _, bytes) = random_policy(OBSERVATION_DIM, &trained);
    let err = SkillPolicy::from_bytes(bytes, "fast.onnx", &arm_skill(30.0), BackendChoice::Tract)
        .unwrap_err();
    assert!(matches!(err, RuntimeError::Metadata { .. }));
    let text = err.to_string();
    assert!(
        text.starts_with("fast.onnx: does not fit module `arm`"),
        "{text}"
    );
    assert!(text.contains("kumi.action_scale"), "{text}");
}

#[test]
fn a_policy_for_other_joints_is_refused() {
    let skill = arm_skill(30.0);
    let mut m = skill.metadata(OBSERVATION_DIM, "test", 0);
    m.insert(metadata::JOINT_NAMES.into(), "j7,j6,j5,j4,j3,j2,j1".into());
    let (_, _, bytes) = random_policy(OBSERVATION_DIM, &m);
    let text = SkillPolicy::from_bytes(bytes, "p.onnx", &skill, BackendChoice::Tract)
        .unwrap_err()
        .to_string();
    assert!(
        text.contains("kumi.joints") && text.contains("j7,j6"),
        "{text}"
    );
}

#[test]
fn a_model_without_kumi_metadata_is_refused() {
    let (_, _, bytes) = random_policy(OBSERVATION_DIM, &BTreeMap::new());
    let text = SkillPolicy::from_bytes(
        bytes,
        "foreign.onnx",
        &arm_skill(30.0),
        BackendChoice::Tract,
    )
    .unwrap_err()
    .to_string();
    assert!(text.contains("`kumi.format` is missing"), "{text}");
}

#[test]
fn a_model_of_the_wrong_shape_is_refused() {
    // Metadata that claims the arm layout on a network with 20 inputs.
    let skill = arm_skill(30.0);
    let (_, _, bytes) = random_policy(20, &skill.metadata(OBSERVATION_DIM, "test", 0));
    let err = SkillPolicy::from_bytes(bytes, "p.onnx", &skill, BackendChoice::Tract).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, RuntimeError::Shape { .. }), "{text}");
    assert!(
        text.contains("the input has shape [batch, 20]")
            && text.contains(&format!("[batch, {OBSERVATION_DIM}]")),
        "{text}"
    );
}

#[test]
fn unreadable_files_are_errors_not_panics() {
    let skill = arm_skill(30.0);
    let err = SkillPolicy::from_bytes(
        b"not a model".to_vec(),
        "junk.onnx",
        &skill,
        BackendChoice::Tract,
    )
    .unwrap_err();
    assert!(
        err.to_string().starts_with("junk.onnx: not an ONNX model"),
        "{err}"
    );
    let err = SkillPolicy::load(
        std::path::Path::new("/nonexistent/p.onnx"),
        &skill,
        BackendChoice::Tract,
    )
    .unwrap_err();
    assert!(
        err.to_string().starts_with("/nonexistent/p.onnx: "),
        "{err}"
    );
}

#[test]
fn the_shipped_policy_drives_every_arm_module_of_every_morphology() {
    let shipped = kumi_runtime::shipped_arm_policy();
    let mut driven = Vec::new();
    for name in ["arm", "minimal", "dragon", "tricycle"] {
        let robot = kumi_tests::shipped_model(name);
        let control_hz = kumi_worlds::SimConfig::for_model(&robot).control_hz;
        for module in robot.modules.iter().filter(|m| m.kind == "arm") {
            let skill = ArmSkill::new(module, control_hz).unwrap();
            let mut policy = SkillPolicy::load(&shipped, &skill, BackendChoice::Tract)
                .unwrap_or_else(|e| panic!("{name}/{}: {e}", module.name));
            let action = policy.act(&[0.0; OBSERVATION_DIM]).unwrap();
            assert!(action.iter().all(|a| a.is_finite()));
            driven.push(format!("{name}/{}", module.name));
        }
    }
    // Every arm module of the four shipped robots (Tricycle alone has four).
    assert!(driven.len() >= 8, "{driven:?}");
}

#[test]
fn every_shipped_whole_body_policy_fits_its_robot_and_the_shipped_skill() {
    // The contract a whole-body policy is loaded against, built as `kumi eval whole-body` and
    // the whole-body node build it: the robot, its config's goal bounds (or, for the flat and
    // penalty baselines, joint bounds), the shipped skill.
    #[derive(serde::Deserialize)]
    struct Config {
        action: Option<kumi_terms::action::GoalBounds>,
        flat: Option<kumi_terms::action::JointBounds>,
        #[serde(default)]
        observation: kumi_terms::ObservationOptions,
    }
    let skill = std::fs::read(kumi_runtime::shipped_arm_policy()).unwrap();
    let mut loaded = Vec::new();
    for name in ["minimal", "dragon", "tricycle"] {
        for (file, configs) in [
            ("whole_body", "whole_body"),
            ("flat", "flat"),
            ("penalty", "penalty"),
        ] {
            let path = kumi_runtime::shipped_policy(&format!("{name}_{file}"));
            if !path.exists() {
                continue;
            }
            let robot = kumi_tests::shipped_model(name);
            // The config the policy finished its training with: Tricycle's fourth stage
            // tightened its turn governor and its fifth and sixth kept it (`kumi eval` reads it so:
            // SHIPPED_LAST_STAGES in cli/src/train.rs); every other shipped policy has its
            // first stage's terms.
            let stage = if (name, file) == ("tricycle", "whole_body") {
                "tricycle_sixth"
            } else {
                name
            };
            let text = std::fs::read_to_string(
                kumi_tests::workspace().join(format!("train/configs/{configs}/{stage}.toml")),
            )
            .unwrap_or_else(|e| panic!("{name} {file}: no config: {e}"));
            let config: Config = toml::from_str(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
            let terms = match (config.action, config.flat) {
                (Some(bounds), None) => kumi_terms::ActionTerms::new(&robot, &bounds).unwrap(),
                (None, Some(bounds)) => kumi_terms::ActionTerms::flat(&robot, &bounds).unwrap(),
                _ => panic!("{name} {file}: one of [action] and [flat]"),
            };
            let expected = kumi_terms::contract::contract(
                &robot,
                &terms,
                config.observation,
                &skill,
                kumi_model::commands::CONTROL_HZ,
            );
            let mut policy =
                kumi_runtime::WholeBodyPolicy::load(&path, &expected, BackendChoice::Tract)
                    .unwrap_or_else(|e| panic!("{name} {file}: {e}"));
            let size: usize = expected[kumi_policies::metadata::OBSERVATION_DIM_KEY]
                .parse()
                .unwrap();
            let action = policy.act(&vec![0.0; size]).unwrap();
            assert_eq!(action.len(), terms.size());
            assert!(
                action.iter().all(|a| a.is_finite()),
                "{name} {file}: {action:?}"
            );
            loaded.push(format!("{name}_{file}"));
        }
    }
    // Minimal's is shipped (policies/minimal_whole_body/README.md); the others join as they are.
    assert!(
        loaded.contains(&"minimal_whole_body".to_string()),
        "{loaded:?}"
    );
}
