//! Constants of the diagonal Gaussian policies, in one place for PPO (rollout and loss) and SAC.

/// `0.5 ln(2 pi)`: minus the log-density of a standard normal at its mean.
pub(crate) const HALF_LN_2PI: f64 = 0.918_938_533_204_672_7;

/// [`HALF_LN_2PI`] in f32 (the same bits as the literal `0.918_938_5`).
pub(crate) const HALF_LN_2PI_F32: f32 = HALF_LN_2PI as f32;

#[cfg(test)]
mod tests {
    #[test]
    fn half_ln_2pi_is_that() {
        assert!((super::HALF_LN_2PI - 0.5 * (2.0 * std::f64::consts::PI).ln()).abs() < 1e-15);
        assert_eq!(super::HALF_LN_2PI_F32.to_bits(), 0.918_938_5f32.to_bits());
    }
}
