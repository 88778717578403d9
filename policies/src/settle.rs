//! How calmly the skill holds and reaches a goal: the measures `kumi eval arm` and
//! `kumi sim --skill-on` report beside the final errors, defined once here.
//!
//! - **Hold smoothness**, over the last [`HOLD_WINDOW_S`] of each goal: the mean absolute
//!   increment per joint per step as a share of the largest increment (the action value clipped
//!   to +-[`ACTION_LIMIT`], made absolute), and the share of steps at which a joint's increment
//!   reverses sign with a magnitude above [`REVERSAL_SHARE`] of the largest. A skill that has
//!   settled commands small increments of one sign; a relay commands the largest ones, back and
//!   forth.
//! - **Settle time**: from the goal's start until the tool stays within
//!   [`SETTLE_POSITION_M`] and [`SETTLE_ORIENTATION_RAD`] of where it ends.
//! - **Joint speed after the first second** of standing on the skill ([`SpeedStats`]).

use nalgebra::{UnitQuaternion, Vector3};

use crate::observation::JOINTS;
use crate::skill::ACTION_LIMIT;

/// The window at the end of each goal over which hold smoothness is measured [s].
pub const HOLD_WINDOW_S: f64 = 1.0;
/// A sign reversal counts when the new increment is larger than this share of the largest.
pub const REVERSAL_SHARE: f64 = 0.2;
/// The tool has settled once it stays this close to its final position [m] ...
pub const SETTLE_POSITION_M: f64 = 0.02;
/// ... and to its final orientation [rad].
pub const SETTLE_ORIENTATION_RAD: f64 = 0.1;
/// Standing checks measure joint speeds after this long [s], past the start's transient.
pub const SPEED_AFTER_S: f64 = 1.0;

/// An action value as a signed share of the largest increment: clipped to +-[`ACTION_LIMIT`],
/// divided by the limit (a non-finite value holds: 0).
fn signed_share(value: f32) -> f64 {
    let v = f64::from(value);
    if v.is_finite() {
        v.clamp(-ACTION_LIMIT, ACTION_LIMIT) / ACTION_LIMIT
    } else {
        0.0
    }
}

/// Hold-smoothness counts, summed over any number of windows (`+`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HoldCounts {
    share_sum: f64,
    values: usize,
    reversals: usize,
    pairs: usize,
}

impl HoldCounts {
    /// The counts of one window of consecutive actions (the skill's outputs, policy units).
    pub fn of(actions: &[[f32; JOINTS]]) -> Self {
        let mut counts = Self::default();
        for action in actions {
            counts.share_sum += action.iter().map(|a| signed_share(*a).abs()).sum::<f64>();
            counts.values += JOINTS;
        }
        for pair in actions.windows(2) {
            for (before, now) in pair[0].iter().zip(&pair[1]) {
                let (before, now) = (signed_share(*before), signed_share(*now));
                if before * now < 0.0 && now.abs() > REVERSAL_SHARE {
                    counts.reversals += 1;
                }
                counts.pairs += 1;
            }
        }
        counts
    }

    /// The mean absolute increment per joint per step, as a share of the largest (NaN without
    /// values).
    pub fn mean_increment_share(&self) -> f64 {
        if self.values == 0 {
            f64::NAN
        } else {
            self.share_sum / self.values as f64
        }
    }

    /// The share of (joint, step) pairs at which the increment reversed sign with a magnitude
    /// above [`REVERSAL_SHARE`] of the largest (NaN without two steps).
    pub fn reversal_share(&self) -> f64 {
        if self.pairs == 0 {
            f64::NAN
        } else {
            self.reversals as f64 / self.pairs as f64
        }
    }
}

impl std::ops::Add for HoldCounts {
    type Output = Self;

    /// Both windows' counts together.
    fn add(self, other: Self) -> Self {
        Self {
            share_sum: self.share_sum + other.share_sum,
            values: self.values + other.values,
            reversals: self.reversals + other.reversals,
            pairs: self.pairs + other.pairs,
        }
    }
}

/// The number of steps after a goal's start until the tool stays within
/// [`SETTLE_POSITION_M`] and [`SETTLE_ORIENTATION_RAD`] of its pose at the goal's end: `poses`
/// are the tool's poses after each step of the goal, in any one frame. 0 if it never left that
/// neighbourhood; `poses.len()` is never returned (the last pose is its own end).
pub fn settle_steps(poses: &[(Vector3<f64>, UnitQuaternion<f64>)]) -> usize {
    let Some((end_p, end_q)) = poses.last() else {
        return 0;
    };
    poses
        .iter()
        .rposition(|(p, q)| {
            (p - end_p).norm() > SETTLE_POSITION_M || q.angle_to(end_q) > SETTLE_ORIENTATION_RAD
        })
        .map_or(0, |last_outside| last_outside + 1)
}

/// Mean and largest absolute joint speed over a run [rad/s].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SpeedStats {
    pub mean: f64,
    pub max: f64,
}

/// Accumulates [`SpeedStats`] over control steps.
#[derive(Debug, Clone, Copy, Default)]
pub struct SpeedTally {
    sum: f64,
    count: usize,
    max: f64,
}

impl SpeedTally {
    /// Adds one step's joint speeds [rad/s] (non-finite ones make the maximum infinite).
    pub fn add(&mut self, speeds: impl IntoIterator<Item = f64>) {
        for v in speeds {
            let v = if v.is_finite() {
                v.abs()
            } else {
                f64::INFINITY
            };
            self.sum += v;
            self.count += 1;
            self.max = self.max.max(v);
        }
    }

    /// The stats so far (NaN without any speed).
    pub fn stats(&self) -> SpeedStats {
        if self.count == 0 {
            SpeedStats {
                mean: f64::NAN,
                max: f64::NAN,
            }
        } else {
            SpeedStats {
                mean: self.sum / self.count as f64,
                max: self.max,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repeat(a: f32, n: usize) -> Vec<[f32; JOINTS]> {
        vec![[a; JOINTS]; n]
    }

    #[test]
    fn a_relay_is_all_reversals_at_full_increment() {
        let relay: Vec<[f32; JOINTS]> = (0..30_usize)
            .map(|k| [if k.is_multiple_of(2) { 3.0 } else { -3.0 }; JOINTS])
            .collect();
        let c = HoldCounts::of(&relay);
        assert_eq!(c.mean_increment_share(), 1.0);
        assert_eq!(c.reversal_share(), 1.0);
    }

    #[test]
    fn a_calm_hold_has_small_increments_and_no_reversals() {
        let c = HoldCounts::of(&repeat(0.02, 30));
        assert!((c.mean_increment_share() - 0.02).abs() < 1e-9);
        assert_eq!(c.reversal_share(), 0.0);
        // Small reversals (below 20 % of the largest) are dither, not counted.
        let small: Vec<[f32; JOINTS]> = (0..30_usize)
            .map(|k| [if k.is_multiple_of(2) { 0.1 } else { -0.1 }; JOINTS])
            .collect();
        assert_eq!(HoldCounts::of(&small).reversal_share(), 0.0);
    }

    #[test]
    fn counts_by_hand() {
        // Joint 0: 0.5, -0.5, -0.1, 0.3: reversals at steps 1 (|-0.5| > 0.2) and 3 (0.3 > 0.2),
        // not at step 2 (same sign). The other joints hold 0: no sign, no reversal.
        let mut actions = repeat(0.0, 4);
        for (k, v) in [0.5, -0.5, -0.1, 0.3].into_iter().enumerate() {
            actions[k][0] = v;
        }
        let c = HoldCounts::of(&actions);
        assert!((c.mean_increment_share() - 1.4 / 28.0).abs() < 1e-9);
        assert!((c.reversal_share() - 2.0 / 21.0).abs() < 1e-12);
        let both = c + HoldCounts::of(&repeat(0.0, 4));
        assert!((both.reversal_share() - 2.0 / 42.0).abs() < 1e-12);
        assert!(HoldCounts::default().mean_increment_share().is_nan());
        // Past the clip a value counts as the largest increment; NaN holds.
        let c = HoldCounts::of(&[[5.0, -5.0, f32::NAN, 0.0, 0.0, 0.0, 0.0]]);
        assert!((c.mean_increment_share() - 2.0 / 7.0).abs() < 1e-9);
    }

    #[test]
    fn settle_steps_by_hand() {
        let at = |x: f64, angle: f64| {
            (
                Vector3::new(x, 0.0, 0.0),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle),
            )
        };
        // Moves 0.5, 0.3, 0.11 (outside 2 cm), 0.105, 0.1 (within): settled after 3 steps.
        let poses = [
            at(0.5, 0.0),
            at(0.3, 0.0),
            at(0.13, 0.0),
            at(0.105, 0.0),
            at(0.1, 0.0),
        ];
        assert_eq!(settle_steps(&poses), 3);
        // Position settled but orientation 0.2 rad off until the fourth step.
        let poses = [
            at(0.1, 0.5),
            at(0.1, 0.3),
            at(0.1, 0.2),
            at(0.1, 0.05),
            at(0.1, 0.0),
        ];
        assert_eq!(settle_steps(&poses), 3);
        // Never away: 0; leaving and coming back counts the leaving.
        assert_eq!(settle_steps(&[at(0.1, 0.0), at(0.1, 0.0)]), 0);
        let poses = [at(0.1, 0.0), at(0.2, 0.0), at(0.1, 0.0), at(0.1, 0.0)];
        assert_eq!(settle_steps(&poses), 2);
        assert_eq!(settle_steps(&[]), 0);
    }

    #[test]
    fn speed_stats_by_hand() {
        let mut t = SpeedTally::default();
        assert!(t.stats().mean.is_nan());
        t.add([1.0, -3.0]);
        t.add([0.5]);
        assert_eq!(
            t.stats(),
            SpeedStats {
                mean: 1.5,
                max: 3.0
            }
        );
        t.add([f64::NAN]);
        assert_eq!(t.stats().max, f64::INFINITY);
    }
}
