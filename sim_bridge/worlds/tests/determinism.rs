//! Same seed and commands give bit-identical trajectories; resets and snapshots reproduce them.
//! Within each engine (the engines differ from each other; see `cross_engine.rs`).

mod common;

use common::{engines, random_commands, state_bits, world, Rng};
use kumi_worlds::SimWorld;
use nalgebra::Vector3;

/// Runs `steps` control steps of seeded random commands and records every state.
fn trajectory(w: &mut dyn SimWorld, seed: u64, steps: usize) -> Vec<Vec<u64>> {
    let mut rng = Rng::new(seed);
    (0..steps)
        .map(|k| {
            if k % 10 == 0 {
                random_commands(w, &mut rng);
            }
            w.step();
            state_bits(w)
        })
        .collect()
}

#[test]
fn same_seed_same_commands_give_bit_identical_trajectories() {
    for engine in engines() {
        for name in ["arm", "minimal", "dragon", "tricycle"] {
            let a = trajectory(world(engine, name).as_mut(), 7, 90);
            let b = trajectory(world(engine, name).as_mut(), 7, 90);
            assert_eq!(a, b, "{engine} {name}: two fresh worlds diverged");
            let c = trajectory(world(engine, name).as_mut(), 8, 90);
            assert_ne!(
                a, c,
                "{engine} {name}: a different seed must change the trajectory"
            );
        }
    }
}

#[test]
fn reset_in_place_reproduces_a_fresh_world_bit_for_bit() {
    for engine in engines() {
        for name in ["arm", "minimal", "dragon", "tricycle"] {
            let fresh = trajectory(world(engine, name).as_mut(), 3, 60);
            let mut w = world(engine, name);
            // Dirty the world: drive it around, then reset to home.
            trajectory(w.as_mut(), 99, 45);
            let home = w.home_state();
            w.reset(&home);
            assert_eq!(w.time(), 0.0);
            let replay = trajectory(w.as_mut(), 3, 60);
            assert_eq!(
                fresh, replay,
                "{engine} {name}: reset world diverged from a fresh one"
            );
        }
    }
}

#[test]
fn reset_to_another_configuration_matches_a_fresh_world_reset_there() {
    for engine in engines() {
        let mut a = world(engine, "tricycle");
        let mut b = world(engine, "tricycle");
        trajectory(b.as_mut(), 5, 30);
        let mut q = a.home_state().joint_positions;
        q[1] += 0.3; // arm0/joint2
        let state = a.standing_state(0.4, -0.2, 1.0, q);
        a.reset(&state);
        b.reset(&state);
        let base = a.base_pose().translation.vector;
        assert!(
            (base.x - 0.4).abs() < 1e-6 && (base.y + 0.2).abs() < 1e-6,
            "{engine}: {base}"
        );
        assert!((a.joint_positions()[1] - state.joint_positions[1]).abs() < 1e-6);
        assert_eq!(
            trajectory(a.as_mut(), 11, 45),
            trajectory(b.as_mut(), 11, 45),
            "{engine}"
        );
    }
}

#[test]
fn restoring_a_snapshot_replays_bit_for_bit() {
    for engine in engines() {
        for name in ["arm", "dragon"] {
            let mut w = world(engine, name);
            trajectory(w.as_mut(), 1, 30);
            let snapshot = w.snapshot();
            let first = trajectory(w.as_mut(), 2, 45);
            w.restore(&snapshot).unwrap();
            let second = trajectory(w.as_mut(), 2, 45);
            assert_eq!(first, second, "{engine} {name}");
        }
    }
}

#[test]
fn a_snapshot_taken_before_a_blow_up_restores_a_sound_world() {
    // MuJoCo flags a blow-up by a warning count that its state leaves alone: a restore that
    // kept it called every replayed start diverged on its first step. Rapier flags one by the
    // engines' shared bounds (`kumi_worlds::blown_up`), checked after every control step.
    for engine in engines() {
        let mut w = world(engine, "minimal");
        trajectory(w.as_mut(), 1, 30);
        let snapshot = w.snapshot();
        let first = trajectory(w.as_mut(), 2, 45);
        w.restore(&snapshot).unwrap();
        let absurd = Vector3::new(1e15, -1e15, 1e15);
        w.push(&absurd, &absurd);
        w.step();
        assert!(w.diverged(), "{engine}: an absurd shove did not blow up");
        w.restore(&snapshot).unwrap();
        assert!(!w.diverged(), "{engine}: restored, still diverged");
        let second = trajectory(w.as_mut(), 2, 45);
        assert!(!w.diverged(), "{engine}: diverged after a restore");
        assert_eq!(first, second, "{engine}");
    }
}

#[test]
fn a_snapshot_of_another_world_is_refused() {
    // The snapshot outlives its world, and the next world is built right after: a check by the
    // model's address once took another robot's model at the same address for the same robot
    // (CI: a Dragon world restored an arm's 7 servo states into its 18 and panicked). Several
    // rounds, so that an allocator that reuses the address would show it.
    for _ in 0..5 {
        for a in engines() {
            for b in engines() {
                let snapshot = world(a, "arm").snapshot();
                let mut other = world(b, if a == b { "dragon" } else { "arm" });
                assert!(
                    other.restore(&snapshot).is_err(),
                    "{b} accepted a snapshot of {a}"
                );
            }
        }
    }
}

/// CI (`.ci/run`, with `KUMI_REQUIRE_MUJOCO=1`) builds MuJoCo in: every parity test above then
/// runs in both engines, and this fails if the build lost it.
#[test]
fn engines_under_test() {
    let engines = engines();
    println!("engines under test: {engines:?}");
    assert_eq!(engines[0], kumi_worlds::Engine::Rapier);
    if std::env::var_os("KUMI_REQUIRE_MUJOCO").is_some_and(|v| v == "1") {
        assert!(
            engines.contains(&kumi_worlds::Engine::Mujoco),
            "KUMI_REQUIRE_MUJOCO=1 but this build has no MuJoCo: {}",
            kumi_worlds::MUJOCO_INSTALL_HINT
        );
    }
}
