//! `outage` (SPEC §3.5): communication-loss windows with a cooldown.

use super::{Millis, Model, ParamError, Probability, StageRng, Verdict};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OutageUnit {
    /// Window length and cooldown in milliseconds of frame time.
    #[default]
    Time,
    /// Window length (uniform integer ≥ 1) and cooldown counted in frames.
    Frames,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OutageParams {
    /// Probability that a window opens at a frame outside window and cooldown.
    pub p_start: Probability,
    #[serde(default)]
    pub unit: OutageUnit,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_ms: Option<Millis>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_ms: Option<Millis>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cooldown_ms: Option<Millis>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_frames: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_frames: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cooldown_frames: Option<u64>,
}

#[derive(Debug, Clone)]
pub struct Outage {}

impl Outage {
    pub fn new(_params: &OutageParams) -> Result<Self, ParamError> {
        todo!()
    }

    /// Long-run lost fraction of frames at a fixed frame interval, where a
    /// closed form or a documented approximation exists.
    pub fn loss_rate_approx(&self, _frame_interval_ns: u64) -> Option<f64> {
        todo!()
    }

    /// Windows opened so far and their total length in ns (frames unit:
    /// length in frames × 0, see docs).
    pub fn windows(&self) -> (u64, u64) {
        todo!()
    }
}

impl Model for Outage {
    fn decide(&mut self, _t_ns: u64, _rng: &mut StageRng) -> Verdict {
        todo!()
    }
}
