//! What the runtime reads from an ONNX file before running it: its metadata and the shapes of
//! its single input and output.

use std::collections::BTreeMap;

use prost::Message;
use tract_onnx::pb::tensor_shape_proto::dimension::Value as Dim;
use tract_onnx::pb::type_proto::Value;
use tract_onnx::pb::{ModelProto, ValueInfoProto};

/// A tensor shape from the file: `None` for a symbolic (dynamic) dimension.
pub type TensorShape = Vec<Option<i64>>;

/// An ONNX model file, decoded enough to be checked.
#[derive(Debug, Clone)]
pub struct ModelFile {
    pub bytes: Vec<u8>,
    pub metadata: BTreeMap<String, String>,
    /// Name and shape of each graph input and output.
    pub inputs: Vec<(String, TensorShape)>,
    pub outputs: Vec<(String, TensorShape)>,
}

fn shape(info: &ValueInfoProto) -> TensorShape {
    match info.r#type.as_ref().and_then(|t| t.value.as_ref()) {
        Some(Value::TensorType(t)) => t
            .shape
            .as_ref()
            .map(|s| {
                s.dim
                    .iter()
                    .map(|d| match d.value {
                        Some(Dim::DimValue(v)) => Some(v),
                        _ => None,
                    })
                    .collect()
            })
            .unwrap_or_default(),
        _ => Vec::new(),
    }
}

impl ModelFile {
    /// Decodes `bytes` as an ONNX model. The error is the protobuf decoder's message.
    pub fn decode(bytes: Vec<u8>) -> Result<Self, String> {
        let model = ModelProto::decode(bytes.as_slice()).map_err(|e| e.to_string())?;
        let graph = model.graph.as_ref().ok_or("the model has no graph")?;
        // Initialisers may also be listed as inputs (IR < 4); they are not fed.
        let fed: Vec<&ValueInfoProto> = graph
            .input
            .iter()
            .filter(|i| !graph.initializer.iter().any(|t| t.name == i.name))
            .collect();
        Ok(Self {
            metadata: model
                .metadata_props
                .iter()
                .map(|p| (p.key.clone(), p.value.clone()))
                .collect(),
            inputs: fed.iter().map(|i| (i.name.clone(), shape(i))).collect(),
            outputs: graph
                .output
                .iter()
                .map(|o| (o.name.clone(), shape(o)))
                .collect(),
            bytes,
        })
    }
}
