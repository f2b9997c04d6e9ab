//! Running observation normalisation (SB3's `VecNormalize` for observations): statistics are
//! updated from every batch seen in training, frozen at inference and saved in the policy file.

use serde::{Deserialize, Serialize};

/// Per-element running mean and variance (parallel update of Chan et al., as SB3's
/// `RunningMeanStd`), and the clipped normalisation it defines.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObsNormalizer {
    /// Running mean per element.
    pub mean: Vec<f64>,
    /// Running variance per element.
    pub var: Vec<f64>,
    /// Number of samples seen (starts at 1e-4 as in SB3).
    pub count: f64,
    /// Normalised values are clipped to `[-clip, clip]`.
    pub clip: f64,
    /// Added to the variance before the square root.
    pub eps: f64,
}

impl ObsNormalizer {
    /// Zero mean, unit variance, SB3's `clip_obs = 10`, `epsilon = 1e-8`.
    pub fn new(dim: usize) -> Self {
        Self {
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: 1e-4,
            clip: 10.0,
            eps: 1e-8,
        }
    }

    /// Elements per observation.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Fold in a batch of flat observations (`len` a multiple of `dim`).
    pub fn update(&mut self, batch: &[f32]) {
        let d = self.dim();
        let n = batch.len() / d;
        if n == 0 {
            return;
        }
        let mut bmean = vec![0.0; d];
        for row in batch.chunks_exact(d) {
            bmean.iter_mut().zip(row).for_each(|(m, x)| *m += *x as f64);
        }
        bmean.iter_mut().for_each(|m| *m /= n as f64);
        let mut bvar = vec![0.0; d];
        for row in batch.chunks_exact(d) {
            bvar.iter_mut()
                .zip(row)
                .zip(&bmean)
                .for_each(|((v, x), m)| *v += (*x as f64 - m).powi(2));
        }
        bvar.iter_mut().for_each(|v| *v /= n as f64);
        let (na, nb) = (self.count, n as f64);
        let tot = na + nb;
        for i in 0..d {
            let delta = bmean[i] - self.mean[i];
            let m2 = self.var[i] * na + bvar[i] * nb + delta * delta * na * nb / tot;
            self.mean[i] += delta * nb / tot;
            self.var[i] = m2 / tot;
        }
        self.count = tot;
    }

    /// Normalise flat observations in place.
    pub fn normalize(&self, obs: &mut [f32]) {
        let d = self.dim();
        for row in obs.chunks_exact_mut(d) {
            for ((x, m), v) in row.iter_mut().zip(&self.mean).zip(&self.var) {
                *x = ((*x as f64 - m) / (v + self.eps).sqrt()).clamp(-self.clip, self.clip) as f32;
            }
        }
    }
}

impl ObsNormalizer {
    /// [`update`](Self::update) with the statistics of the first `dim()` values of each
    /// `row_len`-wide row (the rest, an image, is left out).
    pub fn update_rows(&mut self, batch: &[f32], row_len: usize) {
        let d = self.dim();
        if row_len == d {
            return self.update(batch);
        }
        if d == 0 || row_len == 0 {
            return;
        }
        let head: Vec<f32> = batch.chunks_exact(row_len).flat_map(|r| &r[..d]).copied().collect();
        self.update(&head);
    }

    /// [`normalize`](Self::normalize) of the first `dim()` values of each `row_len`-wide row.
    pub fn normalize_rows(&self, obs: &mut [f32], row_len: usize) {
        let d = self.dim();
        if row_len == d {
            return self.normalize(obs);
        }
        if d == 0 || row_len == 0 {
            return;
        }
        for row in obs.chunks_exact_mut(row_len) {
            self.normalize(&mut row[..d]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_batch_statistics() {
        let mut n = ObsNormalizer::new(2);
        let data: Vec<f32> = (0..1000).flat_map(|i| [i as f32, 5.0 - 0.5 * i as f32]).collect();
        for chunk in data.chunks(20) {
            n.update(chunk);
        }
        assert!((n.mean[0] - 499.5).abs() < 0.1, "{:?}", n.mean);
        assert!((n.var[0] - 83333.25).abs() / 83333.25 < 1e-3, "{:?}", n.var);
        let mut x = vec![499.5, 5.0 - 0.5 * 499.5];
        n.normalize(&mut x);
        assert!(x[0].abs() < 1e-3 && x[1].abs() < 1e-3);
    }

    #[test]
    fn rows_leave_the_image_part_alone() {
        let mut n = ObsNormalizer::new(1);
        // Rows [v, image, image]: only v is tracked and normalised.
        n.update_rows(&[2.0, 0.5, 0.25, 4.0, 0.5, 0.75], 3);
        assert!((n.mean[0] - 3.0).abs() < 1e-3, "{:?}", n.mean);
        let mut x = [3.0, 0.5, 0.25];
        n.normalize_rows(&mut x, 3);
        assert!(x[0].abs() < 1e-3);
        assert_eq!(&x[1..], &[0.5, 0.25]);
    }
}
