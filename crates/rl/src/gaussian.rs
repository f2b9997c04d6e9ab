//! The diagonal Gaussian of the policies, in one place: PPO's rollout (host, per sample), PPO's
//! loss (host, fused; and autodiff, the reference) and SAC's squashed sample (autodiff).
//! Every function keeps the operation order the learners were validated with, so moving a
//! formula here never changes a bit of a training run.

use burn::tensor::Tensor;

/// `0.5 ln(2 pi)`: minus the log-density of a standard normal at its mean.
pub(crate) const HALF_LN_2PI: f64 = 0.918_938_533_204_672_7;

/// [`HALF_LN_2PI`] in f32 (the same bits as the literal `0.918_938_5`).
pub(crate) const HALF_LN_2PI_F32: f32 = HALF_LN_2PI as f32;

/// Minus the log-density of one element, without the `0.5 ln(2 pi)` constant:
/// `diff^2 / (2 var) + ln(var) / 2`, for a sample `diff` away from the mean.
#[inline]
pub(crate) fn neg_log_density(diff: f64, var: f64) -> f64 {
    0.5 * diff * diff / var + 0.5 * var.ln()
}

/// Entropy of one element of variance `var`: `0.5 + 0.5 ln(2 pi) + ln(var) / 2`.
#[inline]
pub(crate) fn entropy(var: f64) -> f64 {
    0.5 + HALF_LN_2PI + 0.5 * var.ln()
}

/// Log-probability of a sample `mean + std * z` summed over `a` elements, minus the
/// `-sum z^2 / 2` term the caller adds per draw: `-sum(log_std) - a ln(2 pi) / 2`.
pub(crate) fn log_prob_const(log_std: &[f32]) -> f32 {
    -log_std.iter().sum::<f32>() - log_std.len() as f32 * HALF_LN_2PI_F32
}

/// `log N(mean + diff; mean, var)` summed over the last axis: `[m, b, a] -> [m, b, 1]` (the
/// autodiff reference of PPO's fused loss).
#[cfg(test)]
pub(crate) fn log_prob(diff: Tensor<3>, var: Tensor<3>) -> Tensor<3> {
    (diff.powi_scalar(2) / var.clone() * -0.5 - var.log() * 0.5 - HALF_LN_2PI).sum_dim(2)
}

/// `log N(mean + std * eps; mean, std)` summed over the last axis, from the standard-normal
/// draw `eps` and `log_std` (the reparameterised form SAC differentiates).
pub(crate) fn log_prob_of_noise(eps: Tensor<3>, log_std: Tensor<3>) -> Tensor<3> {
    (eps.powi_scalar(2) * -0.5 - log_std - HALF_LN_2PI_F32).sum_dim(2)
}

/// Entropy summed over the last axis, from the variances.
#[cfg(test)]
pub(crate) fn entropy_of(var: Tensor<3>) -> Tensor<3> {
    (var.log() * 0.5 + (0.5 + HALF_LN_2PI)).sum_dim(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_ln_2pi_is_that() {
        assert!((HALF_LN_2PI - 0.5 * (2.0 * std::f64::consts::PI).ln()).abs() < 1e-15);
        assert_eq!(HALF_LN_2PI_F32.to_bits(), 0.918_938_5f32.to_bits());
    }

    #[test]
    fn host_density_and_entropy_match_the_closed_forms() {
        // N(0.3; 0, 4): ln p = -0.09/8 - ln(2) - 0.5 ln(2 pi).
        let lp = -HALF_LN_2PI - neg_log_density(0.3, 4.0);
        let want = -0.09 / 8.0 - 2f64.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
        assert!((lp - want).abs() < 1e-14, "{lp} vs {want}");
        // Entropy of N(., 4) = 0.5 ln(2 pi e 4).
        let h = entropy(4.0);
        let want = 0.5 * (2.0 * std::f64::consts::PI * std::f64::consts::E * 4.0).ln();
        assert!((h - want).abs() < 1e-14, "{h} vs {want}");
        // The rollout's constant: std = 0.5 and 2 in two elements, z = 0 gives the density
        // at the mean, -ln(0.5) - ln(2) - ln(2 pi) = -ln(2 pi).
        let c = log_prob_const(&[0.5f32.ln(), 2f32.ln()]);
        assert!((c as f64 + (2.0 * std::f64::consts::PI).ln()).abs() < 1e-6, "{c}");
    }
}
