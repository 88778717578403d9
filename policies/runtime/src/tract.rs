//! The pure-Rust backend: tract, with the model optimised for a batch of one.

use tract_onnx::prelude::*;

use crate::policy::Infer;

pub(crate) struct TractEngine {
    plan: Arc<TypedRunnableModel>,
    input_dim: usize,
}

impl TractEngine {
    pub(crate) fn new(bytes: &[u8], input_dim: usize) -> TractResult<Self> {
        let plan = tract_onnx::onnx()
            .model_for_read(&mut &bytes[..])?
            .with_input_fact(0, f32::fact([1, input_dim]).into())?
            .into_optimized()?
            .into_runnable()?;
        Ok(Self { plan, input_dim })
    }
}

impl Infer for TractEngine {
    fn infer(&mut self, observation: &[f32]) -> Result<Vec<f32>, String> {
        let input =
            Tensor::from_shape(&[1, self.input_dim], observation).map_err(|e| e.to_string())?;
        let outputs = self
            .plan
            .run(tvec!(input.into()))
            .map_err(|e| e.to_string())?;
        let view = outputs[0]
            .to_plain_array_view::<f32>()
            .map_err(|e| e.to_string())?;
        Ok(view.iter().copied().collect())
    }
}
