//! Observation noise in training (`[observation_noise]` in a whole-body config): Gaussian noise
//! added to the policy's observation, slot by slot, so that the policy cannot lean on exact
//! readings (legged_gym's `add_noise` and mjlab's per-term observation noise do the same for
//! legged robots). Each environment draws from its own stream, apart from the episodes' stream,
//! so that the same seed starts the same episodes with or without noise. Evaluation, the
//! exported policy and the whole-body node never add noise.

use std::collections::BTreeMap;

use kumi_terms::observation::{ObservationSlot, OPTIONAL_SLOTS};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// `[observation_noise]`: the standard deviation of the noise on each named observation slot,
/// in that slot's unit (`base_linear_velocity = 0.05` is 0.05 m/s on each of its three values).
/// Slots left out get none.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
#[serde(transparent)]
pub struct ObservationNoise(pub BTreeMap<String, f64>);

/// Written without its zero entries: a slot set to 0 is a slot left out, and the config's hash
/// says so.
impl serde::Serialize for ObservationNoise {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_map(self.0.iter().filter(|(_, std)| **std != 0.0))
    }
}

impl ObservationNoise {
    /// Noise on the named slots, with these standard deviations.
    pub fn from_pairs(pairs: &[(&str, f64)]) -> Self {
        Self(pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect())
    }

    /// True when no slot is noised.
    pub fn is_none(&self) -> bool {
        self.0.values().all(|std| *std == 0.0)
    }

    /// One standard deviation per observation value, laid out as `slots`. A name that is no
    /// slot of this observation, or a deviation that is negative or not finite, is an error
    /// that names it.
    pub fn per_value(&self, slots: &[ObservationSlot]) -> Result<Vec<f32>, String> {
        for (name, std) in &self.0 {
            if !slots.iter().any(|s| s.name == name) {
                let known: Vec<&str> = slots.iter().map(|s| s.name).collect();
                let hint = if OPTIONAL_SLOTS.contains(&name.as_str()) {
                    format!("; `{name}` is an optional slot: turn it on in [observation]")
                } else {
                    String::new()
                };
                return Err(format!(
                    "[observation_noise] names `{name}`, which is no slot of this observation \
                     (its slots: {}){hint}",
                    known.join(", ")
                ));
            }
            if !(std.is_finite() && *std >= 0.0) {
                return Err(format!(
                    "[observation_noise] {name} = {std}: a standard deviation must be finite \
                     and >= 0"
                ));
            }
        }
        Ok(slots
            .iter()
            .flat_map(|s| {
                let std = self.0.get(s.name).copied().unwrap_or(0.0) as f32;
                std::iter::repeat_n(std, s.size)
            })
            .collect())
    }
}

/// Adds the noise to an observation: `std` holds one deviation per value (empty: none).
pub struct NoiseSource {
    std: Vec<f32>,
    rng: ChaCha8Rng,
}

impl NoiseSource {
    /// Noise with these per-value deviations, from a stream of `seed` apart from the episodes'.
    pub fn new(std: Vec<f32>, seed: u64) -> Self {
        Self {
            std,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x0B5E_2F00_A015_u64),
        }
    }

    /// None at all (draws nothing).
    pub fn silent() -> Self {
        Self::new(Vec::new(), 0)
    }

    /// Noises `obs` in place: each value with a deviation gets one standard-normal draw times
    /// it; values past the deviations (and all of them when there are none) are untouched.
    pub fn apply(&mut self, obs: &mut [f32]) {
        for (value, std) in obs.iter_mut().zip(&self.std) {
            if *std > 0.0 {
                let z: f32 = StandardNormal.sample(&mut self.rng);
                *value += std * z;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slots() -> Vec<ObservationSlot> {
        let slot = |name, size| ObservationSlot {
            name,
            size,
            unit: "1",
            frame: "base",
        };
        vec![slot("a", 2), slot("b", 1), slot("c", 3)]
    }

    fn noise(pairs: &[(&str, f64)]) -> ObservationNoise {
        ObservationNoise::from_pairs(pairs)
    }

    #[test]
    fn each_slot_gets_its_deviation_on_every_value_and_the_rest_none() {
        let std = noise(&[("c", 0.5), ("a", 0.1)])
            .per_value(&slots())
            .unwrap();
        assert_eq!(std, vec![0.1, 0.1, 0.0, 0.5, 0.5, 0.5]);
        assert!(noise(&[]).is_none() && noise(&[("a", 0.0)]).is_none());
        assert!(!noise(&[("a", 0.1)]).is_none());
    }

    #[test]
    fn an_unknown_slot_or_a_bad_deviation_is_refused_by_name() {
        let e = noise(&[("d", 0.1)]).per_value(&slots()).unwrap_err();
        assert!(e.contains("`d`") && e.contains("a, b, c"), "{e}");
        assert!(!e.contains("optional"), "{e}");
        let e = noise(&[("arm_joint_angles", 0.1)])
            .per_value(&slots())
            .unwrap_err();
        assert!(
            e.ends_with("`arm_joint_angles` is an optional slot: turn it on in [observation]"),
            "an optional slot switched off says where to switch it on: {e}"
        );
        for bad in [-0.1, f64::NAN, f64::INFINITY] {
            let e = noise(&[("b", bad)]).per_value(&slots()).unwrap_err();
            assert!(e.contains("b = "), "{e}");
        }
    }

    #[test]
    fn noise_moves_only_the_noised_values_with_the_deviation_asked() {
        let mut source = NoiseSource::new(vec![0.0, 0.2, 0.0], 3);
        let (n, mut sum, mut sum_sq) = (20_000, 0.0f64, 0.0f64);
        for _ in 0..n {
            let mut obs = [1.0f32, 2.0, 3.0, 4.0];
            source.apply(&mut obs);
            assert_eq!((obs[0], obs[2], obs[3]), (1.0, 3.0, 4.0));
            let d = f64::from(obs[1] - 2.0);
            sum += d;
            sum_sq += d * d;
        }
        let mean = sum / f64::from(n);
        let std = (sum_sq / f64::from(n) - mean * mean).sqrt();
        // 20,000 draws: the mean's standard error is 0.2 / sqrt(20000) = 0.0014.
        assert!(mean.abs() < 0.006, "mean {mean}");
        assert!((std - 0.2).abs() < 0.006, "std {std}");
        let mut silent = NoiseSource::silent();
        let mut obs = [1.0f32, 2.0];
        silent.apply(&mut obs);
        assert_eq!(obs, [1.0, 2.0]);
    }
}
