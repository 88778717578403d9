//! Runs an exported skill policy: reads the ONNX file, checks its metadata and its input and
//! output shapes against the module it is asked to drive (a mismatch is an error, never a
//! silently wrong layout), then infers with one of two backends:
//!
//! - [`Backend::OnnxRuntime`]: ONNX Runtime through `ort`, loaded at run time from the shared
//!   library named by `ORT_DYLIB_PATH` (the PyPI `onnxruntime` wheel ships it as
//!   `onnxruntime/capi/libonnxruntime.so.<version>`);
//! - [`Backend::Tract`]: tract, pure Rust, always available.
//!
//! [`BackendChoice::Auto`] takes ONNX Runtime when `ORT_DYLIB_PATH` is set and tract otherwise.

mod model_file;
mod onnxruntime;
mod policy;
mod tract;

pub use model_file::{MissingKey, ModelFile, TensorShape};
pub use onnxruntime::{ort_library_from_env, ORT_DYLIB_PATH};
pub use policy::{Backend, BackendChoice, Network, RuntimeError, SkillPolicy, WholeBodyPolicy};

/// The folder of the shipped policies, `policies/` in the source tree: one folder per policy
/// (`policies/<name>/`: the ONNX file, its model card `README.md`, its learning curve
/// `metrics.csv`).
pub fn shipped_policies_dir() -> std::path::PathBuf {
    let runtime_crate = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    runtime_crate
        .parent()
        .unwrap_or(runtime_crate)
        .to_path_buf()
}

/// The shipped policy called `name` (`arm_reach`, `<robot>_whole_body`, `<robot>_flat`, ...),
/// `policies/<name>/<name>.onnx` in the source tree.
pub fn shipped_policy(name: &str) -> std::path::PathBuf {
    shipped_policies_dir()
        .join(name)
        .join(format!("{name}.onnx"))
}

/// The shipped low-level skill, `policies/arm_reach/arm_reach.onnx` in the source tree.
pub fn shipped_arm_policy() -> std::path::PathBuf {
    shipped_policy("arm_reach")
}

/// The shipped whole-body policy of a robot,
/// `policies/<robot>_whole_body/<robot>_whole_body.onnx` in the source tree.
pub fn shipped_whole_body_policy(robot: &str) -> std::path::PathBuf {
    shipped_policy(&format!("{robot}_whole_body"))
}
