//! The exported ONNX actor reproduces the training network's output.

use kumi_train::export::{actor_model, encode, INPUT, OPSET, OUTPUT};
use kumi_train::ppo::network::ActorCritic;
use kumi_train::ppo::normalizer::RunningNorm;
use prost::Message;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tract_onnx::prelude::*;

const OBS: usize = 21;
const ACT: usize = 7;

fn random_rows(rng: &mut ChaCha8Rng, n: usize) -> Vec<Vec<f32>> {
    (0..n)
        .map(|_| (0..OBS).map(|_| rng.random_range(-3.0..3.0)).collect())
        .collect()
}

/// The model's outputs [rows, ACT] for `rows`, run in tract (pure Rust).
fn run_in_tract(bytes: &[u8], rows: &[Vec<f32>]) -> Vec<f32> {
    let model = tract_onnx::onnx()
        .model_for_read(&mut &bytes[..])
        .unwrap()
        .with_input_fact(0, f32::fact([rows.len(), OBS]).into())
        .unwrap()
        .into_optimized()
        .unwrap()
        .into_runnable()
        .unwrap();
    let flat: Vec<f32> = rows.iter().flatten().copied().collect();
    let input = tract_ndarray::Array2::from_shape_vec((rows.len(), OBS), flat).unwrap();
    let outputs = model.run(tvec!(Tensor::from(input).into())).unwrap();
    outputs[0]
        .to_plain_array_view::<f32>()
        .unwrap()
        .iter()
        .copied()
        .collect()
}

#[test]
fn onnx_actor_matches_the_training_network_to_1e_5() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let net = ActorCritic::<f32>::new(OBS, ACT, &[256, 128], -0.5, &mut rng);
    // Statistics that are far from identity, so the normalisation matters.
    let mut norm = RunningNorm::new(OBS);
    let seen: Vec<Vec<f32>> = (0..500)
        .map(|_| {
            (0..OBS)
                .map(|j| rng.random_range(-1.0..1.0) * (j as f32 + 1.0) + j as f32)
                .collect()
        })
        .collect();
    norm.update(&seen.iter().map(|r| r.as_slice()).collect::<Vec<_>>());

    let metadata = [
        ("kumi.format".to_string(), "test".to_string()),
        ("a.first".to_string(), "1".to_string()),
    ]
    .into_iter()
    .collect();
    let bytes = encode(&actor_model(
        &norm,
        &net.actor.parameters(),
        None,
        &metadata,
    ));

    // The model declares what the format promises, metadata sorted by key.
    let decoded = tract_onnx::pb::ModelProto::decode(bytes.as_slice()).unwrap();
    assert_eq!(decoded.opset_import[0].version, OPSET);
    let keys: Vec<&str> = decoded
        .metadata_props
        .iter()
        .map(|p| p.key.as_str())
        .collect();
    assert_eq!(keys, vec!["a.first", "kumi.format"]);
    let graph = decoded.graph.unwrap();
    assert_eq!(
        (graph.input[0].name.as_str(), graph.output[0].name.as_str()),
        (INPUT, OUTPUT)
    );

    // Run it in tract (pure Rust) on a batch and compare with the training forward pass.
    let batch = 32;
    let rows = random_rows(&mut rng, batch);
    let onnx = run_in_tract(&bytes, &rows);

    let normalized: Vec<f32> = rows.iter().flat_map(|r| norm.apply(r)).collect();
    let expected = net.mean(&normalized);
    assert_eq!(onnx.len(), batch * ACT);
    let worst = onnx
        .iter()
        .zip(&expected)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0_f32, f32::max);
    assert!(
        worst <= 1e-5,
        "ONNX differs from the training network by {worst}"
    );
}

#[test]
fn restamping_replaces_one_value_keeps_the_first_and_leaves_the_graph() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let net = ActorCritic::<f32>::new(OBS, ACT, &[8], -0.5, &mut rng);
    let norm = RunningNorm::new(OBS);
    let metadata = [
        ("kumi.format".to_string(), "test".to_string()),
        ("robot".to_string(), "old".to_string()),
    ]
    .into_iter()
    .collect();
    let bytes = encode(&actor_model(
        &norm,
        &net.actor.parameters(),
        None,
        &metadata,
    ));
    let props = |b: &[u8]| {
        let m = tract_onnx::pb::ModelProto::decode(b).unwrap();
        let graph = m.graph.unwrap().encode_to_vec();
        let props: Vec<(String, String)> = m
            .metadata_props
            .into_iter()
            .map(|p| (p.key, p.value))
            .collect();
        (props, graph)
    };
    let restamp = |b: &[u8], key: &str, value: &str| {
        kumi_runtime::ModelFile::decode(b.to_vec())
            .unwrap()
            .restamp(key, value, "robot.trained")
    };
    let (once, old) = restamp(&bytes, "robot", "new").unwrap();
    assert_eq!(old, "old");
    let (twice, old) = restamp(&once, "robot", "newer").unwrap();
    assert_eq!(old, "new");
    let (before, graph) = props(&bytes);
    let (after, graph_after) = props(&twice);
    assert_eq!(graph, graph_after, "the graph is not touched");
    assert_eq!(before.len() + 1, after.len());
    let get = |k: &str| after.iter().find(|(key, _)| key == k).unwrap().1.clone();
    assert_eq!(get("robot"), "newer");
    assert_eq!(get("robot.trained"), "old", "the first value survives");
    assert_eq!(
        restamp(&bytes, "no.such.key", "x"),
        Err(kumi_runtime::MissingKey("no.such.key".into()))
    );
}

#[test]
fn a_prior_adds_the_raw_observation_times_its_matrix_to_the_network() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let net = ActorCritic::<f32>::new(OBS, ACT, &[16], -0.5, &mut rng);
    let mut norm = RunningNorm::new(OBS);
    let seen = random_rows(&mut rng, 100);
    norm.update(&seen.iter().map(|r| r.as_slice()).collect::<Vec<_>>());
    let prior: Vec<f32> = (0..OBS * ACT)
        .map(|_| rng.random_range(-2.0..2.0))
        .collect();
    let metadata = Default::default();
    let bytes = encode(&actor_model(
        &norm,
        &net.actor.parameters(),
        Some(&prior),
        &metadata,
    ));
    let batch = 8;
    let rows = random_rows(&mut rng, batch);
    let onnx = run_in_tract(&bytes, &rows);
    let normalized: Vec<f32> = rows.iter().flat_map(|r| norm.apply(r)).collect();
    let network = net.mean(&normalized);
    for (r, row) in rows.iter().enumerate() {
        for a in 0..ACT {
            let followed: f32 = (0..OBS).map(|i| row[i] * prior[i * ACT + a]).sum();
            let expected = network[r * ACT + a] + followed;
            let found = onnx[r * ACT + a];
            assert!(
                (found - expected).abs() <= 1e-4,
                "row {r}, action {a}: {found} against {expected}"
            );
        }
    }
}
