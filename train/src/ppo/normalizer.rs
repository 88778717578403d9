//! Running observation normalisation (mean and variance over everything seen so far), frozen
//! into the exported policy.

/// Running mean and variance per observation entry (Chan et al.'s parallel update).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunningNorm {
    pub mean: Vec<f64>,
    pub var: Vec<f64>,
    pub count: f64,
}

/// Smallest standard deviation used to divide by (constant entries stay finite).
pub const MIN_STD: f64 = 1e-4;

impl RunningNorm {
    pub fn new(dim: usize) -> Self {
        Self {
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: 0.0,
        }
    }

    /// Folds a batch of rows (each `dim` long) into the statistics.
    pub fn update(&mut self, rows: &[&[f32]]) {
        if rows.is_empty() {
            return;
        }
        let n = rows.len() as f64;
        for j in 0..self.mean.len() {
            let batch_mean = rows.iter().map(|r| f64::from(r[j])).sum::<f64>() / n;
            let batch_var = rows
                .iter()
                .map(|r| (f64::from(r[j]) - batch_mean).powi(2))
                .sum::<f64>()
                / n;
            if self.count == 0.0 {
                self.mean[j] = batch_mean;
                self.var[j] = batch_var;
                continue;
            }
            let total = self.count + n;
            let delta = batch_mean - self.mean[j];
            let m2 =
                self.var[j] * self.count + batch_var * n + delta * delta * self.count * n / total;
            self.mean[j] += delta * n / total;
            self.var[j] = m2 / total;
        }
        self.count += n;
    }

    /// The standard deviation used for entry `j`.
    pub fn std(&self, j: usize) -> f64 {
        self.var[j].sqrt().max(MIN_STD)
    }

    /// (x - mean) / std, entry by entry.
    pub fn apply(&self, x: &[f32]) -> Vec<f32> {
        x.iter()
            .enumerate()
            .map(|(j, v)| ((f64::from(*v) - self.mean[j]) / self.std(j)) as f32)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_statistics_of_everything_seen() {
        let mut n = RunningNorm::new(1);
        n.update(&[&[1.0], &[2.0]]);
        n.update(&[&[3.0], &[4.0], &[10.0]]);
        // mean of 1, 2, 3, 4, 10 = 4; population variance = (9 + 4 + 1 + 0 + 36) / 5 = 10
        assert!((n.mean[0] - 4.0).abs() < 1e-12);
        assert!((n.var[0] - 10.0).abs() < 1e-12);
        assert_eq!(n.count, 5.0);
        let y = n.apply(&[4.0 + 10f32.sqrt()]);
        assert!((y[0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn constant_entries_stay_finite() {
        let mut n = RunningNorm::new(1);
        n.update(&[&[5.0], &[5.0]]);
        assert_eq!(n.apply(&[5.0]), vec![0.0]);
        assert!(n.apply(&[6.0])[0].is_finite());
    }
}
