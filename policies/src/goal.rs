//! Reaching goals (the paper's section IV-A): sampled in the arm base frame every 4 s, with a little noise
//! added at every step to emulate an upper level that keeps moving them.

use nalgebra::{UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};

use crate::observation::Goal;

/// Where goals are drawn from. Defaults are the paper's (section IV-A).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalRange {
    /// Lower corner of the position box [m], arm base frame.
    pub position_min: Vector3<f64>,
    /// Upper corner of the position box [m].
    pub position_max: Vector3<f64>,
    /// Roll range [rad] about the tool's x axis.
    pub roll: (f64, f64),
    /// Pitch range [rad].
    pub pitch: (f64, f64),
    /// Yaw range [rad] (the paper fixes yaw at 0).
    pub yaw: (f64, f64),
}

impl Default for GoalRange {
    fn default() -> Self {
        use std::f64::consts::{FRAC_PI_3, PI};
        Self {
            position_min: Vector3::new(-0.1, -0.3, 0.6),
            position_max: Vector3::new(0.6, 0.3, 1.3),
            roll: (-PI, PI),
            pitch: (-FRAC_PI_3, FRAC_PI_3),
            yaw: (0.0, 0.0),
        }
    }
}

fn uniform<R: Rng + ?Sized>(rng: &mut R, (lo, hi): (f64, f64)) -> f64 {
    if hi > lo {
        rng.random_range(lo..hi)
    } else {
        lo
    }
}

impl GoalRange {
    /// A goal drawn uniformly: position in the box, roll, pitch and yaw in their ranges,
    /// converted to a quaternion (fixed-axis roll, pitch, yaw, as URDF's `rpy`).
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Goal {
        let p = Vector3::new(
            uniform(rng, (self.position_min.x, self.position_max.x)),
            uniform(rng, (self.position_min.y, self.position_max.y)),
            uniform(rng, (self.position_min.z, self.position_max.z)),
        );
        Goal {
            position_b: p,
            orientation_b: UnitQuaternion::from_euler_angles(
                uniform(rng, self.roll),
                uniform(rng, self.pitch),
                uniform(rng, self.yaw),
            ),
        }
    }
}

/// Per-step goal noise: Gaussian on the position [m] and a small random rotation [rad].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalNoise {
    pub position_std: f64,
    pub orientation_std: f64,
}

impl GoalNoise {
    /// The goal with noise added (the underlying goal is not changed).
    pub fn apply<R: Rng + ?Sized>(&self, goal: &Goal, rng: &mut R) -> Goal {
        let mut normal = |std: f64| {
            if std > 0.0 {
                Normal::new(0.0, std).map(|n| n.sample(rng)).unwrap_or(0.0)
            } else {
                0.0
            }
        };
        let dp = Vector3::new(
            normal(self.position_std),
            normal(self.position_std),
            normal(self.position_std),
        );
        let dr = Vector3::new(
            normal(self.orientation_std),
            normal(self.orientation_std),
            normal(self.orientation_std),
        );
        Goal {
            position_b: goal.position_b + dp,
            orientation_b: UnitQuaternion::from_scaled_axis(dr) * goal.orientation_b,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::orientation_error;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn samples_stay_in_the_paper_ranges() {
        let range = GoalRange::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..2000 {
            let g = range.sample(&mut rng);
            for i in 0..3 {
                assert!(
                    g.position_b[i] >= range.position_min[i]
                        && g.position_b[i] <= range.position_max[i]
                );
            }
            let (roll, pitch, yaw) = g.orientation_b.euler_angles();
            assert!(
                pitch.abs() <= std::f64::consts::FRAC_PI_3 + 1e-9,
                "pitch {pitch}"
            );
            assert!(
                yaw.abs() < 1e-9 || (yaw.abs() - std::f64::consts::PI).abs() < 1e-9,
                "yaw {yaw}"
            );
            assert!(roll.abs() <= std::f64::consts::PI + 1e-9);
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_goals() {
        let range = GoalRange::default();
        let a = range.sample(&mut ChaCha8Rng::seed_from_u64(9));
        let b = range.sample(&mut ChaCha8Rng::seed_from_u64(9));
        assert_eq!(a, b);
    }

    #[test]
    fn noise_is_small_and_zero_noise_is_exact() {
        let range = GoalRange::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let g = range.sample(&mut rng);
        let none = GoalNoise {
            position_std: 0.0,
            orientation_std: 0.0,
        };
        assert_eq!(none.apply(&g, &mut rng), g);
        let noise = GoalNoise {
            position_std: 0.005,
            orientation_std: 0.01,
        };
        for _ in 0..100 {
            let n = noise.apply(&g, &mut rng);
            assert!((n.position_b - g.position_b).norm() < 0.05);
            assert!(orientation_error(&n.orientation_b, &g.orientation_b) < 0.1);
        }
    }
}
