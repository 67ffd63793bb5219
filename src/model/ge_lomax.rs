//! `ge_lomax` (SPEC §3.2): NetFI's bursty loss model. A Markov chain of 1–4
//! states with a Lomax burst-length law per state.

use super::{Model, ParamError, StageRng, Verdict};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GeLomaxParams {
    /// Row-stochastic transition matrix, 1–4 states; state 0 starts.
    pub transition: Vec<Vec<f64>>,
    /// Lomax shape per state (> 0).
    pub alpha: Vec<f64>,
    /// Lomax scale per state (> 0), in frames.
    pub lambda: Vec<f64>,
}

#[derive(Debug, Clone)]
pub struct GeLomax {}

impl GeLomax {
    pub fn new(_params: &GeLomaxParams) -> Result<Self, ParamError> {
        todo!()
    }

    pub fn loss_rate_exact(&self) -> f64 {
        todo!()
    }
}

impl Model for GeLomax {
    fn decide(&mut self, _t_ns: u64, _rng: &mut StageRng) -> Verdict {
        todo!()
    }
}
