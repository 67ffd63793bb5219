//! [`ModelSpec`]: a model's kind and its parameters as a scenario stage
//! writes them, before validation. [`ModelSpec::build`] validates them into
//! an [`AnyModel`].

use super::{
    AnyModel, Bernoulli, BernoulliParams, Corrupt, CorruptParams, Delay, DelayParams, GeLomax, GeLomaxParams, GilbertElliott,
    GilbertElliottParams, Duplicate, DuplicateParams, Jitter, JitterParams, Markov4, Markov4Params, ModelKind, Outage, OutageParams, ParamError, Reorder, ReorderParams, Slot, SlotParams,
    LinkTrace, LinkTraceParams, Rate, RateParams, Replay, ReplayParams,
};
use serde::Serialize;

/// One model with its parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum ModelSpec {
    Bernoulli(BernoulliParams),
    GeLomax(GeLomaxParams),
    Markov4(Markov4Params),
    GilbertElliott(GilbertElliottParams),
    Delay(DelayParams),
    Outage(OutageParams),
    Jitter(JitterParams),
    Duplicate(DuplicateParams),
    Corrupt(CorruptParams),
    Reorder(ReorderParams),
    Slot(SlotParams),
    Rate(RateParams),
    #[serde(rename = "trace")]
    LinkTrace(LinkTraceParams),
    Replay(ReplayParams),
}

impl ModelSpec {
    pub fn kind(&self) -> ModelKind {
        match self {
            ModelSpec::Bernoulli(_) => ModelKind::Bernoulli,
            ModelSpec::GeLomax(_) => ModelKind::GeLomax,
            ModelSpec::Markov4(_) => ModelKind::Markov4,
            ModelSpec::GilbertElliott(_) => ModelKind::GilbertElliott,
            ModelSpec::Delay(_) => ModelKind::Delay,
            ModelSpec::Outage(_) => ModelKind::Outage,
            ModelSpec::Jitter(_) => ModelKind::Jitter,
            ModelSpec::Duplicate(_) => ModelKind::Duplicate,
            ModelSpec::Corrupt(_) => ModelKind::Corrupt,
            ModelSpec::Reorder(_) => ModelKind::Reorder,
            ModelSpec::Slot(_) => ModelKind::Slot,
            ModelSpec::Rate(_) => ModelKind::Rate,
            ModelSpec::LinkTrace(_) => ModelKind::LinkTrace,
            ModelSpec::Replay(_) => ModelKind::Replay,
        }
    }

    /// The file the stage reads (a link trace, a recording), as the
    /// scenario names it; `None` for a stage that reads none.
    pub fn file_mut(&mut self) -> Option<&mut String> {
        match self {
            ModelSpec::LinkTrace(p) => Some(&mut p.file),
            ModelSpec::Replay(p) => Some(&mut p.file),
            _ => None,
        }
    }

    /// Validates the parameters and builds the model.
    pub fn build(&self) -> Result<AnyModel, ParamError> {
        Ok(match self {
            ModelSpec::Bernoulli(p) => AnyModel::Bernoulli(Bernoulli::new(p)?),
            ModelSpec::GeLomax(p) => AnyModel::GeLomax(GeLomax::new(p)?),
            ModelSpec::Markov4(p) => AnyModel::Markov4(Markov4::new(p)?),
            ModelSpec::GilbertElliott(p) => AnyModel::GilbertElliott(GilbertElliott::new(p)?),
            ModelSpec::Delay(p) => AnyModel::Delay(Delay::new(p)?),
            ModelSpec::Outage(p) => AnyModel::Outage(Outage::new(p)?),
            ModelSpec::Jitter(p) => AnyModel::Jitter(Jitter::new(p)?),
            ModelSpec::Duplicate(p) => AnyModel::Duplicate(Duplicate::new(p)?),
            ModelSpec::Corrupt(p) => AnyModel::Corrupt(Corrupt::new(p)?),
            ModelSpec::Reorder(p) => AnyModel::Reorder(Reorder::new(p)?),
            ModelSpec::Slot(p) => AnyModel::Slot(Slot::new(p)?),
            ModelSpec::Rate(p) => AnyModel::Rate(Rate::new(p)?),
            ModelSpec::LinkTrace(p) => AnyModel::LinkTrace(LinkTrace::new(p)?),
            ModelSpec::Replay(p) => AnyModel::Replay(Replay::new(p)?),
        })
    }
}
