//! `gilbert_elliott` (SPEC §3.3): netem's `loss gemodel p r 1-h 1-k`.

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

#[derive(Debug, Clone)]
pub struct GilbertElliott {}

impl GilbertElliott {
    pub fn new(_params: &GilbertElliottParams) -> Result<Self, ParamError> {
        todo!()
    }

    pub fn loss_rate_exact(&self) -> f64 {
        todo!()
    }
}

impl Model for GilbertElliott {
    fn decide(&mut self, _t_ns: u64, _rng: &mut StageRng) -> Verdict {
        todo!()
    }
}
