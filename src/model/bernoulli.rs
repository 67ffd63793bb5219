//! `bernoulli` (SPEC §3.1): each frame is dropped independently with
//! probability `p`.

use super::{Model, ParamError, Probability, StageRng, Verdict};
use rand::RngExt;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BernoulliParams {
    /// Drop probability per frame.
    pub p: Probability,
}

#[derive(Debug, Clone)]
pub struct Bernoulli {
    dist: rand::distr::Bernoulli,
    p: f64,
}

impl Bernoulli {
    pub fn new(params: &BernoulliParams) -> Result<Self, ParamError> {
        let p = params.p.get();
        let dist = rand::distr::Bernoulli::new(p)
            .map_err(|e| ParamError::new("p", format!("{p}: {e}; expected a probability in [0, 1]")))?;
        Ok(Bernoulli { dist, p })
    }

    pub fn loss_rate_exact(&self) -> f64 {
        self.p
    }
}

impl Model for Bernoulli {
    #[inline]
    fn decide(&mut self, _t_ns: u64, rng: &mut StageRng) -> Verdict {
        if rng.sample(self.dist) {
            Verdict::Drop
        } else {
            Verdict::PASS
        }
    }
}
