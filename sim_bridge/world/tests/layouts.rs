//! rapier's articulation layouts.

use std::sync::Arc;

use kumi_model::{assemble, load_morphology, ModuleLibrary};

/// Each articulation layout builds Dragon; a single multibody keeps its mounts exactly rigid,
/// while per-module impulse-joint mounts flex a little under load.
#[test]
fn layouts_articulate_mounts_as_documented() {
    use kumi_sim::{Layout, SimConfig, SimWorld, World};
    let library = ModuleLibrary::shipped();
    let model = Arc::new(assemble(
        &load_morphology("dragon", &library).unwrap(),
        &library,
    ));
    for layout in Layout::ALL {
        let config = SimConfig {
            layout,
            ..SimConfig::for_model(&model)
        };
        let mut w = World::new(model.clone(), config).unwrap();
        for _ in 0..30 {
            w.step();
        }
        let worst = w
            .mount_errors()
            .iter()
            .fold(0.0_f64, |a, (_, m, r)| a.max(*m).max(*r));
        match layout {
            Layout::SingleMultibody => assert!(worst < 1e-5, "{layout:?}: mounts moved {worst}"),
            Layout::PerModule => {
                assert!(worst > 1e-7, "{layout:?}: impulse mounts cannot be exact")
            }
            Layout::PerLimb => assert!(worst < 0.01, "{layout:?}: mounts flexed {worst}"),
        }
        assert!(w.base_tilt() < 0.1, "{layout:?}: tilted {}", w.base_tilt());
    }
}
