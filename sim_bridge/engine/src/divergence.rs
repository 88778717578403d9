//! When a world's physics has blown up: the rule both engines apply after every control step
//! (rapier also before each physics substep).
//!
//! MuJoCo notices its own blow-ups (positions, velocities or accelerations past 1e10 or not
//! finite: its `mjMAXVAL`), and restarts from its initial state; rapier notices none. A rapier
//! world that blew up once gave a training batch rewards summing to -3.6e20 (joint speeds of the
//! order of 1e12 rad/s through the joint-speed penalty) while a Tricycle policy trained in it
//! (`docs/notebook/tricycle_whole_body_runs.md`). Long before 1e10, a state is not one these
//! robots can be in: the bounds below sit far above any speed their modules reach, so that a
//! world that passes them is taken as lost.

use nalgebra::Vector3;

/// A joint or the base turning faster than this [rad/s] means the physics blew up. The
/// fastest joints are the wheels, commanded at most 5 rad/s; a robot tipping over turns its
/// base at a few rad/s.
pub const BLOWN_UP_RATE_RAD_S: f64 = 1e3;

/// The base moving faster than this [m/s] means the physics blew up: a fall from the tallest
/// robot's 2.5 m lands at 7 m/s, and the wheels drive it at under 1 m/s.
pub const BLOWN_UP_SPEED_M_S: f64 = 1e2;

/// Whether a state is past what sound physics of these robots gives: a joint or the base
/// turning faster than [`BLOWN_UP_RATE_RAD_S`], the base moving faster than
/// [`BLOWN_UP_SPEED_M_S`], or any of these values or the base's position [m] not finite. Speeds
/// and the position are in the world frame.
pub fn blown_up(
    joint_velocities_rad_s: &[f64],
    base_position_w_m: &Vector3<f64>,
    base_linear_velocity_w_m_s: &Vector3<f64>,
    base_angular_velocity_w_rad_s: &Vector3<f64>,
) -> bool {
    // Within a bound only if finite and below it: NaN fails both.
    let within = |x: f64, bound: f64| x.is_finite() && x.abs() < bound;
    let joint_too_fast = !joint_velocities_rad_s
        .iter()
        .all(|&v| within(v, BLOWN_UP_RATE_RAD_S));
    let base_lost = !base_position_w_m.iter().all(|x| x.is_finite());
    let base_too_fast = !within(base_linear_velocity_w_m_s.norm(), BLOWN_UP_SPEED_M_S)
        || !within(base_angular_velocity_w_rad_s.norm(), BLOWN_UP_RATE_RAD_S);
    joint_too_fast || base_lost || base_too_fast
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(joints: &[f64], position: [f64; 3], linear: [f64; 3], angular: [f64; 3]) -> bool {
        blown_up(
            joints,
            &Vector3::from(position),
            &Vector3::from(linear),
            &Vector3::from(angular),
        )
    }

    #[test]
    fn a_robot_driving_and_tipping_over_is_sound() {
        assert!(!check(
            &[5.0, -5.0, 3.0, 0.0],
            [100.0, -40.0, 1.2],
            [0.9, 0.3, -7.0],
            [4.0, -2.0, 1.0]
        ));
    }

    #[test]
    fn each_bound_and_each_non_finite_value_is_a_blow_up() {
        let sound = (
            [1.0, -1.0],
            [0.0, 0.0, 1.0],
            [0.5, 0.0, 0.0],
            [0.0, 0.0, 1.0],
        );
        let (j, p, l, a) = sound;
        assert!(check(&[1.0, -1e3], p, l, a), "a joint at the rate bound");
        assert!(check(&[1.0, f64::NAN], p, l, a), "a NaN joint speed");
        assert!(check(&j, [0.0, f64::INFINITY, 1.0], l, a), "the base lost");
        assert!(
            check(&j, [0.0, 0.0, f64::NAN], l, a),
            "the base's height NaN"
        );
        assert!(check(&j, p, [60.0, 0.0, -80.0], a), "the base at 100 m/s");
        assert!(check(&j, p, [f64::NAN, 0.0, 0.0], a), "a NaN base velocity");
        assert!(
            check(&j, p, l, [0.0, 0.0, 1e3]),
            "the base turning at the bound"
        );
        assert!(check(&j, p, l, [0.0, f64::NAN, 0.0]), "a NaN base rate");
        assert!(!check(&j, p, l, a), "the sound state itself");
    }

    #[test]
    fn a_robot_without_joints_is_judged_by_its_base() {
        assert!(!check(&[], [0.0, 0.0, 0.5], [0.1, 0.0, 0.0], [0.0; 3]));
        assert!(check(&[], [0.0, 0.0, 0.5], [1e12, 0.0, 0.0], [0.0; 3]));
    }
}
