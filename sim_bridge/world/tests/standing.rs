//! Every shipped morphology stands on flat ground at its home pose.

mod common;

use common::world;

/// 60 s of simulated time at home: tilt stays under 0.1 rad, nothing sinks through the ground
/// (deepest penetration under 5 mm), every value stays finite.
#[test]
fn every_morphology_stands_60_s_at_home() {
    for name in ["minimal", "dragon", "tricycle"] {
        let mut w = world(name);
        let steps = (60.0 * w.config().control_hz) as usize;
        let (mut max_tilt, mut lowest) = (0.0_f64, f64::INFINITY);
        for _ in 0..steps {
            w.step();
            max_tilt = max_tilt.max(w.base_tilt());
            lowest = lowest.min(w.lowest_collider_z());
            assert!(
                w.joint_velocities().iter().all(|v| v.is_finite()),
                "{name}: non-finite joint velocity at t = {}",
                w.time()
            );
        }
        assert!(max_tilt < 0.1, "{name}: base tilted {max_tilt} rad");
        assert!(lowest > -0.005, "{name}: sank {lowest} m into the ground");
        // It is standing on its wheels (and Minimal's skids), nothing else.
        for link in w.ground_contacts() {
            assert!(link.contains("wheel"), "{name}: {link} touches the ground");
        }
    }
}

/// Each articulation layout builds Dragon; a single multibody keeps its mounts exactly rigid,
/// while per-module impulse-joint mounts flex a little under load.
#[test]
fn layouts_articulate_mounts_as_documented() {
    use kumi_sim::{Layout, SimConfig, World};
    let model = common::model("dragon");
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
