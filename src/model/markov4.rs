//! `markov4` (SPEC §3.3): netem's 4-state loss model (`loss state ...`).

use super::{Model, ParamError, Probability, StageRng, Verdict};
use serde::{Deserialize, Serialize};

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

#[derive(Debug, Clone)]
pub struct Markov4 {}

impl Markov4 {
    pub fn new(_params: &Markov4Params) -> Result<Self, ParamError> {
        todo!()
    }

    pub fn loss_rate_exact(&self) -> f64 {
        todo!()
    }
}

impl Model for Markov4 {
    fn decide(&mut self, _t_ns: u64, _rng: &mut StageRng) -> Verdict {
        todo!()
    }
}
