//! `markov4` (docs/spec.md §3.3): netem's 4-state loss model (`loss state ...`).
//!
//! States: 1 = delivered in a gap, 2 = delivered in a burst, 3 = lost in a
//! burst, 4 = isolated loss; start in 1. Transitions: 1→4 `p14`, 1→3 `p13`
//! (else stay), 2→3 `p23` (else stay), 3→2 `p32`, 3→1 `p31` (else stay),
//! 4→1 always. Per frame one draw moves the chain, partitioned in netem's
//! order (1: `[0, p14)` → 4, `[p14, p14 + p13)` → 3; 3: `[0, p32)` → 2,
//! `[p32, p32 + p31)` → 1), and the frame is lost iff the new state is 3 or 4.
//! Defaults are those of iproute2's `tc`: `p31 = 1 − p13`, `p32 = 0`,
//! `p23 = 1`, `p14 = 0`.
//!
//! Long-run loss. Balance gives `π4 = p14 π1`, `π3 = (p13/p31) π1` and
//! `π2 = (p32/p23) π3`, so the lost fraction `π3 + π4` is
//! `(p13·p23 + p14·p31·p23) / (p31·p23 + p14·p31·p23 + p13·p23 + p13·p32)`.
//! Two corners make that 0/0 and are taken apart: `p13 = 0` (state 3 is
//! never reached; the loss is `p14/(1 + p14)`, from the 1↔4 alternation) and
//! `p23 = p32 = 0` (state 2 is never reached; the loss is
//! `(p13 + p14·p31)/(p31 + p14·p31 + p13)`).

use super::draw::{threshold, u53, ALWAYS};
use super::{Model, ParamError, Probability, StageRng, Verdict};
use serde::{Deserialize, Serialize};

/// How far a state's outgoing probabilities may sum past 1 (rounding in
/// decimal inputs such as `0.7 + 0.3`).
const SUM_TOLERANCE: f64 = 1e-9;

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Markov4Params {
    pub p13: Probability,
    /// Defaults as netem: `1 - p13`.
    pub p31: Option<Probability>,
    /// Defaults as netem: 0.
    pub p32: Option<Probability>,
    /// Defaults as netem: 1.
    pub p23: Option<Probability>,
    /// Defaults as netem: 0.
    pub p14: Option<Probability>,
}

impl Markov4Params {
    /// netem's `loss state p13 p31 p32 p23 p14`, every parameter given.
    pub fn new(p13: f64, p31: f64, p32: f64, p23: f64, p14: f64) -> Result<Self, ParamError> {
        use super::units::probability;
        Ok(Markov4Params {
            p13: probability("p13", p13)?,
            p31: Some(probability("p31", p31)?),
            p32: Some(probability("p32", p32)?),
            p23: Some(probability("p23", p23)?),
            p14: Some(probability("p14", p14)?),
        })
    }
}

/// State indices (0-based) of the four netem states.
const GAP_DELIVERED: u8 = 0;
const BURST_DELIVERED: u8 = 1;
const BURST_LOST: u8 = 2;
const ISOLATED_LOST: u8 = 3;

/// One state's move: a draw below `first` goes to `to_first`, below `second`
/// to `to_second`, otherwise to `otherwise`.
#[derive(Debug, Clone, Copy)]
struct Move {
    first: u64,
    second: u64,
    to_first: u8,
    to_second: u8,
    otherwise: u8,
}

/// A validated `markov4` stage and its state.
#[derive(Debug, Clone)]
pub struct Markov4 {
    p13: f64,
    p31: f64,
    p32: f64,
    p23: f64,
    p14: f64,
    moves: [Move; 4],
    state: u8,
}

impl Markov4 {
    pub fn new(params: &Markov4Params) -> Result<Self, ParamError> {
        let p13 = params.p13.get();
        let p31 = params.p31.map_or(1.0 - p13, Probability::get);
        let p32 = params.p32.map_or(0.0, Probability::get);
        let p23 = params.p23.map_or(1.0, Probability::get);
        let p14 = params.p14.map_or(0.0, Probability::get);
        if p13 + p14 > 1.0 + SUM_TOLERANCE {
            return Err(ParamError::new(
                "p14",
                format!("p13 + p14 = {}: state 1 leaves to 3 and to 4 with at most probability 1 in total", p13 + p14),
            ));
        }
        if p31 + p32 > 1.0 + SUM_TOLERANCE {
            return Err(ParamError::new(
                "p32",
                format!(
                    "p31 + p32 = {}{}: state 3 leaves to 1 and to 2 with at most probability 1 in total",
                    p31 + p32,
                    if params.p31.is_none() { " (p31 defaults to 1 − p13)" } else { "" }
                ),
            ));
        }
        let moves = [
            Move {
                first: threshold(p14),
                second: threshold(p14 + p13),
                to_first: ISOLATED_LOST,
                to_second: BURST_LOST,
                otherwise: GAP_DELIVERED,
            },
            Move {
                first: threshold(p23),
                second: threshold(p23),
                to_first: BURST_LOST,
                to_second: BURST_LOST,
                otherwise: BURST_DELIVERED,
            },
            Move {
                first: threshold(p32),
                second: threshold(p32 + p31),
                to_first: BURST_DELIVERED,
                to_second: GAP_DELIVERED,
                otherwise: BURST_LOST,
            },
            Move {
                first: ALWAYS,
                second: ALWAYS,
                to_first: GAP_DELIVERED,
                to_second: GAP_DELIVERED,
                otherwise: GAP_DELIVERED,
            },
        ];
        Ok(Markov4 { p13, p31, p32, p23, p14, moves, state: GAP_DELIVERED })
    }

    /// The long-run lost fraction of frames (module docs).
    pub fn loss_rate_exact(&self) -> f64 {
        let (p13, p31, p32, p23, p14) = (self.p13, self.p31, self.p32, self.p23, self.p14);
        if p13 == 0.0 {
            p14 / (1.0 + p14)
        } else if p23 == 0.0 && p32 == 0.0 {
            (p13 + p14 * p31) / (p31 + p14 * p31 + p13)
        } else {
            (p13 * p23 + p14 * p31 * p23) / (p31 * p23 + p14 * p31 * p23 + p13 * p23 + p13 * p32)
        }
    }

    /// The netem state (1 to 4) after the last frame.
    pub fn state(&self) -> u8 {
        self.state + 1
    }
}

impl Model for Markov4 {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        let r = u53(rng);
        let m = &self.moves[self.state as usize];
        self.state = if r < m.first {
            m.to_first
        } else if r < m.second {
            m.to_second
        } else {
            m.otherwise
        };
        if self.state >= BURST_LOST {
            Verdict::Drop
        } else {
            Verdict::PASS
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::units::prob;
    use rand::{RngExt, SeedableRng};

    fn params(p13: f64, p31: Option<f64>, p32: Option<f64>, p23: Option<f64>, p14: Option<f64>) -> Markov4Params {
        Markov4Params { p13: prob(p13), p31: p31.map(prob), p32: p32.map(prob), p23: p23.map(prob), p14: p14.map(prob) }
    }

    #[test]
    fn netem_defaults_make_bernoulli() {
        // With only p13 given the chain is 1 ⇄ 3 with p31 = 1 − p13: each frame
        // is lost independently with probability p13.
        let m = Markov4::new(&params(0.3, None, None, None, None)).unwrap();
        assert_eq!((m.p31, m.p32, m.p23, m.p14), (0.7, 0.0, 1.0, 0.0));
        assert!((m.loss_rate_exact() - 0.3).abs() < 1e-15);
    }

    #[test]
    fn rejects_outgoing_probabilities_above_one() {
        assert_eq!(Markov4::new(&params(0.6, None, None, None, Some(0.5))).unwrap_err().field, "p14");
        assert_eq!(Markov4::new(&params(0.2, Some(0.5), Some(0.6), None, None)).unwrap_err().field, "p32");
        // Default p31 = 1 − p13 = 0.9 leaves no room for p32 = 0.2.
        let e = Markov4::new(&params(0.1, None, Some(0.2), None, None)).unwrap_err();
        assert_eq!(e.field, "p32");
        assert!(e.problem.contains("defaults"), "{e}");
        // Decimal rounding right at 1 is fine.
        Markov4::new(&params(0.7, None, None, None, Some(0.3))).unwrap();
        assert!(toml::from_str::<Markov4Params>("p13 = 0.1\np41 = 0.2").is_err());
    }

    /// The long-run loss of the chain started in state 1, by averaging the
    /// state distribution over many steps.
    fn cesaro_loss(m: &Markov4) -> f64 {
        let (p13, p31, p32, p23, p14) = (m.p13, m.p31, m.p32, m.p23, m.p14);
        let t = [
            [1.0 - p13 - p14, 0.0, p13, p14],
            [0.0, 1.0 - p23, p23, 0.0],
            [p31, p32, 1.0 - p31 - p32, 0.0],
            [1.0, 0.0, 0.0, 0.0],
        ];
        let mut d = [1.0, 0.0, 0.0, 0.0];
        let steps = 200_000;
        let mut lost = 0.0;
        for _ in 0..steps {
            let mut next = [0.0; 4];
            for i in 0..4 {
                for j in 0..4 {
                    next[j] += d[i] * t[i][j];
                }
            }
            d = next;
            lost += d[2] + d[3];
        }
        lost / steps as f64
    }

    #[test]
    fn closed_form_matches_the_chain_including_corners() {
        let cases = [
            params(0.05, Some(0.4), Some(0.1), Some(0.2), Some(0.01)),
            params(0.3, None, None, None, None),
            params(0.0, Some(0.4), Some(0.1), Some(0.2), Some(0.2)),
            params(0.1, Some(0.5), Some(0.0), Some(0.0), Some(0.2)),
            params(0.1, Some(0.0), Some(0.0), Some(0.0), Some(0.2)),
            params(0.1, Some(0.0), Some(0.3), Some(0.6), Some(0.0)),
            params(0.1, Some(0.2), Some(0.3), Some(0.0), Some(0.0)),
            params(1.0, Some(1.0), Some(0.0), Some(1.0), Some(0.0)),
        ];
        for p in cases {
            let m = Markov4::new(&p).unwrap();
            let (exact, chain) = (m.loss_rate_exact(), cesaro_loss(&m));
            // The Cesàro average converges like 1/steps.
            assert!((exact - chain).abs() < 1e-4, "{p:?}: {exact} vs {chain}");
        }
    }

    #[test]
    fn moves_as_netem_partitions_the_draw() {
        // A reference step with a floating-point draw, in netem's order.
        let p = params(0.05, Some(0.4), Some(0.1), Some(0.2), Some(0.01));
        let mut m = Markov4::new(&p).unwrap();
        let mut rng = StageRng::seed_from_u64(9);
        let mut reference_rng = rng.clone();
        let mut state = 1u8;
        for t in 0..200_000 {
            let u: f64 = reference_rng.random();
            state = match state {
                1 if u < 0.01 => 4,
                1 if u < 0.06 => 3,
                1 => 1,
                2 if u < 0.2 => 3,
                2 => 2,
                3 if u < 0.1 => 2,
                3 if u < 0.5 => 1,
                3 => 3,
                _ => 1,
            };
            let expected = if state >= 3 { Verdict::Drop } else { Verdict::PASS };
            assert_eq!(m.decide(t, &mut rng), expected, "frame {t}");
            assert_eq!(m.state(), state);
        }
    }

    #[test]
    fn value_stability() {
        let mut m = Markov4::new(&params(0.05, Some(0.4), Some(0.1), Some(0.2), Some(0.01))).unwrap();
        let mut rng = StageRng::seed_from_u64(42);
        let fates: String = (0..64).map(|i| if m.decide(i, &mut rng) == Verdict::Drop { 'x' } else { '.' }).collect();
        assert_eq!(fates, PINNED_FATES);
    }
    const PINNED_FATES: &str = ".................xx.........................x...................";
}
