//! Units as written in scenario files and on the command line:
//! probabilities (`0.3` or `"30%"`) and durations (a number in the field's
//! own unit, decimals allowed, or a string with a unit: `"250ms"`, `"10s"`,
//! `"1.5 min"`, `"500us"`; [`parse_duration`]), validated at parse time.
//!
//! Physical ranges (docs/spec.md §1). A [`Millis`] is any finite duration
//! ≥ 0; each model then bounds its own durations to what a lab could mean,
//! far beyond any experiment and far inside the `u64` nanosecond clock
//! (which lasts 584 years), so that no sum of them can saturate:
//!
//! | quantity | accepted |
//! |---|---|
//! | a delay's `min_ms` and `jitter_ms`, an outage window (`min_ms`, `max_ms`) | 0 to [`MAX_DURATION_MS`] (one hour) |
//! | a delay component's mean `1/rate` | up to 10^10 ms ([`super::delay::MIN_RATE_PER_MS`]) |
//! | an outage cooldown (`cooldown_ms`) | 0 to [`MAX_COOLDOWN_MS`] (one week) |
//! | a count of frames (`max_frames`, `cooldown_frames`), a Lomax scale (`lambda`) | up to [`MAX_FRAMES`] (one hour at 1 MHz) |
//! | a phase start (`start_s`, `start_ms`) | 0 to [`MAX_PHASE_START_MS`] (one year) |

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

/// `p` as a [`Probability`], for tests (panics where it is not one).
#[cfg(test)]
pub(crate) fn prob(p: f64) -> Probability {
    Probability::new(p).unwrap()
}

impl fmt::Display for Probability {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A value written as a number or as text (`"30%"`, `"250ms"`): `number`
/// takes the one, `text` the other; `expecting` says what is accepted.
struct NumberOrText<T> {
    expecting: &'static str,
    number: fn(f64) -> Result<T, String>,
    text: fn(&str) -> Result<T, String>,
}

impl<T> serde::de::Visitor<'_> for NumberOrText<T> {
    type Value = T;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.expecting)
    }
    fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<T, E> {
        (self.number)(v).map_err(E::custom)
    }
    fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<T, E> {
        (self.number)(v as f64).map_err(E::custom)
    }
    fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<T, E> {
        (self.number)(v as f64).map_err(E::custom)
    }
    fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<T, E> {
        (self.text)(v).map_err(E::custom)
    }
}

impl<'de> Deserialize<'de> for Probability {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NumberOrText {
            expecting: "a probability: a number in [0, 1] or a percentage like \"30%\"",
            number: Probability::new,
            text: Probability::parse,
        })
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
        d.deserialize_any(NumberOrText {
            expecting: "a number of milliseconds ≥ 0 (decimals allowed) or a duration with its unit, like \"250ms\" or \"2s\"",
            number: Millis::new,
            text: |v| parse_duration(v, TimeUnit::Ms).and_then(Millis::new),
        })
    }
}

/// The unit a duration is read in when it is written as a bare number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeUnit {
    Ns,
    Us,
    Ms,
    S,
}

impl TimeUnit {
    /// Nanoseconds in one of this unit.
    fn ns(self) -> f64 {
        match self {
            TimeUnit::Ns => 1.0,
            TimeUnit::Us => 1e3,
            TimeUnit::Ms => 1e6,
            TimeUnit::S => 1e9,
        }
    }

    fn suffix(self) -> &'static str {
        match self {
            TimeUnit::Ns => "ns",
            TimeUnit::Us => "us",
            TimeUnit::Ms => "ms",
            TimeUnit::S => "s",
        }
    }
}

/// Parses a duration, in `unit` (the result is in that unit too): a bare
/// number (`"250"`: already in `unit`) or a number with one of the units
/// `ns`, `us` (or `µs`), `ms`, `s`, `min`, `h` (`"250ms"`, `"1.5 s"`). The
/// result is finite and ≥ 0; the error says what is accepted.
pub fn parse_duration(text: &str, unit: TimeUnit) -> Result<f64, String> {
    const UNITS: [(&str, f64); 7] =
        [("min", 60e9), ("ns", 1.0), ("us", 1e3), ("µs", 1e3), ("ms", 1e6), ("h", 3600e9), ("s", 1e9)];
    let t = text.trim();
    let bad = || {
        format!(
            "\"{text}\" is not a duration: expected a number ≥ 0 (in {}) or a number with a unit (ns, us, ms, s, min, h), like \"250ms\" or \"10s\"",
            unit.suffix()
        )
    };
    let (num, ns) = match UNITS.iter().find(|(u, _)| t.ends_with(u)) {
        Some((u, f)) => (t[..t.len() - u.len()].trim(), *f),
        None => (t, unit.ns()),
    };
    let v: f64 = num.parse().map_err(|_| bad())?;
    let out = if ns == unit.ns() { v } else { v * ns / unit.ns() };
    if out.is_finite() && out >= 0.0 {
        Ok(out)
    } else {
        Err(bad())
    }
}

/// The longest delay or outage window: one hour, in ms.
pub const MAX_DURATION_MS: f64 = 3_600_000.0;

/// The longest outage cooldown: one week, in ms. Longer than any run, so
/// it reads "one window, then none"; the fits search cooldowns up to 1e8 ms.
pub const MAX_COOLDOWN_MS: f64 = 604_800_000.0;

/// The most frames a window, cooldown or Lomax scale may count: one hour at
/// 1 MHz.
pub const MAX_FRAMES: u64 = 3_600_000_000;

/// The latest phase start: one year (365.25 days), in ms.
pub const MAX_PHASE_START_MS: f64 = 31_557_600_000.0;

/// A number as an error message shows it: plainly in the everyday range,
/// in scientific notation beyond it (`1e300`, not three hundred zeros).
pub fn show(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e16).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Checks that the duration `ms` of `field` is at most `max_ms`; the error
/// states the range and what the limit is (`what`, e.g. "one hour").
pub(crate) fn at_most_ms(field: &str, ms: f64, max_ms: f64, what: &str) -> Result<(), super::ParamError> {
    if ms <= max_ms {
        Ok(())
    } else {
        Err(super::ParamError::new(field, format!("{} ms is out of range: expected 0 to {max_ms} ms ({what})", show(ms))))
    }
}

/// Checks that the count `n` of `field` is at most [`MAX_FRAMES`].
pub(crate) fn at_most_frames(field: &str, n: u64) -> Result<(), super::ParamError> {
    if n <= MAX_FRAMES {
        Ok(())
    } else {
        Err(super::ParamError::new(
            field,
            format!("{n} frames is out of range: expected at most {MAX_FRAMES} (one hour at 1 MHz)"),
        ))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_in_their_unit_or_the_fields() {
        assert_eq!(parse_duration("250ms", TimeUnit::S), Ok(0.25));
        assert_eq!(parse_duration("10s", TimeUnit::S), Ok(10.0));
        assert_eq!(parse_duration(" 1.5 min ", TimeUnit::S), Ok(90.0));
        assert_eq!(parse_duration("2h", TimeUnit::Ms), Ok(7_200_000.0));
        assert_eq!(parse_duration("500us", TimeUnit::Ms), Ok(0.5));
        assert_eq!(parse_duration("500µs", TimeUnit::Ms), Ok(0.5));
        assert_eq!(parse_duration("1500ns", TimeUnit::Us), Ok(1.5));
        assert_eq!(parse_duration("12", TimeUnit::Ms), Ok(12.0));
        assert_eq!(parse_duration("12", TimeUnit::S), Ok(12.0));
        assert_eq!(parse_duration("1e3", TimeUnit::Ms), Ok(1000.0));
        assert_eq!(parse_duration("1e-3s", TimeUnit::Ms), Ok(1.0));
        for bad in ["", "ms", "-1s", "10 parsecs", "1e400s", "NaN", "inf"] {
            let e = parse_duration(bad, TimeUnit::S).unwrap_err();
            assert!(e.contains("is not a duration") && e.contains("250ms"), "{bad}: {e}");
        }
    }

    #[test]
    fn millis_fields_accept_units() {
        #[derive(Deserialize)]
        struct F {
            a: Millis,
            b: Millis,
        }
        let f: F = toml::from_str("a = \"2s\"\nb = 7.5").unwrap();
        assert_eq!((f.a.get(), f.b.get()), (2000.0, 7.5));
        let e = toml::from_str::<F>("a = \"2 fortnights\"\nb = 1").err().unwrap().to_string();
        assert!(e.contains("is not a duration"), "{e}");
    }
}
