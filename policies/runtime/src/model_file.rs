//! What the runtime reads from an ONNX file before running it: its metadata and the shapes of
//! its single input and output.

use std::collections::BTreeMap;

use prost::Message;
use tract_onnx::pb::tensor_shape_proto::dimension::Value as Dim;
use tract_onnx::pb::type_proto::Value;
use tract_onnx::pb::{ModelProto, StringStringEntryProto, ValueInfoProto};

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

    /// The file's bytes with the metadata value of `key` replaced by `value`, the replaced value
    /// kept under `record_key` unless that key is already there (so the first value survives
    /// any number of re-stamps: `kumi policy restamp`). Returns the new bytes and the replaced
    /// value; the graph is not touched.
    pub fn restamp(
        &self,
        key: &str,
        value: &str,
        record_key: &str,
    ) -> Result<(Vec<u8>, String), MissingKey> {
        let mut model =
            ModelProto::decode(self.bytes.as_slice()).expect("decoded once by ModelFile::decode");
        let entry = model
            .metadata_props
            .iter_mut()
            .find(|p| p.key == key)
            .ok_or_else(|| MissingKey(key.to_string()))?;
        let old = std::mem::replace(&mut entry.value, value.to_string());
        if !model.metadata_props.iter().any(|p| p.key == record_key) {
            model.metadata_props.push(StringStringEntryProto {
                key: record_key.to_string(),
                value: old.clone(),
            });
        }
        Ok((model.encode_to_vec(), old))
    }
}

/// A metadata key a file does not have.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("its metadata has no `{0}`")]
pub struct MissingKey(pub String);
