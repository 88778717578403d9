//! Domain randomisation: each training environment simulates a slightly different world, so
//! that the policy cannot lean on one engine's exact contact and friction (Tobin et al. 2017,
//! "Domain randomization for transferring deep neural networks from simulation to the real
//! world"; legged_gym's `randomize_friction`). kumi draws once per environment, when it is
//! built, from that environment's seed: a MuJoCo model is compiled once per world, and 32
//! environments hold 32 draws. Evaluation never randomises.

use kumi_worlds::SimConfig;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `[randomize]` in a whole-body config (training only; none when the section is absent).
/// Every range is `[lo, hi]`, drawn uniformly; a range left out keeps the robot's setting.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct RandomizeConfig {
    /// The ground's friction coefficient (a contact takes the smaller of its two: the wheels'
    /// is 1.0, so a draw above 1.0 leaves the wheels' contacts as they are).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_friction: Option<[f64; 2]>,
    /// MuJoCo's contact time constant [s] (`solref`; the default is twice the timestep, 1/60 s
    /// for Tricycle). Larger is softer. Rapier ignores it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mujoco_contact_time_s: Option<[f64; 2]>,
}

impl RandomizeConfig {
    /// Refuses a range that is empty, not finite or not positive, naming it.
    pub fn check(&self) -> Result<(), String> {
        let ranges = [
            ("ground_friction", self.ground_friction),
            ("mujoco_contact_time_s", self.mujoco_contact_time_s),
        ];
        for (name, range) in ranges {
            if let Some([lo, hi]) = range {
                if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
                    return Err(format!(
                        "invalid [randomize] {name}: [{lo}, {hi}] must be a finite range [lo, hi] \
                         with 0 < lo <= hi"
                    ));
                }
            }
        }
        Ok(())
    }

    /// `sim` with this environment's draw, from its own stream of `seed` (the episodes' stream
    /// is left as it would be without randomisation).
    pub fn apply(&self, mut sim: SimConfig, seed: u64) -> SimConfig {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x005E_ED0F_D0A1_u64);
        if let Some(range) = self.ground_friction {
            sim.ground_friction = draw(range, &mut rng);
        }
        if let Some(range) = self.mujoco_contact_time_s {
            sim.mujoco_contact_time_s = Some(draw(range, &mut rng));
        }
        sim
    }
}

/// Uniform in `[lo, hi]`, both ends included (`lo` itself for an empty range).
pub(crate) fn draw([lo, hi]: [f64; 2], rng: &mut impl Rng) -> f64 {
    if hi > lo {
        rng.random_range(lo..=hi)
    } else {
        lo
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_lie_in_range_and_differ_between_environments() {
        let config = RandomizeConfig {
            ground_friction: Some([0.5, 1.5]),
            mujoco_contact_time_s: Some([0.02, 0.04]),
        };
        let base = SimConfig::default();
        let draws: Vec<SimConfig> = (0..32).map(|seed| config.apply(base, seed)).collect();
        for d in &draws {
            assert!((0.5..=1.5).contains(&d.ground_friction), "{d:?}");
            let t = d.mujoco_contact_time_s.unwrap();
            assert!((0.02..=0.04).contains(&t), "{d:?}");
            assert_eq!(d.mujoco_substeps, base.mujoco_substeps);
        }
        let lowest = draws
            .iter()
            .map(|d| d.ground_friction)
            .fold(f64::MAX, f64::min);
        let highest = draws.iter().map(|d| d.ground_friction).fold(0.0, f64::max);
        assert!(lowest < 0.8 && highest > 1.2, "{lowest} {highest}");
        // The same seed draws the same world.
        assert_eq!(config.apply(base, 7), config.apply(base, 7));
    }

    #[test]
    fn an_empty_section_changes_nothing() {
        let base = SimConfig::default();
        assert_eq!(RandomizeConfig::default().apply(base, 3), base);
        assert_eq!(base.mujoco_contact_time_s(), 2.0 * base.mujoco_dt());
    }

    #[test]
    fn bad_ranges_are_refused_by_name() {
        let bad = RandomizeConfig {
            mujoco_contact_time_s: Some([0.04, 0.02]),
            ..Default::default()
        };
        assert!(bad.check().unwrap_err().contains("mujoco_contact_time_s"));
        let bad = RandomizeConfig {
            ground_friction: Some([0.0, 1.0]),
            ..Default::default()
        };
        assert!(bad.check().unwrap_err().contains("ground_friction"));
        assert!(RandomizeConfig::default().check().is_ok());
    }
}
