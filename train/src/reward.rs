//! The low-level reaching reward (the paper's Eq. 4), as pure functions.
//!
//! r = w_p exp(-a_p d) + w_pf exp(-a_pf d) + w_o exp(-a_o theta) + w_of exp(-a_of theta)
//!     - w_a |a_t - a_{t-1}|^2 - w_v |qd|^2 - w_lead sum_j max(0, |q_target,j - q_j| - l_free)^2
//!
//! where d = |p_ref - p_ee| [m] and theta = 2 |log(q_ref^-1 q_ee)| is the orientation error
//! [rad]. Two deviations from the paper's Eq. 4, both deliberate:
//! - the paper prints the orientation term with a minus sign, which would penalise being
//!   *aligned*; kumi rewards alignment (+ w_o exp(-a_o theta)), the evident intent;
//! - the position and orientation terms each have a coarse and a fine scale (like the upper
//!   level's two tanh terms, Table IV): one exp cannot both pull from a metre (or a radian) away
//!   and sharpen the last centimetres. Set `w_pf = w_of = 0` for the paper's single terms.
//!
//! The last term is kumi's addition (0 by default): how far the position targets lead the
//! joints. A servo reaches its effort limit a few mrad from its target at rest, so a larger lead
//! at rest moves nothing and only winds up against whatever blocks the arm (the ground under a
//! leg, a load it cannot lift); legged_gym's torque penalty plays this part.

/// Weights and scales of the reaching reward. Defaults are kumi's choice (the paper gives none).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReachWeights {
    /// Position term weight.
    pub w_p: f64,
    /// Position scale [1/m]: the term halves at ln 2 / a_p metres.
    pub a_p: f64,
    /// Fine position term weight.
    pub w_pf: f64,
    /// Fine position scale [1/m].
    pub a_pf: f64,
    /// Orientation term weight.
    pub w_o: f64,
    /// Orientation scale [1/rad].
    pub a_o: f64,
    /// Fine orientation term weight.
    pub w_of: f64,
    /// Fine orientation scale [1/rad].
    pub a_of: f64,
    /// Action-rate penalty weight (actions in policy units, [-1, 1] per joint).
    pub w_a: f64,
    /// Joint-velocity penalty weight [1/(rad/s)^2].
    pub w_v: f64,
    /// Target-lead penalty weight [1/rad^2]; 0 when absent.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub w_lead: f64,
    /// The lead [rad] the penalty leaves free: a joint moving at its velocity limit needs its
    /// target a little ahead (its damping over its stiffness times its speed: 0.04 rad for the
    /// arm's joint2); only the lead beyond it counts. 0 when absent.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lead_free_rad: f64,
}

/// Keys left at 0 are left out of a config's text, so that a config written before them keeps
/// its fingerprint.
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for ReachWeights {
    fn default() -> Self {
        Self {
            w_p: 1.0,
            a_p: 2.0,
            w_pf: 1.0,
            a_pf: 20.0,
            w_o: 1.0,
            a_o: 0.5,
            w_of: 1.0,
            a_of: 4.0,
            w_a: 0.01,
            w_v: 0.001,
            w_lead: 0.0,
            lead_free_rad: 0.0,
        }
    }
}

/// Every term of one step's reward, for logging.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ReachTerms {
    pub position: f64,
    pub orientation: f64,
    pub action_rate: f64,
    pub joint_velocity: f64,
    pub target_lead: f64,
}

impl ReachTerms {
    pub fn total(&self) -> f64 {
        self.position + self.orientation + self.action_rate + self.joint_velocity + self.target_lead
    }
}

/// The reward terms for a position error [m], an orientation error [rad], this and the previous
/// action (policy units), the joint velocities [rad/s] and how far the position targets lead
/// the joints [rad].
pub fn reach_terms(
    position_error: f64,
    orientation_error: f64,
    action: &[f32],
    previous_action: &[f32],
    qd: &[f64],
    lead: &[f64],
    w: &ReachWeights,
) -> ReachTerms {
    let action_rate: f64 = action
        .iter()
        .zip(previous_action)
        .map(|(a, b)| f64::from(a - b).powi(2))
        .sum();
    let speed: f64 = qd.iter().map(|v| v * v).sum();
    let lead: f64 = lead
        .iter()
        .map(|l| (l.abs() - w.lead_free_rad).max(0.0).powi(2))
        .sum();
    ReachTerms {
        position: w.w_p * (-w.a_p * position_error).exp()
            + w.w_pf * (-w.a_pf * position_error).exp(),
        orientation: w.w_o * (-w.a_o * orientation_error).exp()
            + w.w_of * (-w.a_of * orientation_error).exp(),
        action_rate: -w.w_a * action_rate,
        joint_velocity: -w.w_v * speed,
        target_lead: -w.w_lead * lead,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_terms() {
        let w = ReachWeights {
            w_p: 2.0,
            a_p: 10.0,
            w_pf: 0.0,
            a_pf: 0.0,
            w_o: 0.5,
            a_o: 1.0,
            w_of: 0.0,
            a_of: 0.0,
            w_a: 0.1,
            w_v: 0.01,
            w_lead: 2.0,
            lead_free_rad: 0.05,
        };
        let t = reach_terms(
            0.1,
            0.0,
            &[1.0, 0.5],
            &[0.0, 0.5],
            &[3.0, 4.0],
            &[0.15, -0.25, 0.01],
            &w,
        );
        assert!((t.position - 2.0 * (-1.0_f64).exp()).abs() < 1e-12); // 2 e^-1
        assert_eq!(t.orientation, 0.5); // aligned: the full orientation reward
        assert!((t.action_rate + 0.1).abs() < 1e-12); // -0.1 * (1^2 + 0^2)
        assert!((t.joint_velocity + 0.25).abs() < 1e-12); // -0.01 * (9 + 16)
        assert!((t.target_lead + 0.1).abs() < 1e-12); // -2 * (0.1^2 + 0.2^2 + 0), 0.05 rad free
        assert!((t.total() - (2.0 * (-1.0_f64).exp() + 0.5 - 0.1 - 0.25 - 0.1)).abs() < 1e-12);
    }

    #[test]
    fn the_fine_position_term_adds_a_sharp_peak() {
        let w = ReachWeights {
            w_p: 1.0,
            a_p: 2.0,
            w_pf: 1.0,
            a_pf: 20.0,
            w_o: 0.0,
            a_o: 0.0,
            w_of: 0.0,
            a_of: 0.0,
            w_a: 0.0,
            w_v: 0.0,
            w_lead: 0.0,
            lead_free_rad: 0.0,
        };
        // At 0.05 m: e^-0.1 + e^-1.
        let t = reach_terms(0.05, 0.0, &[], &[], &[], &[], &w);
        assert!((t.position - ((-0.1_f64).exp() + (-1.0_f64).exp())).abs() < 1e-12);
        // Going from 5 cm to 1 cm gains far more with the fine term than without.
        let gain = reach_terms(0.01, 0.0, &[], &[], &[], &[], &w).position - t.position;
        let coarse_only = (-0.02_f64).exp() - (-0.1_f64).exp();
        assert!(gain > 3.0 * coarse_only);
    }

    #[test]
    fn the_fine_orientation_term_adds_a_sharp_peak() {
        let w = ReachWeights {
            w_p: 0.0,
            a_p: 0.0,
            w_pf: 0.0,
            a_pf: 0.0,
            w_o: 1.0,
            a_o: 0.5,
            w_of: 2.0,
            a_of: 4.0,
            w_a: 0.0,
            w_v: 0.0,
            w_lead: 0.0,
            lead_free_rad: 0.0,
        };
        // At 0.25 rad: e^-0.125 + 2 e^-1.
        let t = reach_terms(0.0, 0.25, &[], &[], &[], &[], &w);
        assert!((t.orientation - ((-0.125_f64).exp() + 2.0 * (-1.0_f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn alignment_is_rewarded_not_penalised() {
        let w = ReachWeights::default();
        let aligned = reach_terms(0.0, 0.0, &[], &[], &[], &[], &w).total();
        let off = reach_terms(0.0, 1.0, &[], &[], &[], &[], &w).total();
        let far = reach_terms(0.5, 0.0, &[], &[], &[], &[], &w).total();
        assert!(aligned > off && aligned > far);
    }
}
