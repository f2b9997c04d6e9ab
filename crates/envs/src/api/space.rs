use serde::{Deserialize, Serialize};

/// A box in R^n: element `i` lies in `[low[i], high[i]]` (Gymnasium's `Box`, flat `f32`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoxSpace {
    /// Lower bound per element (may be `-inf`).
    pub low: Vec<f32>,
    /// Upper bound per element (may be `+inf`).
    pub high: Vec<f32>,
}

impl BoxSpace {
    /// A box with the same bounds on every element.
    pub fn uniform(dim: usize, low: f32, high: f32) -> Self {
        Self {
            low: vec![low; dim],
            high: vec![high; dim],
        }
    }

    /// Number of elements.
    pub fn dim(&self) -> usize {
        self.low.len()
    }

    /// Whether `x` has the right length and every element lies within bounds (NaN never does).
    pub fn contains(&self, x: &[f32]) -> bool {
        x.len() == self.dim()
            && x.iter()
                .zip(&self.low)
                .zip(&self.high)
                .all(|((v, lo), hi)| *v >= *lo && *v <= *hi)
    }

    /// Clamp `x` into the box in place (NaN stays NaN: callers reject it first).
    pub fn clamp(&self, x: &mut [f32]) {
        for ((v, lo), hi) in x.iter_mut().zip(&self.low).zip(&self.high) {
            *v = v.clamp(*lo, *hi);
        }
    }
}
