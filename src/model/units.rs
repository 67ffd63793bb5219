//! Units as written in scenario files: probabilities (`0.3` or `"30%"`) and
//! milliseconds (decimals allowed), validated at parse time.

use serde::{Deserialize, Deserializer};
use std::fmt;

/// A probability in `[0, 1]`. Accepts a number or a percentage string such as
/// `"30%"` (or `"30 %"`).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, serde::Serialize)]
#[serde(transparent)]
pub struct Probability(f64);

impl Probability {
    /// Validates `p`; the error text says what is accepted.
    pub fn new(p: f64) -> Result<Self, String> {
        if p.is_finite() && (0.0..=1.0).contains(&p) {
            Ok(Probability(p))
        } else {
            Err(format!("{p} is not a probability: expected a number in [0, 1] or a percentage like \"30%\""))
        }
    }

    pub fn get(self) -> f64 {
        self.0
    }

    /// Parses `"0.3"` or `"30%"`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let t = s.trim();
        if let Some(pct) = t.strip_suffix('%') {
            let v: f64 = pct.trim().parse().map_err(|_| format!("\"{s}\" is not a percentage: expected e.g. \"30%\""))?;
            Probability::new(v / 100.0)
        } else {
            let v: f64 = t.parse().map_err(|_| format!("\"{s}\" is not a probability: expected a number in [0, 1] or e.g. \"30%\""))?;
            Probability::new(v)
        }
    }
}

impl fmt::Display for Probability {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

impl<'de> Deserialize<'de> for Probability {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Probability;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a probability: a number in [0, 1] or a percentage like \"30%\"")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Probability, E> {
                Probability::new(v).map_err(E::custom)
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Probability, E> {
                Probability::new(v as f64).map_err(E::custom)
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Probability, E> {
                Probability::new(v as f64).map_err(E::custom)
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Probability, E> {
                Probability::parse(v).map_err(E::custom)
            }
        }
        d.deserialize_any(V)
    }
}

/// A non-negative, finite duration in milliseconds (decimals allowed).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, serde::Serialize)]
#[serde(transparent)]
pub struct Millis(f64);

impl Millis {
    pub fn new(ms: f64) -> Result<Self, String> {
        if ms.is_finite() && ms >= 0.0 {
            Ok(Millis(ms))
        } else {
            Err(format!("{ms} is not a duration: expected a finite number of milliseconds ≥ 0"))
        }
    }

    pub fn get(self) -> f64 {
        self.0
    }

    /// Nanoseconds, rounded to the nearest.
    pub fn to_ns(self) -> u64 {
        ms_to_ns(self.0)
    }
}

impl<'de> Deserialize<'de> for Millis {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Millis;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number of milliseconds ≥ 0 (decimals allowed)")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Millis, E> {
                Millis::new(v).map_err(E::custom)
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Millis, E> {
                Millis::new(v as f64).map_err(E::custom)
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Millis, E> {
                Millis::new(v as f64).map_err(E::custom)
            }
        }
        d.deserialize_any(V)
    }
}

/// `ms` as a [`Millis`] for `field`, or the error naming it.
pub(crate) fn millis(field: &str, ms: f64) -> Result<Millis, super::ParamError> {
    Millis::new(ms).map_err(|e| super::ParamError::new(field, e))
}

/// `p` as a [`Probability`] for `field`, or the error naming it.
pub(crate) fn probability(field: &str, p: f64) -> Result<Probability, super::ParamError> {
    Probability::new(p).map_err(|e| super::ParamError::new(field, e))
}

/// Milliseconds (f64) to nanoseconds, rounded to the nearest; saturates.
#[inline]
pub fn ms_to_ns(ms: f64) -> u64 {
    let ns = (ms * 1e6).round();
    if ns <= 0.0 {
        0
    } else if ns >= u64::MAX as f64 {
        u64::MAX
    } else {
        ns as u64
    }
}
