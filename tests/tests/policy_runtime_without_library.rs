//! Without `ORT_DYLIB_PATH`, asking for ONNX Runtime is a clear error and `auto` falls back to
//! tract. (Its own process: ONNX Runtime is loaded at most once per process.)

use kumi_policies::skill::ArmSkill;
use kumi_runtime::{Backend, BackendChoice, SkillPolicy};

#[test]
fn onnxruntime_without_its_library_is_a_clear_error() {
    std::env::remove_var("ORT_DYLIB_PATH");
    let model = kumi_tests::shipped_model("arm");
    let skill = ArmSkill::new(&model.modules[0], 30.0).unwrap();
    let shipped = kumi_runtime::shipped_arm_policy();

    let err = SkillPolicy::load(&shipped, &skill, BackendChoice::OnnxRuntime).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("onnxruntime cannot load the model"), "{text}");
    assert!(text.contains("ORT_DYLIB_PATH is not set"), "{text}");

    assert_eq!(BackendChoice::Auto.resolve(), Backend::Tract);
    let policy = SkillPolicy::load(&shipped, &skill, BackendChoice::Auto).unwrap();
    assert_eq!(policy.backend(), Backend::Tract);
}
