//! `gilbert_elliott` (docs/spec.md §3.3): netem's `loss gemodel p r 1-h 1-k`.
//!
//! Two states, Good and Bad, starting in Good. Per frame, as netem does, one
//! draw moves the chain (Good → Bad with `p`, Bad → Good with `r`) and a
//! second draw decides the loss with the probability of the state the chain
//! was in *before* the move: `loss_good` (netem's `1-k`) or `loss_bad`
//! (netem's `1-h`). Defaults are those of iproute2's `tc`: `r = 1 − p`,
//! `loss_good = 0`, `loss_bad = 1` (the simple Gilbert model).
//!
//! Long-run loss: the chain spends `r/(p + r)` of frames in Good and
//! `p/(p + r)` in Bad, so the loss is `(r·loss_good + p·loss_bad)/(p + r)`;
//! with `p = r = 0` it never leaves Good and the loss is `loss_good`.

use super::draw::{threshold, u53};
use super::{Model, ParamError, Probability, StageRng, Verdict};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GilbertElliottParams {
    /// Good → Bad per frame.
    pub p: Probability,
    /// Bad → Good per frame; defaults as netem: `1 - p`.
    pub r: Option<Probability>,
    /// Loss probability in Good (netem's `1-k`); default 0.
    pub loss_good: Option<Probability>,
    /// Loss probability in Bad (netem's `1-h`); default 1.
    pub loss_bad: Option<Probability>,
}

impl GilbertElliottParams {
    /// netem's `loss gemodel p r 1-h 1-k`, every parameter given: Good → Bad
    /// `p`, Bad → Good `r`, loss `loss_good` in Good and `loss_bad` in Bad.
    pub fn new(p: f64, r: f64, loss_good: f64, loss_bad: f64) -> Result<Self, ParamError> {
        use super::units::probability;
        Ok(GilbertElliottParams {
            p: probability("p", p)?,
            r: Some(probability("r", r)?),
            loss_good: Some(probability("loss_good", loss_good)?),
            loss_bad: Some(probability("loss_bad", loss_bad)?),
        })
    }

    /// The simple Gilbert model with netem's defaults: Good → Bad `p`,
    /// Bad → Good `1 − p`, every frame in Bad lost, none in Good.
    pub fn gilbert(p: f64) -> Result<Self, ParamError> {
        Ok(GilbertElliottParams { p: super::units::probability("p", p)?, r: None, loss_good: None, loss_bad: None })
    }
}

/// A validated `gilbert_elliott` stage and its state.
#[derive(Debug, Clone)]
pub struct GilbertElliott {
    p: f64,
    r: f64,
    loss_good: f64,
    loss_bad: f64,
    /// Thresholds (units of 2^-53) indexed by `bad as usize`: of leaving the
    /// state, and of losing the frame in it.
    leave: [u64; 2],
    lose: [u64; 2],
    bad: bool,
}

impl GilbertElliott {
    pub fn new(params: &GilbertElliottParams) -> Result<Self, ParamError> {
        // Probabilities are validated when parsed; a `Probability` is always
        // in [0, 1].
        let p = params.p.get();
        let r = params.r.map_or(1.0 - p, Probability::get);
        let loss_good = params.loss_good.map_or(0.0, Probability::get);
        let loss_bad = params.loss_bad.map_or(1.0, Probability::get);
        Ok(GilbertElliott {
            p,
            r,
            loss_good,
            loss_bad,
            leave: [threshold(p), threshold(r)],
            lose: [threshold(loss_good), threshold(loss_bad)],
            bad: false,
        })
    }

    /// `(r·loss_good + p·loss_bad)/(p + r)` (module docs).
    pub fn loss_rate_exact(&self) -> f64 {
        if self.p + self.r == 0.0 {
            self.loss_good
        } else {
            (self.r * self.loss_good + self.p * self.loss_bad) / (self.p + self.r)
        }
    }

    /// Whether the chain is in Bad (after the last frame's move).
    pub fn is_bad(&self) -> bool {
        self.bad
    }
}

impl Model for GilbertElliott {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        let before = self.bad as usize;
        let move_draw = u53(rng);
        let loss_draw = u53(rng);
        self.bad ^= move_draw < self.leave[before];
        if loss_draw < self.lose[before] {
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
    use rand::SeedableRng;

    fn params(p: f64, r: Option<f64>, loss_good: Option<f64>, loss_bad: Option<f64>) -> GilbertElliottParams {
        GilbertElliottParams {
            p: prob(p),
            r: r.map(prob),
            loss_good: loss_good.map(prob),
            loss_bad: loss_bad.map(prob),
        }
    }

    #[test]
    fn netem_defaults() {
        let m = GilbertElliott::new(&params(0.2, None, None, None)).unwrap();
        assert_eq!((m.p, m.r, m.loss_good, m.loss_bad), (0.2, 0.8, 0.0, 1.0));
        // Simple Gilbert with r = 1 − p: loss = p.
        assert!((m.loss_rate_exact() - 0.2).abs() < 1e-15);
    }

    #[test]
    fn parses_from_toml_and_rejects_bad_fields() {
        let p: GilbertElliottParams = toml::from_str("p = \"1%\"\nr = 0.3\nloss_bad = 0.9").unwrap();
        assert_eq!(p, params(0.01, Some(0.3), None, Some(0.9)));
        assert!(toml::from_str::<GilbertElliottParams>("p = 1.5").is_err());
        assert!(toml::from_str::<GilbertElliottParams>("p = 0.1\nh = 0.2").is_err());
    }

    #[test]
    fn closed_form_edge_cases() {
        let stuck_good = GilbertElliott::new(&params(0.0, Some(0.0), Some(0.25), None)).unwrap();
        assert_eq!(stuck_good.loss_rate_exact(), 0.25);
        let absorbed_bad = GilbertElliott::new(&params(0.5, Some(0.0), Some(0.1), Some(0.7))).unwrap();
        assert!((absorbed_bad.loss_rate_exact() - 0.7).abs() < 1e-15);
        let m = GilbertElliott::new(&params(0.01, Some(0.3), Some(0.02), Some(0.6))).unwrap();
        let expected = (0.3 * 0.02 + 0.01 * 0.6) / 0.31;
        assert!((m.loss_rate_exact() - expected).abs() < 1e-15);
    }

    #[test]
    fn loss_follows_the_state_before_the_move() {
        // Good always moves to Bad and Bad always back; Good never loses, Bad
        // always does. Frames are decided in Good, Bad, Good, …: delivered,
        // lost, delivered, …
        let mut m = GilbertElliott::new(&params(1.0, Some(1.0), Some(0.0), Some(1.0))).unwrap();
        let mut rng = StageRng::seed_from_u64(1);
        for i in 0..100 {
            let expected = if i % 2 == 0 { Verdict::PASS } else { Verdict::Drop };
            assert_eq!(m.decide(i, &mut rng), expected, "frame {i}");
            assert_eq!(m.is_bad(), i % 2 == 0);
        }
    }

    #[test]
    fn value_stability() {
        let mut m = GilbertElliott::new(&params(0.1, Some(0.3), Some(0.05), Some(0.7))).unwrap();
        let mut rng = StageRng::seed_from_u64(42);
        let fates: String = (0..64).map(|i| if m.decide(i, &mut rng) == Verdict::Drop { 'x' } else { '.' }).collect();
        assert_eq!(fates, PINNED_FATES);
    }
    const PINNED_FATES: &str = "................x.x.xxx...........x.xx.xxx.x........x.xxxx......";
}
