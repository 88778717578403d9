//! Every shipped mobile morphology stands on flat ground at its home pose, in every engine.

mod common;

use common::{engines, world};

/// The stability bar: 60 s of simulated time at home with wheels braked, the base drifts less
/// than 1 cm and tilts less than 1 degree; nothing sinks through the ground (deepest
/// penetration under 5 mm); every value stays finite; only wheels (and Minimal's skids) touch
/// the ground.
#[test]
fn every_morphology_stands_60_s_at_home() {
    for engine in engines() {
        for name in ["minimal", "dragon", "tricycle"] {
            let mut w = world(engine, name);
            let start = w.base_pose().translation.vector;
            let steps = (60.0 * w.config().control_hz) as usize;
            let (mut max_tilt, mut lowest, mut drift) = (0.0_f64, f64::INFINITY, 0.0_f64);
            for _ in 0..steps {
                w.step();
                max_tilt = max_tilt.max(w.base_tilt());
                lowest = lowest.min(w.lowest_collider_z());
                let moved = w.base_pose().translation.vector - start;
                drift = drift.max(moved.xy().norm());
                assert!(
                    w.joint_velocities().iter().all(|v| v.is_finite()),
                    "{engine} {name}: non-finite joint velocity at t = {}",
                    w.time()
                );
            }
            println!(
                "{engine} {name}: drift {:.2} mm, max tilt {:.3} deg, deepest {:.2} mm",
                drift * 1e3,
                max_tilt.to_degrees(),
                -lowest * 1e3
            );
            assert!(drift < 0.01, "{engine} {name}: drifted {drift} m");
            assert!(
                max_tilt < 1f64.to_radians(),
                "{engine} {name}: base tilted {} deg",
                max_tilt.to_degrees()
            );
            assert!(
                lowest > -0.005,
                "{engine} {name}: sank {lowest} m into the ground"
            );
            for link in w.ground_contacts() {
                assert!(
                    link.contains("wheel"),
                    "{engine} {name}: {link} touches the ground"
                );
            }
        }
    }
}
