//! ONNX export of a trained policy: the deterministic actor (its mean action), with the
//! observation normalisation in the graph, as a standard ONNX model (IR 8, opset 17) whose
//! `metadata_props` describe how to feed it.
//!
//! Graph: `observation [batch, O]` -> Sub(mean) -> Div(std) -> (Gemm -> Elu)* -> Gemm ->
//! `action [batch, A]`, the same arithmetic as training (see [`crate::ppo::network::Mlp`]).

use prost::Message;
use tract_onnx::pb::attribute_proto::AttributeType;
use tract_onnx::pb::tensor_proto::DataType;
use tract_onnx::pb::tensor_shape_proto::{dimension, Dimension};
use tract_onnx::pb::type_proto::{Tensor as TensorType, Value};
use tract_onnx::pb::{
    AttributeProto, GraphProto, ModelProto, NodeProto, OperatorSetIdProto, StringStringEntryProto,
    TensorProto, TensorShapeProto, TypeProto, ValueInfoProto,
};

use crate::ppo::network::DenseParameters;
use crate::ppo::normalizer::RunningNorm;

/// Name of the graph's input.
pub const INPUT: &str = "observation";
/// Name of the graph's output.
pub const OUTPUT: &str = "action";
/// ONNX IR version written.
pub const IR_VERSION: i64 = 8;
/// ONNX operator set written.
pub const OPSET: i64 = 17;

fn tensor(name: &str, dims: &[i64], values: Vec<f32>) -> TensorProto {
    TensorProto {
        name: name.to_string(),
        dims: dims.to_vec(),
        data_type: DataType::Float as i32,
        float_data: values,
        ..Default::default()
    }
}

fn value_info(name: &str, width: usize) -> ValueInfoProto {
    let dim = |value| Dimension {
        value: Some(value),
        ..Default::default()
    };
    ValueInfoProto {
        name: name.to_string(),
        r#type: Some(TypeProto {
            value: Some(Value::TensorType(TensorType {
                elem_type: DataType::Float as i32,
                shape: Some(TensorShapeProto {
                    dim: vec![
                        dim(dimension::Value::DimParam("batch".into())),
                        dim(dimension::Value::DimValue(width as i64)),
                    ],
                }),
            })),
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn node(
    op: &str,
    name: &str,
    inputs: &[&str],
    output: &str,
    attributes: Vec<AttributeProto>,
) -> NodeProto {
    NodeProto {
        op_type: op.to_string(),
        name: name.to_string(),
        input: inputs.iter().map(|s| s.to_string()).collect(),
        output: vec![output.to_string()],
        attribute: attributes,
        ..Default::default()
    }
}

/// The actor as an ONNX model. `prior`, when given, is a matrix [observation][action]
/// (row-major) whose product with the raw observation is added to the network's output (a
/// skill's step follower, [`crate::arm_reach::step_prior`]). `metadata` becomes
/// `metadata_props` (sorted by key).
pub fn actor_model(
    norm: &RunningNorm,
    layers: &[DenseParameters],
    prior: Option<&[f32]>,
    metadata: &std::collections::BTreeMap<String, String>,
) -> ModelProto {
    let obs_dim = norm.mean.len();
    assert_eq!(
        layers.first().map(|l| l.inputs),
        Some(obs_dim),
        "the normaliser's width is the actor's input (Trainer::actor_norm)"
    );
    let mut initializer = vec![
        tensor(
            "obs_mean",
            &[obs_dim as i64],
            norm.mean.iter().map(|m| *m as f32).collect(),
        ),
        tensor(
            "obs_std",
            &[obs_dim as i64],
            (0..obs_dim).map(|j| norm.std(j) as f32).collect(),
        ),
    ];
    let mut nodes = vec![
        node("Sub", "center", &[INPUT, "obs_mean"], "centered", vec![]),
        node("Div", "scale", &["centered", "obs_std"], "h0", vec![]),
    ];
    let mut current = "h0".to_string();
    for (k, layer) in layers.iter().enumerate() {
        let (w, b) = (format!("w{k}"), format!("b{k}"));
        initializer.push(tensor(
            &w,
            &[layer.outputs as i64, layer.inputs as i64],
            layer.weight.clone(),
        ));
        initializer.push(tensor(&b, &[layer.outputs as i64], layer.bias.clone()));
        let last = k + 1 == layers.len();
        let linear = match (last, prior) {
            (true, None) => OUTPUT.to_string(),
            (true, Some(_)) => "network".to_string(),
            (false, _) => format!("z{k}"),
        };
        let trans_b = AttributeProto {
            name: "transB".into(),
            r#type: AttributeType::Int as i32,
            i: 1,
            ..Default::default()
        };
        nodes.push(node(
            "Gemm",
            &format!("dense{k}"),
            &[&current, &w, &b],
            &linear,
            vec![trans_b],
        ));
        if !last {
            let alpha = AttributeProto {
                name: "alpha".into(),
                r#type: AttributeType::Float as i32,
                f: 1.0,
                ..Default::default()
            };
            let activated = format!("h{}", k + 1);
            nodes.push(node(
                "Elu",
                &format!("elu{k}"),
                &[&linear],
                &activated,
                vec![alpha],
            ));
            current = activated;
        }
    }
    let action_dim = layers.last().map_or(0, |l| l.outputs);
    if let Some(prior) = prior {
        assert_eq!(
            prior.len(),
            obs_dim * action_dim,
            "the prior is [observation][action]"
        );
        initializer.push(tensor(
            "prior",
            &[obs_dim as i64, action_dim as i64],
            prior.to_vec(),
        ));
        nodes.push(node(
            "MatMul",
            "follower",
            &[INPUT, "prior"],
            "followed",
            vec![],
        ));
        nodes.push(node(
            "Add",
            "residual",
            &["network", "followed"],
            OUTPUT,
            vec![],
        ));
    }
    let props: Vec<StringStringEntryProto> = metadata
        .iter()
        .map(|(k, v)| StringStringEntryProto {
            key: k.clone(),
            value: v.clone(),
        })
        .collect();
    ModelProto {
        ir_version: IR_VERSION,
        opset_import: vec![OperatorSetIdProto {
            domain: String::new(),
            version: OPSET,
        }],
        producer_name: "kumi".into(),
        producer_version: env!("CARGO_PKG_VERSION").into(),
        graph: Some(GraphProto {
            name: "kumi_actor".into(),
            node: nodes,
            initializer,
            input: vec![value_info(INPUT, obs_dim)],
            output: vec![value_info(OUTPUT, action_dim)],
            ..Default::default()
        }),
        metadata_props: props,
        ..Default::default()
    }
}

/// The model as ONNX bytes.
pub fn encode(model: &ModelProto) -> Vec<u8> {
    model.encode_to_vec()
}
