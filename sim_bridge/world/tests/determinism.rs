//! Same seed and commands give bit-identical trajectories; resets and snapshots reproduce them.

mod common;

use common::{model, random_commands, state_bits, world, Rng};
use kumi_sim::{SimConfig, World};

/// Runs `steps` control steps of seeded random commands and records every state.
fn trajectory(w: &mut World, seed: u64, steps: usize) -> Vec<Vec<u64>> {
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
    for name in ["arm", "tricycle"] {
        let a = trajectory(&mut world(name), 7, 90);
        let b = trajectory(&mut world(name), 7, 90);
        assert_eq!(a, b, "{name}: two fresh worlds diverged");
        let c = trajectory(&mut world(name), 8, 90);
        assert_ne!(a, c, "{name}: a different seed must change the trajectory");
    }
}

#[test]
fn reset_in_place_reproduces_a_fresh_world_bit_for_bit() {
    for name in ["arm", "dragon", "tricycle"] {
        let fresh = trajectory(&mut world(name), 3, 60);
        let mut w = world(name);
        // Dirty the world: drive it around, then reset to home.
        trajectory(&mut w, 99, 45);
        let home = w.home_state();
        w.reset(&home);
        assert_eq!(w.time(), 0.0);
        let replay = trajectory(&mut w, 3, 60);
        assert_eq!(
            fresh, replay,
            "{name}: reset world diverged from a fresh one"
        );
    }
}

#[test]
fn reset_to_another_configuration_matches_a_fresh_world_reset_there() {
    let mut a = world("tricycle");
    let mut b = world("tricycle");
    trajectory(&mut b, 5, 30);
    let mut q = a.home_state().joint_positions;
    q[1] += 0.3; // arm0/joint2
    let state = a.standing_state(0.4, -0.2, 1.0, q);
    a.reset(&state);
    b.reset(&state);
    let base = a.base_pose().translation.vector;
    assert!(
        (base.x - 0.4).abs() < 1e-6 && (base.y + 0.2).abs() < 1e-6,
        "{base}"
    );
    assert!((a.joint_positions()[1] - state.joint_positions[1]).abs() < 1e-6);
    assert_eq!(trajectory(&mut a, 11, 45), trajectory(&mut b, 11, 45));
}

#[test]
fn restoring_a_snapshot_replays_bit_for_bit() {
    let model = model("dragon");
    let mut w = World::new(model.clone(), SimConfig::for_model(&model)).unwrap();
    trajectory(&mut w, 1, 30);
    let snapshot = w.snapshot();
    let first = trajectory(&mut w, 2, 45);
    w.restore(&snapshot);
    let second = trajectory(&mut w, 2, 45);
    assert_eq!(first, second);
}
