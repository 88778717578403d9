//! Random joint targets within limits for 60 s: no NaN, no explosion.

mod common;

use common::{engines, random_commands, world, Rng};

/// Joint speed bound [rad/s]. Set-points slew at 1.5 rad/s and wheels turn at up to 5 rad/s,
/// but fully random targets tip the mobile robots over (and the fixed arm into the floor), and
/// impacts while tumbling peak at 11 (arm), 16 (Minimal), 19 (Dragon) and 24 (Tricycle) rad/s
/// with these seeds. A blown-up simulation reaches thousands of rad/s or NaN within steps.
const MAX_JOINT_SPEED: f64 = 100.0;
/// Base speed bound [m/s]: wheels drive at up to 1.35 m/s; a base falling from Tricycle's
/// 2.5 m reaches 7 m/s.
const MAX_BASE_SPEED: f64 = 10.0;

#[test]
fn random_targets_for_60_s_stay_finite_and_bounded() {
    for (seed, (engine, name)) in engines()
        .into_iter()
        .flat_map(|e| ["arm", "minimal", "dragon", "tricycle"].map(|n| (e, n)))
        .enumerate()
    {
        let mut w = world(engine, name);
        let mut rng = Rng::new(seed as u64 + 1);
        let steps = (60.0 * w.config().control_hz) as usize;
        for k in 0..steps {
            // A new random command every second.
            if k % 30 == 0 {
                random_commands(w.as_mut(), &mut rng);
            }
            w.step();
            let v = w.joint_velocities();
            let worst = v.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
            assert!(
                worst.is_finite() && worst < MAX_JOINT_SPEED,
                "{engine} {name}: joint speed {worst} rad/s at t = {:.2} s",
                w.time()
            );
            let (lin, _) = w.base_twist_w();
            assert!(
                lin.norm().is_finite() && lin.norm() < MAX_BASE_SPEED,
                "{engine} {name}: base speed {} m/s at t = {:.2} s",
                lin.norm(),
                w.time()
            );
            assert!(w.joint_positions().iter().all(|q| q.is_finite()));
            assert!(
                !w.diverged(),
                "{engine} {name}: the physics diverged at t = {:.2} s",
                w.time()
            );
        }
    }
}
