//! `delay` (SPEC §3.4): a minimum plus a random part (none, hyperexponential,
//! or uniform jitter), released in `reorder` or `fifo` order.

use super::{Millis, Model, ParamError, StageRng, Verdict};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DelayDist {
    /// Constant delay `min_ms`.
    #[default]
    None,
    /// `min_ms + Exp(rates_per_ms[i])` with probability `weights[i]`.
    Hyperexp,
    /// `min_ms + U[0, jitter_ms)`.
    Uniform,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Order {
    /// Each frame is released at its own time (NetFI, netem).
    #[default]
    Reorder,
    /// A frame is held until the previous one is released.
    Fifo,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DelayParams {
    pub min_ms: Millis,
    #[serde(default)]
    pub dist: DelayDist,
    /// Hyperexponential component weights (sum to 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<Vec<f64>>,
    /// Hyperexponential component rates, per millisecond (> 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rates_per_ms: Option<Vec<f64>>,
    /// Uniform jitter width.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jitter_ms: Option<Millis>,
    #[serde(default)]
    pub order: Order,
}

#[derive(Debug, Clone)]
pub struct Delay {}

impl Delay {
    pub fn new(_params: &DelayParams) -> Result<Self, ParamError> {
        todo!()
    }

    /// `E[D]` in ms: `min_ms + Σ w_i/λ_i` (or `+ jitter/2`).
    pub fn mean_ms_exact(&self) -> f64 {
        todo!()
    }

    pub fn may_reorder(&self) -> bool {
        todo!()
    }
}

impl Model for Delay {
    fn decide(&mut self, _t_ns: u64, _rng: &mut StageRng) -> Verdict {
        todo!()
    }
}
