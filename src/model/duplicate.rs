//! `duplicate` (docs/spec.md §3.8): each frame is delivered twice with
//! probability `p`.
//!
//! The stage passes every frame without delay; with probability `p` its
//! verdict is [`Verdict::Duplicate`]: the frame goes on, and so does a copy,
//! at the same time, through the *same later stages* of the pipeline (which
//! see it, draw for it and may drop or delay it as any frame). A copy is not
//! duplicated again by this stage; a later `duplicate` stage may copy it. The
//! scenario runs the original through the rest of the pipeline first, then
//! its copies, so a stateful later stage (a `fifo` delay, a loss chain) sees
//! the copy right after the original.
//!
//! netem's `duplicate P` clones the packet and enqueues the clone at the root
//! qdisc again, through the whole netem (its loss, delay, corruption) with
//! duplication switched off for it; here the copy passes the stages after this
//! one, so put `duplicate` first to match netem. netem's `duplicate P CORR`
//! correlation has the flaw described in §3.7 and is not offered.
//!
//! Long-run: copies per frame reaching the stage `= p`. Draws: one 53-bit
//! uniform per frame.

use super::draw::{threshold, u53};
use super::{Model, ParamError, Probability, StageRng, Verdict};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DuplicateParams {
    /// Probability that a frame is delivered twice.
    pub p: Probability,
}

impl DuplicateParams {
    pub fn new(p: f64) -> Result<Self, ParamError> {
        Ok(DuplicateParams { p: super::units::probability("p", p)? })
    }
}

/// A validated `duplicate` stage.
#[derive(Debug, Clone)]
pub struct Duplicate {
    threshold: u64,
    p: f64,
}

impl Duplicate {
    pub fn new(params: &DuplicateParams) -> Result<Self, ParamError> {
        let p = params.p.get();
        if !(0.0..=1.0).contains(&p) {
            return Err(ParamError::new("p", format!("{p}: expected a probability in [0, 1]")));
        }
        Ok(Duplicate { threshold: threshold(p), p })
    }

    /// The exact long-run number of copies per frame reaching the stage.
    pub fn duplicate_rate_exact(&self) -> f64 {
        self.p
    }
}

impl Model for Duplicate {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        if u53(rng) < self.threshold {
            Verdict::Duplicate
        } else {
            Verdict::PASS
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn construction_and_bad_parameters() {
        assert_eq!(Duplicate::new(&DuplicateParams::new(0.25).unwrap()).unwrap().duplicate_rate_exact(), 0.25);
        assert_eq!(DuplicateParams::new(1.5).unwrap_err().field, "p");
        assert_eq!(DuplicateParams::new(-0.1).unwrap_err().field, "p");
        let p: DuplicateParams = toml::from_str("p = \"1%\"").unwrap();
        assert_eq!(p, DuplicateParams::new(0.01).unwrap());
        assert!(toml::from_str::<DuplicateParams>("p = 0.1\ncorrelation = 0.2").is_err());
    }

    #[test]
    fn certain_and_impossible() {
        let mut rng = StageRng::seed_from_u64(1);
        let mut always = Duplicate::new(&DuplicateParams::new(1.0).unwrap()).unwrap();
        let mut never = Duplicate::new(&DuplicateParams::new(0.0).unwrap()).unwrap();
        for t in 0..10_000 {
            assert_eq!(always.decide(t, &mut rng), Verdict::Duplicate);
            assert_eq!(never.decide(t, &mut rng), Verdict::PASS);
        }
    }

    #[test]
    fn value_stability() {
        let mut d = Duplicate::new(&DuplicateParams::new(0.3).unwrap()).unwrap();
        let mut rng = StageRng::seed_from_u64(42);
        let got: Vec<bool> = (0..16).map(|t| d.decide(t, &mut rng) == Verdict::Duplicate).collect();
        assert_eq!(got, PINNED);
    }
    const PINNED: [bool; 16] =
        [false, false, false, false, false, false, true, false, true, false, false, false, false, true, false, false];
}
