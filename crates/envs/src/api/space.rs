use serde::{Deserialize, Serialize};

/// A box in R^n: element `i` lies in `[low[i], high[i]]` (Gymnasium's `Box`, flat `f32`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoxSpace {
    /// Lower bound per element (may be `-inf`).
    #[serde(with = "bounds::low")]
    pub low: Vec<f32>,
    /// Upper bound per element (may be `+inf`).
    #[serde(with = "bounds::high")]
    pub high: Vec<f32>,
}

/// JSON has no infinity (serde_json writes `null`), so unbounded elements are written as the
/// strings `"inf"` / `"-inf"`; a `null` read back is the open side of that bound.
mod bounds {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    #[serde(untagged)]
    enum Bound {
        Num(f32),
        Text(String),
        Null(Option<()>),
    }

    fn ser<S: Serializer>(v: &[f32], s: S) -> Result<S::Ok, S::Error> {
        let b: Vec<Bound> = v
            .iter()
            .map(|&x| match x {
                x if x.is_finite() => Bound::Num(x),
                x if x > 0.0 => Bound::Text("inf".into()),
                x if x < 0.0 => Bound::Text("-inf".into()),
                _ => Bound::Text("nan".into()),
            })
            .collect();
        b.serialize(s)
    }

    fn de<'de, D: Deserializer<'de>>(d: D, open: f32) -> Result<Vec<f32>, D::Error> {
        Vec::<Bound>::deserialize(d)?
            .into_iter()
            .map(|b| match b {
                Bound::Num(x) => Ok(x),
                Bound::Null(_) => Ok(open),
                Bound::Text(t) => match t.as_str() {
                    "inf" | "+inf" => Ok(f32::INFINITY),
                    "-inf" => Ok(f32::NEG_INFINITY),
                    "nan" => Ok(f32::NAN),
                    _ => Err(serde::de::Error::custom(format!("bad bound {t:?}"))),
                },
            })
            .collect()
    }

    pub mod low {
        use super::*;
        pub fn serialize<S: Serializer>(v: &[f32], s: S) -> Result<S::Ok, S::Error> {
            ser(v, s)
        }
        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f32>, D::Error> {
            de(d, f32::NEG_INFINITY)
        }
    }

    pub mod high {
        use super::*;
        pub fn serialize<S: Serializer>(v: &[f32], s: S) -> Result<S::Ok, S::Error> {
            ser(v, s)
        }
        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f32>, D::Error> {
            de(d, f32::INFINITY)
        }
    }
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

#[cfg(test)]
mod tests {
    use super::BoxSpace;

    #[test]
    fn unbounded_spaces_survive_a_json_round_trip() {
        let b = BoxSpace {
            low: vec![f32::NEG_INFINITY, -1.5, 0.0],
            high: vec![f32::INFINITY, 2.0, f32::INFINITY],
        };
        let text = serde_json::to_string(&b).unwrap();
        assert!(!text.contains("null"), "{text}");
        assert_eq!(serde_json::from_str::<BoxSpace>(&text).unwrap(), b);
        // Files written before this format hold null for an infinite bound.
        let old: BoxSpace = serde_json::from_str(r#"{"low":[null,0.5],"high":[1.0,null]}"#).unwrap();
        assert_eq!(old.low, [f32::NEG_INFINITY, 0.5]);
        assert_eq!(old.high, [1.0, f32::INFINITY]);
        assert!(serde_json::from_str::<BoxSpace>(r#"{"low":["x"],"high":[1]}"#).is_err());
    }
}
