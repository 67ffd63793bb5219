//! `reorder` (docs/spec.md §3.10): netem's `delay D reorder P gap N`. Every
//! frame is delayed by `delay_ms`, except that, once `gap − 1` frames have
//! been delayed since the last one sent early, each frame is a candidate
//! and is sent at once (no delay) with probability `p`, so it overtakes the
//! frames still held.
//!
//! The rule, as netem's enqueue has it: a counter starts at 0; a frame with
//! `counter < gap − 1`, or a candidate not picked, is delayed and the counter
//! goes up by one; a picked candidate goes at once and the counter returns
//! to 0. `gap = 1` (tc's default when only `reorder P` is given) makes every
//! frame a candidate. netem's reorder correlation has the flaw of §3.7 and is
//! not offered; netem's jittered delays are not combined here (the held
//! frames get the constant `delay_ms`).
//!
//! Long-run: the picks form a renewal process with cycles of `gap − 1`
//! frames plus a geometric number of candidates (mean `1/p`), so the fraction
//! of frames sent at once is `1 / (gap − 1 + 1/p)` (0 for `p = 0`). Draws:
//! one 53-bit uniform per candidate, none for the other frames.

use super::draw::{threshold, u53};
use super::units::{at_most_ms, MAX_DURATION_MS};
use super::{Millis, Model, ParamError, Probability, StageRng, Verdict};
use serde::{Deserialize, Serialize};

/// The longest gap: one hour of frames at 1 MHz, as every frame count.
pub const MAX_GAP: u64 = super::units::MAX_FRAMES;

fn one() -> u64 {
    1
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReorderParams {
    /// Probability that a candidate is sent at once.
    pub p: Probability,
    /// Every `gap`-th frame at the earliest is a candidate (≥ 1; 1 by default).
    #[serde(default = "one")]
    pub gap: u64,
    /// The delay of every frame not sent at once.
    pub delay_ms: Millis,
}

impl ReorderParams {
    pub fn new(p: f64, gap: u64, delay_ms: f64) -> Result<Self, ParamError> {
        Ok(ReorderParams {
            p: super::units::probability("p", p)?,
            gap,
            delay_ms: super::units::millis("delay_ms", delay_ms)?,
        })
    }
}

/// A validated `reorder` stage and its counter.
#[derive(Debug, Clone)]
pub struct Reorder {
    threshold: u64,
    p: f64,
    gap: u64,
    delay_ns: u64,
    counter: u64,
}

impl Reorder {
    pub fn new(params: &ReorderParams) -> Result<Self, ParamError> {
        if !(1..=MAX_GAP).contains(&params.gap) {
            return Err(ParamError::new(
                "gap",
                format!("{}: expected a whole number of frames from 1 to {MAX_GAP} (1 makes every frame a candidate)", params.gap),
            ));
        }
        let delay_ms = params.delay_ms.get();
        at_most_ms("delay_ms", delay_ms, MAX_DURATION_MS, "one hour")?;
        let p = params.p.get();
        Ok(Reorder { threshold: threshold(p), p, gap: params.gap, delay_ns: params.delay_ms.to_ns(), counter: 0 })
    }

    /// The exact long-run fraction of frames sent at once:
    /// `1 / (gap − 1 + 1/p)`.
    pub fn early_fraction_exact(&self) -> f64 {
        if self.p == 0.0 {
            0.0
        } else {
            1.0 / ((self.gap - 1) as f64 + 1.0 / self.p)
        }
    }

    /// The exact mean delay in ms: `delay_ms` times the frames held.
    pub fn mean_ms_exact(&self) -> f64 {
        self.delay_ns as f64 / 1e6 * (1.0 - self.early_fraction_exact())
    }

    pub fn may_reorder(&self) -> bool {
        self.p > 0.0 && self.delay_ns > 0
    }
}

impl Model for Reorder {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        if self.counter + 1 < self.gap || u53(rng) >= self.threshold {
            self.counter += 1;
            Verdict::Pass { delay_ns: self.delay_ns }
        } else {
            self.counter = 0;
            Verdict::PASS
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn model(p: f64, gap: u64) -> Reorder {
        Reorder::new(&ReorderParams::new(p, gap, 10.0).unwrap()).unwrap()
    }

    #[test]
    fn construction_and_bad_parameters() {
        assert_eq!(Reorder::new(&ReorderParams::new(0.5, 0, 10.0).unwrap()).unwrap_err().field, "gap");
        assert_eq!(Reorder::new(&ReorderParams::new(0.5, 2, 3_600_001.0).unwrap()).unwrap_err().field, "delay_ms");
        assert_eq!(ReorderParams::new(1.5, 2, 1.0).unwrap_err().field, "p");
        let p: ReorderParams = toml::from_str("p = \"25%\"\ndelay_ms = 10").unwrap();
        assert_eq!(p.gap, 1);
        assert!((model(0.25, 5).early_fraction_exact() - 1.0 / 8.0).abs() < 1e-15);
        assert_eq!(model(0.25, 1).early_fraction_exact(), 0.25);
        assert_eq!(model(0.0, 3).early_fraction_exact(), 0.0);
    }

    #[test]
    fn a_certain_pick_sends_every_gapth_frame_at_once() {
        // p = 1, gap 3: frames 3, 6, 9, … (1-based) go at once.
        let mut m = model(1.0, 3);
        let mut rng = StageRng::seed_from_u64(1);
        let got: Vec<bool> = (0..9).map(|t| m.decide(t, &mut rng) == Verdict::PASS).collect();
        assert_eq!(got, [false, false, true, false, false, true, false, false, true]);
    }

    #[test]
    fn frames_inside_the_gap_draw_nothing() {
        let mut m = model(0.5, 4);
        let mut rng = StageRng::seed_from_u64(2);
        let before = rng.clone();
        for t in 0..3 {
            assert_eq!(m.decide(t, &mut rng), Verdict::Pass { delay_ns: 10_000_000 });
        }
        assert_eq!(rng, before);
    }

    #[test]
    fn value_stability() {
        let mut m = model(0.3, 2);
        let mut rng = StageRng::seed_from_u64(42);
        let got: Vec<bool> = (0..16).map(|t| m.decide(t, &mut rng) == Verdict::PASS).collect();
        assert_eq!(got, PINNED);
    }
    const PINNED: [bool; 16] =
        [false, false, false, false, false, false, false, true, false, false, true, false, false, false, false, false];
}
