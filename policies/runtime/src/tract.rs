//! The pure-Rust backend: tract, with the model optimised for each batch size it meets (one
//! plan per size, built on first use).

use std::collections::HashMap;

use tract_onnx::prelude::*;

use crate::policy::Infer;

pub(crate) struct TractEngine {
    bytes: Vec<u8>,
    plans: HashMap<usize, Arc<TypedRunnableModel>>,
    input_dim: usize,
}

impl TractEngine {
    /// Checks that tract can run the model (for a batch of one).
    pub(crate) fn new(bytes: &[u8], input_dim: usize) -> TractResult<Self> {
        let mut engine = Self {
            bytes: bytes.to_vec(),
            plans: HashMap::new(),
            input_dim,
        };
        engine.plan(1)?;
        Ok(engine)
    }

    fn plan(&mut self, rows: usize) -> TractResult<Arc<TypedRunnableModel>> {
        if let Some(plan) = self.plans.get(&rows) {
            return Ok(plan.clone());
        }
        let plan = tract_onnx::onnx()
            .model_for_read(&mut &self.bytes[..])?
            .with_input_fact(0, f32::fact([rows, self.input_dim]).into())?
            .into_optimized()?
            .into_runnable()?;
        self.plans.insert(rows, plan.clone());
        Ok(plan)
    }
}

impl Infer for TractEngine {
    fn infer(&mut self, input: &[f32], rows: usize) -> Result<Vec<f32>, String> {
        let plan = self.plan(rows).map_err(|e| e.to_string())?;
        let input =
            Tensor::from_shape(&[rows, self.input_dim], input).map_err(|e| e.to_string())?;
        let outputs = plan.run(tvec!(input.into())).map_err(|e| e.to_string())?;
        let view = outputs[0]
            .to_plain_array_view::<f32>()
            .map_err(|e| e.to_string())?;
        Ok(view.iter().copied().collect())
    }
}
