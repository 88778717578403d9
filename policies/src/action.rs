//! The low-level policy's action (Table I): one joint-angle increment per joint.

use crate::observation::JOINTS;

/// Largest increment per control step [rad]: the servo slews at 1.5 rad/s (arm.urdf), which is
/// 0.05 rad per 30 Hz step, so a saturated action asks for what the joint can do in one step.
pub const INCREMENT_SCALE: f64 = 0.05;

/// The joint increments [rad] for a policy output: each value clipped to [-1, 1] and scaled by
/// [`INCREMENT_SCALE`]. A non-finite output becomes 0 (hold), never a command.
pub fn increments(action: &[f32; JOINTS]) -> [f64; JOINTS] {
    let mut out = [0.0; JOINTS];
    for (o, a) in out.iter_mut().zip(action) {
        let a = f64::from(*a);
        *o = if a.is_finite() {
            a.clamp(-1.0, 1.0) * INCREMENT_SCALE
        } else {
            0.0
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipped_scaled_and_safe() {
        let out = increments(&[0.5, -0.5, 2.0, -3.0, 0.0, f32::NAN, f32::INFINITY]);
        assert_eq!(out, [0.025, -0.025, 0.05, -0.05, 0.0, 0.0, 0.0]);
    }
}
