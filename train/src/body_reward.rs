//! The upper-level reward (the paper's Table IV) and termination, as pure functions.
//!
//! r = w_p1 (1 - tanh(d / 2)) + w_p2 (1 - tanh(d / 0.2)) - w_o |theta_h|
//!     - w_v |qd|^2 - w_a |a_t - a_{t-1}|^2 + alive
//!
//! where d is the tool-to-target distance [m], theta_h the yaw error [rad], qd the arm joints'
//! velocities [rad/s] (wheels excluded: driving is the task) and a the policy's actions.

/// Table IV's scales [m] of the coarse and the close-range position terms.
pub const COARSE_SCALE_M: f64 = 2.0;
pub const CLOSE_SCALE_M: f64 = 0.2;

/// Weights of the upper-level reward (the paper gives the terms, not the weights).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct BodyWeights {
    pub w_p1: f64,
    pub w_p2: f64,
    /// Yaw error penalty [1/rad].
    pub w_o: f64,
    /// Arm joint velocity penalty [1/(rad/s)^2].
    pub w_v: f64,
    /// Action-rate penalty (policy units).
    pub w_a: f64,
    /// Reward per step for staying up (the paper: 0.2 for Minimal, none for the others).
    pub alive: f64,
    /// Penalty on the step the base tilts past the limit (kumi's; the paper has none). Absent
    /// in a config: 0, and left out of the serialised config, so older policies' config
    /// fingerprints still hold.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub fall: f64,
    /// Base tilt penalty `-tilt * sin^2(tilt angle)` per step: the squared horizontal part of
    /// gravity in the base frame (Isaac Lab's `flat_orientation_l2`; kumi's, the paper has
    /// none). It costs a robot that starts to tip before the tilt limit ends the episode.
    /// Absent in a config: 0, and left out of the serialised config like `fall`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub tilt: f64,
    /// Turn penalty `-turn * (|v_xy| * |w_z|)^2` per step [1/(m/s^2)^2]: the base's horizontal
    /// speed [m/s] times its yaw rate [rad/s], squared, the lateral acceleration of a turn
    /// without sideslip (kumi's; the paper has none). Tricycle's falls follow fast turns at speed. Absent in a
    /// config: 0, and left out of the serialised config like `fall`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub turn: f64,
    /// Rocking penalty `-rock * (w_x^2 + w_y^2)` per step [1/(rad/s)^2]: the base's roll and
    /// pitch rates [rad/s], its angular velocity about its own x and y axes (Isaac Lab's
    /// `ang_vel_xy_l2`; kumi's, the paper has none). Tricycle rocks on two wheels for seconds
    /// before it falls. Absent in a config: 0, and left out of the serialised config like
    /// `fall`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub rock: f64,
    /// Airborne penalty `-airborne * n` per step, n the wheel modules none of whose wheels
    /// touches the ground (kumi's, training only; the paper has none). A tipping robot lifts a
    /// wheel module first, so the term is felt long before the rare fall. Absent in a config:
    /// 0, and left out of the serialised config like `fall`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub airborne: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// The penalty baseline's extra terms (the paper's Eqs. 5 and 6; `[penalty]` of a whole-body
/// training config). Both 0 by default: the plain task.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct PenaltyWeights {
    /// Leg tool orientation reward `w_ori exp(-sum_i theta_i)` (Eq. 5).
    pub w_ori: f64,
    /// Penalty per step with an undesired arm contact (Eq. 6).
    pub w_c: f64,
}

impl PenaltyWeights {
    pub fn any(&self) -> bool {
        self.w_ori != 0.0 || self.w_c != 0.0
    }
}

/// Every term of one step's reward, signed as added.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BodyTerms {
    pub position: f64,
    pub close_position: f64,
    pub yaw: f64,
    pub joint_velocity: f64,
    pub action_rate: f64,
    pub alive: f64,
    /// The fall penalty (0 on every step but the one that falls).
    pub fall: f64,
    /// The base tilt penalty.
    pub tilt: f64,
    /// The turn penalty.
    pub turn: f64,
    /// The rocking penalty.
    pub rock: f64,
    /// The airborne penalty.
    pub airborne: f64,
    /// Eq. 5 (penalty baseline only).
    pub leg_orientation: f64,
    /// Eq. 6 (penalty baseline only).
    pub contact: f64,
}

impl BodyTerms {
    pub fn total(&self) -> f64 {
        self.position
            + self.close_position
            + self.yaw
            + self.joint_velocity
            + self.action_rate
            + self.alive
            + self.fall
            + self.tilt
            + self.turn
            + self.rock
            + self.airborne
            + self.leg_orientation
            + self.contact
    }
}

/// Eq. 5: `w_ori exp(-sum_i theta_i)` over the angles [rad] between each leg tool's x axis
/// and gravity (0 for a robot without legs: the term rewards a posture it cannot have).
pub fn leg_orientation_reward(w_ori: f64, leg_angles_rad: &[f64]) -> f64 {
    if leg_angles_rad.is_empty() {
        0.0
    } else {
        w_ori * (-leg_angles_rad.iter().sum::<f64>()).exp()
    }
}

/// `-w_fall` on the step the robot falls, else 0.
pub fn fall_penalty(w_fall: f64, fell: bool) -> f64 {
    if fell {
        -w_fall
    } else {
        0.0
    }
}

/// `-w_tilt sin^2(tilt_rad)`: the squared horizontal part of gravity seen from a base tilted
/// by `tilt_rad` ([`tilt`]).
pub fn tilt_penalty(w_tilt: f64, tilt_rad: f64) -> f64 {
    -w_tilt * tilt_rad.sin().powi(2)
}

/// `-w_turn (|v_xy| |w_z|)^2` for the base's horizontal speed `speed_xy_m_s` [m/s] and yaw
/// rate `yaw_rate_rad_s` [rad/s]: the squared centripetal acceleration [m/s^2] of a base that
/// drives along its heading while it turns
/// ([`kumi_terms::action::turn_lateral_acceleration`], which the turn governor bounds).
pub fn turn_penalty(w_turn: f64, speed_xy_m_s: f64, yaw_rate_rad_s: f64) -> f64 {
    -w_turn * kumi_terms::action::turn_lateral_acceleration(speed_xy_m_s, yaw_rate_rad_s).powi(2)
}

/// `-w_rock (w_x^2 + w_y^2)` for the base's angular velocity `angular_velocity_b` [rad/s] in
/// its own frame: its roll and pitch rates, not its yaw rate (driving turns the base about z).
pub fn rock_penalty(w_rock: f64, angular_velocity_b: &nalgebra::Vector3<f64>) -> f64 {
    -w_rock * angular_velocity_b.xy().norm_squared()
}

/// `-w_airborne * modules_off_ground`: the wheel modules with no wheel on the ground.
pub fn airborne_penalty(w_airborne: f64, modules_off_ground: usize) -> f64 {
    -w_airborne * modules_off_ground as f64
}

/// Eq. 6: `-w_c` when an undesired arm contact occurs, else 0.
pub fn contact_penalty(w_c: f64, contact: bool) -> f64 {
    if contact {
        -w_c
    } else {
        0.0
    }
}

/// The terms for a distance [m], a yaw error [rad], arm joint velocities [rad/s] and this and
/// the previous action.
pub fn body_terms(
    distance_m: f64,
    yaw_error_rad: f64,
    arm_joint_velocities: &[f64],
    action: &[f32],
    previous_action: &[f32],
    w: &BodyWeights,
) -> BodyTerms {
    let rate: f64 = action
        .iter()
        .zip(previous_action)
        .map(|(a, b)| f64::from(a - b).powi(2))
        .sum();
    let speed: f64 = arm_joint_velocities.iter().map(|v| v * v).sum();
    BodyTerms {
        position: w.w_p1 * (1.0 - (distance_m / COARSE_SCALE_M).tanh()),
        close_position: w.w_p2 * (1.0 - (distance_m / CLOSE_SCALE_M).tanh()),
        yaw: -w.w_o * yaw_error_rad.abs(),
        joint_velocity: -w.w_v * speed,
        action_rate: -w.w_a * rate,
        alive: w.alive,
        ..BodyTerms::default()
    }
}

/// The tilt rule is the whole-body node's too: it lives with the policy's interface.
pub use kumi_terms::termination::{fallen, tilt};

#[cfg(test)]
mod tests {
    use super::*;

    const W: BodyWeights = BodyWeights {
        w_p1: 1.0,
        w_p2: 2.0,
        w_o: 0.5,
        w_v: 0.01,
        w_a: 0.1,
        alive: 0.2,
        fall: 0.0,
        tilt: 0.0,
        turn: 0.0,
        rock: 0.0,
        airborne: 0.0,
    };

    #[test]
    fn terms_by_hand() {
        // d = 0.2 m: 1 - tanh(0.1) = 0.900332, 1 - tanh(1) = 0.238406 (times 2).
        let t = body_terms(0.2, -0.4, &[1.0, -2.0], &[0.5, 0.0], &[0.0, 1.0], &W);
        assert!((t.position - 0.900_332).abs() < 1e-6, "{t:?}");
        assert!((t.close_position - 0.476_812).abs() < 1e-6, "{t:?}");
        assert!((t.yaw + 0.2).abs() < 1e-12);
        assert!((t.joint_velocity + 0.05).abs() < 1e-12);
        assert!((t.action_rate + 0.125).abs() < 1e-12);
        assert_eq!(t.alive, 0.2);
        let sum = 0.900_332 + 0.476_812 - 0.2 - 0.05 - 0.125 + 0.2;
        assert!((t.total() - sum).abs() < 1e-5);
        // At the target with no motion: both position terms are whole.
        let t = body_terms(0.0, 0.0, &[0.0], &[0.0], &[0.0], &W);
        assert_eq!(t.total(), 1.0 + 2.0 + 0.2);
    }

    #[test]
    fn penalty_terms_by_hand() {
        // Three legs at 0.1, 0.2 and 0.3 rad from gravity: exp(-0.6) = 0.548812.
        let r = leg_orientation_reward(2.0, &[0.1, 0.2, 0.3]);
        assert!((r - 2.0 * 0.548_812).abs() < 1e-6, "{r}");
        // Legs straight along gravity earn the whole weight; no legs earn nothing.
        assert_eq!(leg_orientation_reward(2.0, &[0.0, 0.0, 0.0]), 2.0);
        assert_eq!(leg_orientation_reward(2.0, &[]), 0.0);
        assert_eq!(contact_penalty(0.5, true), -0.5);
        assert_eq!(contact_penalty(0.5, false), 0.0);
        let t = BodyTerms {
            leg_orientation: 1.0,
            contact: -0.5,
            ..BodyTerms::default()
        };
        assert_eq!(t.total(), 0.5);
        assert!(!PenaltyWeights::default().any());
        assert_eq!(fall_penalty(20.0, true), -20.0);
        assert_eq!(fall_penalty(20.0, false), 0.0);
        let t = BodyTerms {
            alive: 0.2,
            fall: -20.0,
            ..BodyTerms::default()
        };
        assert_eq!(t.total(), -19.8);
    }

    #[test]
    fn the_tilt_penalty_by_hand() {
        // sin(0.3) = 0.2955202: 3 x 0.0873322 = 0.2619966.
        assert!((tilt_penalty(3.0, 0.3) + 0.261_996_6).abs() < 1e-6);
        assert_eq!(tilt_penalty(3.0, 0.0), 0.0);
        // Lying on its side (pi / 2) costs the whole weight.
        assert!((tilt_penalty(3.0, std::f64::consts::FRAC_PI_2) + 3.0).abs() < 1e-12);
        let t = BodyTerms {
            alive: 0.5,
            tilt: -0.25,
            ..BodyTerms::default()
        };
        assert_eq!(t.total(), 0.25);
        // Unset, it stays out of the serialised weights: older configs keep their fingerprints.
        let text = serde_json::to_string(&W).unwrap();
        assert!(!text.contains("tilt") && !text.contains("fall"), "{text}");
        let with = BodyWeights { tilt: 3.0, ..W };
        assert!(serde_json::to_string(&with)
            .unwrap()
            .contains("\"tilt\":3.0"));
    }

    #[test]
    fn the_turn_penalty_by_hand() {
        // 0.8 m/s at 0.5 rad/s: 0.4 m/s^2 of lateral acceleration, squared 0.16, times 2.
        assert!((turn_penalty(2.0, 0.8, 0.5) + 0.32).abs() < 1e-12);
        // Either sign of the turn costs the same; turning in place or driving straight, nothing.
        assert_eq!(turn_penalty(2.0, 0.8, -0.5), turn_penalty(2.0, 0.8, 0.5));
        assert_eq!(turn_penalty(2.0, 0.0, 1.0), 0.0);
        assert_eq!(turn_penalty(2.0, 1.0, 0.0), 0.0);
        let t = BodyTerms {
            alive: 0.5,
            turn: -0.32,
            ..BodyTerms::default()
        };
        assert!((t.total() - 0.18).abs() < 1e-12);
        // Unset, it stays out of the serialised weights: older configs keep their fingerprints.
        assert!(!serde_json::to_string(&W).unwrap().contains("turn"));
        let with = BodyWeights { turn: 2.0, ..W };
        assert!(serde_json::to_string(&with)
            .unwrap()
            .contains("\"turn\":2.0"));
    }
    #[test]
    fn the_rock_penalty_by_hand() {
        // Rolling at 0.3 rad/s and pitching at -0.4 rad/s: 0.09 + 0.16 = 0.25, times 2. The
        // yaw rate costs nothing: driving turns the base about its z axis.
        let w = |x, y, z| nalgebra::Vector3::new(x, y, z);
        assert!((rock_penalty(2.0, &w(0.3, -0.4, 0.0)) + 0.5).abs() < 1e-12);
        assert_eq!(
            rock_penalty(2.0, &w(0.3, -0.4, 5.0)),
            rock_penalty(2.0, &w(0.3, -0.4, 0.0))
        );
        assert_eq!(rock_penalty(2.0, &w(0.0, 0.0, 1.0)), 0.0);
        let t = BodyTerms {
            alive: 0.5,
            rock: -0.5,
            ..BodyTerms::default()
        };
        assert_eq!(t.total(), 0.0);
        // Unset, it stays out of the serialised weights: older configs keep their fingerprints.
        assert!(!serde_json::to_string(&W).unwrap().contains("rock"));
        let with = BodyWeights { rock: 2.0, ..W };
        assert!(serde_json::to_string(&with)
            .unwrap()
            .contains("\"rock\":2.0"));
    }

    #[test]
    fn the_airborne_penalty_by_hand() {
        // Two wheel modules off the ground at 0.3 each: -0.6; none off: nothing.
        assert!((airborne_penalty(0.3, 2) + 0.6).abs() < 1e-12);
        assert_eq!(airborne_penalty(0.3, 0), 0.0);
        let t = BodyTerms {
            alive: 0.5,
            airborne: -0.6,
            ..BodyTerms::default()
        };
        assert!((t.total() + 0.1).abs() < 1e-12);
        // Unset, it stays out of the serialised weights: older configs keep their fingerprints.
        assert!(!serde_json::to_string(&W).unwrap().contains("airborne"));
        let with = BodyWeights { airborne: 0.3, ..W };
        assert!(serde_json::to_string(&with)
            .unwrap()
            .contains("\"airborne\":0.3"));
    }
}
