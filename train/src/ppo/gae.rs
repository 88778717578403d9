//! Generalised advantage estimation (Schulman et al. 2016), as a pure function.
//!
//! Buffers are time-major: entry `t * n + i` is step `t` of environment `i`, `n` environments.

/// One rollout's inputs to GAE, each of length `T * n`.
pub struct GaeInput<'a> {
    /// Reward received after the action at step t.
    pub rewards: &'a [f32],
    /// V(s_t).
    pub values: &'a [f32],
    /// V(s_{t+1}): the value of the state the step led to. For a step that ended in a time-out
    /// this is the value of the final observation (before the reset), so the return is
    /// bootstrapped; for a true termination it is ignored.
    pub next_values: &'a [f32],
    /// The episode truly ended at this step (no future reward).
    pub terminated: &'a [bool],
    /// The episode ended at this step for any reason (termination or time-out): the next entry
    /// belongs to a new episode, so advantages do not flow back across it.
    pub ended: &'a [bool],
}

/// Advantages and returns (advantage + value), each of length `T * n`.
///
/// delta_t = r_t + gamma (1 - terminated_t) V(s_{t+1}) - V(s_t)
/// A_t     = delta_t + gamma lambda (1 - ended_t) A_{t+1}
pub fn gae(input: &GaeInput, n: usize, gamma: f32, lambda: f32) -> (Vec<f32>, Vec<f32>) {
    let len = input.rewards.len();
    assert!(
        n > 0 && len.is_multiple_of(n),
        "rollout length {len} is not a multiple of {n} environments"
    );
    for (name, l) in [
        ("values", input.values.len()),
        ("next_values", input.next_values.len()),
        ("terminated", input.terminated.len()),
        ("ended", input.ended.len()),
    ] {
        assert_eq!(l, len, "{name} has {l} entries, rewards {len}");
    }
    let steps = len / n;
    let mut advantages = vec![0.0_f32; len];
    let mut next_advantage = vec![0.0_f32; n];
    for t in (0..steps).rev() {
        for (i, next) in next_advantage.iter_mut().enumerate() {
            let k = t * n + i;
            let bootstrap = if input.terminated[k] {
                0.0
            } else {
                input.next_values[k]
            };
            let delta = input.rewards[k] + gamma * bootstrap - input.values[k];
            let carry = if input.ended[k] { 0.0 } else { *next };
            advantages[k] = delta + gamma * lambda * carry;
            *next = advantages[k];
        }
    }
    let returns = advantages
        .iter()
        .zip(input.values)
        .map(|(a, v)| a + v)
        .collect();
    (advantages, returns)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f32], b: &[f32]) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-6, "{a:?} != {b:?}");
        }
    }

    #[test]
    fn one_env_three_steps_by_hand() {
        // gamma 0.9, lambda 0.5; values 1, 2, 3; next values 2, 3, 4 (bootstrap 4 at the end).
        // delta = r + 0.9 V' - V: [1 + 1.8 - 1, 0 + 2.7 - 2, 2 + 3.6 - 3] = [1.8, 0.7, 2.6]
        // A_2 = 2.6; A_1 = 0.7 + 0.45 * 2.6 = 1.87; A_0 = 1.8 + 0.45 * 1.87 = 2.6415
        let (adv, ret) = gae(
            &GaeInput {
                rewards: &[1.0, 0.0, 2.0],
                values: &[1.0, 2.0, 3.0],
                next_values: &[2.0, 3.0, 4.0],
                terminated: &[false; 3],
                ended: &[false; 3],
            },
            1,
            0.9,
            0.5,
        );
        close(&adv, &[2.6415, 1.87, 2.6]);
        close(&ret, &[3.6415, 3.87, 5.6]);
    }

    #[test]
    fn a_time_out_bootstraps_and_a_termination_does_not() {
        // Step 0 ends by time-out with V(final obs) = 10: delta = 1 + 0.9 * 10 - 1 = 9, and no
        // advantage flows back from step 1 (a new episode). Same step as a termination: 1 - 1 = 0.
        let input = |terminated: bool| GaeInput {
            rewards: &[1.0, 5.0],
            values: &[1.0, 0.0],
            next_values: &[10.0, 0.0],
            terminated: if terminated {
                &[true, false]
            } else {
                &[false, false]
            },
            ended: &[true, false],
        };
        let (adv, _) = gae(&input(false), 1, 0.9, 0.5);
        close(&adv, &[9.0, 5.0]);
        let (adv, _) = gae(&input(true), 1, 0.9, 0.5);
        close(&adv, &[0.0, 5.0]);
    }

    #[test]
    fn environments_are_independent_in_time_major_layout() {
        // Two environments, two steps: [t0 e0, t0 e1, t1 e0, t1 e1]; gamma = lambda = 1.
        // e0 rewards 1, 1 -> A = [2, 1]; e1 rewards 0, 3 -> A = [3, 3].
        let (adv, _) = gae(
            &GaeInput {
                rewards: &[1.0, 0.0, 1.0, 3.0],
                values: &[0.0; 4],
                next_values: &[0.0; 4],
                terminated: &[false; 4],
                ended: &[false; 4],
            },
            2,
            1.0,
            1.0,
        );
        close(&adv, &[2.0, 3.0, 1.0, 3.0]);
    }
}
