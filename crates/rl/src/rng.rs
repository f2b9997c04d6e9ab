//! The learners' seedable RNG: rand_xoshiro's xoshiro256++ (seeded through SplitMix64, the
//! generator's reference seeding), whose whole state fits in a checkpoint. All randomness of
//! training (exploration noise, minibatch order, initial weights) comes from here, so the same
//! seed on one thread gives the same run. The envs draw from rand's `StdRng`; both are rand's.

use rand::RngExt;
use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::{Rng as _, SeedableRng};
use serde::{Deserialize, Serialize};

/// xoshiro256++ with a cached second Box-Muller normal. Serialised as `{ s, spare }`, the
/// generator's state words beside the cache.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Rng {
    #[serde(flatten)]
    core: Xoshiro256PlusPlus,
    spare: Option<f64>,
}

impl Rng {
    /// A generator seeded from `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            core: Xoshiro256PlusPlus::seed_from_u64(seed),
            spare: None,
        }
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.core.next_u64()
    }

    /// Uniform in [0, 1), 53 bits.
    pub fn uniform(&mut self) -> f64 {
        self.core.random::<f64>()
    }

    /// Uniform integer in [0, n) (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        // Lemire's multiply-shift; the bias is below 2^-32 for the sizes used here.
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]: ln stays finite
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
        self.spare = Some(r * s);
        r * c
    }

    /// `n` standard normals as f32.
    pub fn normals(&mut self, n: usize) -> Vec<f32> {
        (0..n).map(|_| self.normal() as f32).collect()
    }

    /// Fisher-Yates shuffle.
    pub fn shuffle<T>(&mut self, v: &mut [T]) {
        for i in (1..v.len()).rev() {
            let j = self.below(i + 1);
            v.swap(i, j);
        }
    }

    /// A new generator derived from this one (for independent streams).
    pub fn fork(&mut self) -> Self {
        Self::new(self.next_u64())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_has_unit_moments_and_below_stays_in_range() {
        let mut r = Rng::new(3);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.02, "{var}");
        assert!((0..1000).all(|_| r.below(7) < 7));
        assert_eq!(Rng::new(5).next_u64(), Rng::new(5).next_u64());
    }

    #[test]
    fn seed_zero_gives_the_reference_xoshiro256_plus_plus_stream() {
        // xoshiro256++ seeded with SplitMix64(0), as in the generator's reference C code: the
        // stream every committed run and shipped policy was trained with.
        let mut r = Rng::new(0);
        let got: Vec<u64> = (0..3).map(|_| r.next_u64()).collect();
        assert_eq!(
            got,
            [0x5317_5d61_490b_23df, 0x61da_6f3d_c380_d507, 0x5c0f_df91_ec9a_7bfc]
        );
    }

    #[test]
    fn the_state_round_trips_through_a_checkpoint_header_as_s_and_spare() {
        let mut r = Rng::new(9);
        r.normal();
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["s"].as_array().map(Vec::len), Some(4), "{json}");
        assert!(json["spare"].is_f64(), "{json}");
        let mut back: Rng = serde_json::from_value(json).unwrap();
        assert_eq!(back, r);
        assert_eq!(back.normal().to_bits(), r.normal().to_bits());
        assert_eq!(back.next_u64(), r.next_u64());
    }
}
