//! The skill's goal distribution: the paper's box (section IV-A) mixed with *working poses*,
//! tool poses near the home configuration of every arm module of the robots the skill serves.
//!
//! The paper's box (x <= 0.6 m) misses where kumi's robots hold their tools: Tricycle's legs
//! stand with their tools at about (0.85, 0, 0.76) m in their base frames, Dragon's second arm
//! stretches straight up to z = 1.6 m. A working pose is the tool pose, by forward kinematics,
//! at joint angles drawn uniformly within `spread_rad` of one module's home angles (clamped to
//! the joint limits): always reachable, and centred where the upper level will send goals.

use nalgebra::Isometry3;
use rand::Rng;

use crate::goal::GoalRange;
use crate::observation::{Goal, JOINTS};

/// Where the skill's goals come from.
#[derive(Debug, Clone, PartialEq)]
pub struct GoalDistribution {
    pub paper_box: GoalRange,
    /// Probability of a goal from the paper's box; the others are working poses.
    pub paper_box_weight: f64,
    /// Home joint angles [rad] of the arm modules whose working poses are drawn.
    pub centres: Vec<[f64; JOINTS]>,
    /// Half-width [rad] of the uniform joint-angle spread around a centre.
    pub spread_rad: f64,
    /// Probability that an episode starts at a working configuration (a centre plus the
    /// spread) with its first goal drawn around the same centre, instead of near zero: the
    /// upper level's goals start where the module stands, so the skill must learn to hold
    /// and move from there (without it, a leg started at its home swung its elbow through
    /// 1.5 rad before coming back, and Tricycle collapsed).
    pub working_start_weight: f64,
}

impl GoalDistribution {
    /// The paper's distribution alone.
    pub fn paper() -> Self {
        Self {
            paper_box: GoalRange::default(),
            paper_box_weight: 1.0,
            centres: Vec::new(),
            spread_rad: 0.0,
            working_start_weight: 0.0,
        }
    }

    /// Only the working poses, every episode from random initial joints near zero (for
    /// evaluating on them alone, with the paper's protocol).
    pub fn working_only(&self) -> Self {
        Self {
            paper_box_weight: 0.0,
            working_start_weight: 0.0,
            ..self.clone()
        }
    }

    /// One goal. `limits` are the joints' (lower, upper) limits [rad]; `tool_pose_b` is the arm's
    /// forward kinematics (tool pose in the arm base frame for joint angles).
    pub fn sample<R: Rng + ?Sized>(
        &self,
        rng: &mut R,
        limits: &[(f64, f64); JOINTS],
        tool_pose_b: &dyn Fn(&[f64; JOINTS]) -> Isometry3<f64>,
    ) -> Goal {
        if self.centres.is_empty() || rng.random::<f64>() < self.paper_box_weight {
            return self.paper_box.sample(rng);
        }
        let centre = rng.random_range(0..self.centres.len());
        self.sample_around(rng, centre, limits, tool_pose_b)
    }

    /// Joint angles [rad] within the spread of centre `centre`, clamped to `limits`.
    fn around<R: Rng + ?Sized>(
        &self,
        rng: &mut R,
        centre: usize,
        limits: &[(f64, f64); JOINTS],
    ) -> [f64; JOINTS] {
        let centre = self.centres[centre];
        std::array::from_fn(|j| {
            let offset = if self.spread_rad > 0.0 {
                rng.random_range(-self.spread_rad..self.spread_rad)
            } else {
                0.0
            };
            (centre[j] + offset).clamp(limits[j].0, limits[j].1)
        })
    }

    /// A working pose around centre `centre` (an index into [`Self::centres`]).
    pub fn sample_around<R: Rng + ?Sized>(
        &self,
        rng: &mut R,
        centre: usize,
        limits: &[(f64, f64); JOINTS],
        tool_pose_b: &dyn Fn(&[f64; JOINTS]) -> Isometry3<f64>,
    ) -> Goal {
        let pose = tool_pose_b(&self.around(rng, centre, limits));
        Goal {
            position_b: pose.translation.vector,
            orientation_b: pose.rotation,
        }
    }

    /// With probability [`Self::working_start_weight`], an episode's start at a working
    /// configuration: the centre's index and the joint angles. Draws nothing when the weight
    /// is 0 or there are no centres.
    pub fn start<R: Rng + ?Sized>(
        &self,
        rng: &mut R,
        limits: &[(f64, f64); JOINTS],
    ) -> Option<(usize, [f64; JOINTS])> {
        if self.centres.is_empty() || self.working_start_weight <= 0.0 {
            return None;
        }
        if rng.random::<f64>() >= self.working_start_weight {
            return None;
        }
        let centre = rng.random_range(0..self.centres.len());
        Some((centre, self.around(rng, centre, limits)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A stand-in "arm": the tool sits at (q0, q1, q2) with a rotation q3 about x.
    fn fk(q: &[f64; JOINTS]) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(q[0], q[1], q[2]),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), q[3]),
        )
    }

    const LIMITS: [(f64, f64); JOINTS] = [(-1.0, 1.0); JOINTS];

    #[test]
    fn working_poses_stay_within_the_spread_and_the_limits() {
        let d = GoalDistribution {
            paper_box_weight: 0.0,
            centres: vec![[0.5, 0.0, -0.9, 0.3, 0.0, 0.0, 0.0]],
            spread_rad: 0.2,
            ..GoalDistribution::paper()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for _ in 0..500 {
            let g = d.sample(&mut rng, &LIMITS, &fk);
            let p = g.position_b;
            assert!((p.x - 0.5).abs() <= 0.2 && p.y.abs() <= 0.2);
            // z: centre -0.9, spread reaches -1.1, clamped at the limit -1.0
            assert!((-1.0..=-0.7).contains(&p.z), "{}", p.z);
            assert!((g.orientation_b.angle() - 0.3).abs() <= 0.2 + 1e-12);
        }
    }

    #[test]
    fn the_mixture_weight_is_respected() {
        let d = GoalDistribution {
            paper_box_weight: 0.25,
            // a centre far outside the paper's box, so the two sources are told apart
            centres: vec![[-5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]],
            spread_rad: 0.0,
            ..GoalDistribution::paper()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let limits = [(-10.0, 10.0); JOINTS];
        let from_box = (0..4000)
            .filter(|_| d.sample(&mut rng, &limits, &fk).position_b.x > -1.0)
            .count();
        assert!((900..1100).contains(&from_box), "{from_box} of 4000");
        // Without centres, every goal is the paper's.
        let paper = GoalDistribution::paper();
        let g = paper.sample(&mut rng, &limits, &fk);
        assert!(g.position_b.x >= -0.1 && g.position_b.x <= 0.6);
    }
}
