//! Degradation models: one file per model, and [`AnyModel`], which holds any
//! one of them; [`ModelSpec`], a model's parameters before validation, with
//! typed constructors per model (`DelayParams::hyperexp`,
//! `OutageParams::time`, …); the study's presets ([`presets`]); the stage
//! stream seeds ([`stream_seed`]). This is the bottom of the core: `fit` and
//! `scenario` both build on it, and `fit` needs nothing else of the core.
//!
//! Contract (docs/spec.md §3): a model validates its parameters once, in
//! `new`, against their physical ranges ([`units`]), and
//! returns a [`ParamError`] naming the offending field; afterwards
//! [`Model::decide`] cannot fail. A model never reads a clock: the frame's time
//! at the stage (`t_ns`, CLOCK_MONOTONIC-like nanoseconds) is passed in, and so
//! is the stage's own random stream. A model that drops a frame adds no delay;
//! a dropped frame is never shown to later stages, so they draw nothing for it.

pub mod backlog;
pub mod bernoulli;
pub mod corrupt;
pub mod delay;
pub mod duplicate;
mod draw;
pub mod ge_lomax;
pub mod gilbert_elliott;
pub mod jitter;
pub mod linktrace;
pub mod markov4;
pub mod outage;
pub mod presets;
pub mod rate;
pub mod replay;
pub mod reorder;
pub mod slot;
mod spec;
pub mod units;

pub use bernoulli::{Bernoulli, BernoulliParams};
pub use corrupt::{Corrupt, CorruptParams, Hits};
pub use delay::{Delay, DelayDist, DelayParams, Order};
pub use duplicate::{Duplicate, DuplicateParams};
pub use ge_lomax::{GeLomax, GeLomaxParams};
pub use gilbert_elliott::{GilbertElliott, GilbertElliottParams};
pub use jitter::{Jitter, JitterDist, JitterParams};
pub use linktrace::{LinkTrace, LinkTraceParams, Schedule};
pub use markov4::{Markov4, Markov4Params};
pub use outage::{Outage, OutageParams, OutageUnit, OutageWindows};
pub use rate::{Rate, RateParams};
pub use reorder::{Reorder, ReorderParams};
pub use replay::{Recording, RecordingKind, Replay, ReplayParams};
pub use slot::{Slot, SlotParams};
pub use spec::ModelSpec;
pub use units::{parse_duration, Millis, Probability, TimeUnit};

use rand_xoshiro::Xoshiro256PlusPlus;

/// The random generator of every stage: portable and seedable, so the same
/// seed gives the same fates on every platform.
pub type StageRng = Xoshiro256PlusPlus;

/// The stream seed of one stage: SplitMix64 mixing of the scenario seed, the
/// phase index and the FNV-1a hash of the stage label.
pub fn stream_seed(seed: u64, phase: usize, label: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in label.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    splitmix64(splitmix64(seed ^ splitmix64(phase as u64)) ^ h)
}

/// One step of SplitMix64 (Steele, Lea, Flood 2014) as a mixing function.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// What one stage decides for one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// The frame goes on, `delay_ns` later than it arrived at this stage.
    Pass { delay_ns: u64 },
    /// The frame is lost at this stage.
    Drop,
    /// The frame goes on without delay, and so does a copy of it, through
    /// the same later stages (`duplicate`, docs/spec.md §3.8).
    Duplicate,
    /// The frame goes on without delay with the bits of the [`corrupt::Hits`]
    /// flipped (bit `b` is bit `b % 8` of byte `b / 8`): `corrupt`,
    /// docs/spec.md §3.9. The core never touches bytes; the holder of the
    /// frame applies the flips.
    Corrupt(corrupt::Hits),
}

impl Verdict {
    /// A pass without delay.
    pub const PASS: Verdict = Verdict::Pass { delay_ns: 0 };
}

/// A parameter that failed validation: which field, and what was wrong with it
/// (including what would be accepted).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{field}`: {problem}")]
pub struct ParamError {
    /// The field as written in a scenario file, with an index where it is a
    /// list element, e.g. `transition[1]`.
    pub field: String,
    /// What is wrong and what would be accepted.
    pub problem: String,
}

impl ParamError {
    pub fn new(field: impl Into<String>, problem: impl Into<String>) -> Self {
        ParamError { field: field.into(), problem: problem.into() }
    }

    /// `field` was given where `switch = "value"` leaves it no meaning.
    pub fn not_for(field: &str, switch: &str, value: &str) -> Self {
        ParamError::new(field, format!("does not apply to {switch} = \"{value}\"; remove it or change `{switch}`"))
    }
}

/// One degradation model's per-frame decision.
pub trait Model {
    /// Decides the fate of the frame that reaches this stage at `t_ns`.
    fn decide(&mut self, t_ns: u64, rng: &mut StageRng) -> Verdict;
}

/// The kinds of model, as named in scenario files and drop reasons.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ModelKind {
    Bernoulli,
    GeLomax,
    Markov4,
    GilbertElliott,
    Delay,
    Outage,
    Jitter,
    Duplicate,
    Corrupt,
    Reorder,
    Slot,
    Rate,
    LinkTrace,
    Replay,
}

impl ModelKind {
    pub const ALL: [ModelKind; 14] = [
        ModelKind::Bernoulli,
        ModelKind::GeLomax,
        ModelKind::Markov4,
        ModelKind::GilbertElliott,
        ModelKind::Delay,
        ModelKind::Outage,
        ModelKind::Jitter,
        ModelKind::Duplicate,
        ModelKind::Corrupt,
        ModelKind::Reorder,
        ModelKind::Slot,
        ModelKind::Rate,
        ModelKind::LinkTrace,
        ModelKind::Replay,
    ];

    /// The name used in scenario files (`model = "..."`).
    pub const fn name(self) -> &'static str {
        match self {
            ModelKind::Bernoulli => "bernoulli",
            ModelKind::GeLomax => "ge_lomax",
            ModelKind::Markov4 => "markov4",
            ModelKind::GilbertElliott => "gilbert_elliott",
            ModelKind::Delay => "delay",
            ModelKind::Outage => "outage",
            ModelKind::Jitter => "jitter",
            ModelKind::Duplicate => "duplicate",
            ModelKind::Corrupt => "corrupt",
            ModelKind::Reorder => "reorder",
            ModelKind::Slot => "slot",
            ModelKind::Rate => "rate",
            ModelKind::LinkTrace => "trace",
            ModelKind::Replay => "replay",
        }
    }

    /// The reason a drop by this model is reported under: the model's name,
    /// but `link_queue` for the link stages (`rate`, `trace`), whose only
    /// drops are their queue's.
    pub const fn drop_reason(self) -> &'static str {
        match self {
            ModelKind::Rate | ModelKind::LinkTrace => "link_queue",
            other => other.name(),
        }
    }

    /// Whether this model is a link with a queue (`rate`, `trace`).
    pub const fn is_link(self) -> bool {
        matches!(self, ModelKind::Rate | ModelKind::LinkTrace)
    }

    pub fn from_name(name: &str) -> Option<ModelKind> {
        ModelKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// A validated model of any kind. Dispatch is a `match`, not a trait object,
/// so a pipeline is a flat array and a decision inlines.
///
/// `GeLomax` makes this about 0.9 KiB: its per-state inverse-CDF tables live
/// inline so a decision reads them without a pointer chase, and a decision
/// touches only the one row it needs. A pipeline has a handful of stages, so
/// boxing would save nothing that matters.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum AnyModel {
    Bernoulli(Bernoulli),
    GeLomax(GeLomax),
    Markov4(Markov4),
    GilbertElliott(GilbertElliott),
    Delay(Delay),
    Outage(Outage),
    Jitter(Jitter),
    Duplicate(Duplicate),
    Corrupt(Corrupt),
    Reorder(Reorder),
    Slot(Slot),
    Rate(Rate),
    LinkTrace(LinkTrace),
    Replay(Replay),
}

impl AnyModel {
    pub fn kind(&self) -> ModelKind {
        match self {
            AnyModel::Bernoulli(_) => ModelKind::Bernoulli,
            AnyModel::GeLomax(_) => ModelKind::GeLomax,
            AnyModel::Markov4(_) => ModelKind::Markov4,
            AnyModel::GilbertElliott(_) => ModelKind::GilbertElliott,
            AnyModel::Delay(_) => ModelKind::Delay,
            AnyModel::Outage(_) => ModelKind::Outage,
            AnyModel::Jitter(_) => ModelKind::Jitter,
            AnyModel::Duplicate(_) => ModelKind::Duplicate,
            AnyModel::Corrupt(_) => ModelKind::Corrupt,
            AnyModel::Reorder(_) => ModelKind::Reorder,
            AnyModel::Slot(_) => ModelKind::Slot,
            AnyModel::Rate(_) => ModelKind::Rate,
            AnyModel::LinkTrace(_) => ModelKind::LinkTrace,
            AnyModel::Replay(_) => ModelKind::Replay,
        }
    }

    #[inline]
    pub fn decide(&mut self, t_ns: u64, rng: &mut StageRng) -> Verdict {
        match self {
            AnyModel::Bernoulli(m) => m.decide(t_ns, rng),
            AnyModel::GeLomax(m) => m.decide(t_ns, rng),
            AnyModel::Markov4(m) => m.decide(t_ns, rng),
            AnyModel::GilbertElliott(m) => m.decide(t_ns, rng),
            AnyModel::Delay(m) => m.decide(t_ns, rng),
            AnyModel::Outage(m) => m.decide(t_ns, rng),
            AnyModel::Jitter(m) => m.decide(t_ns, rng),
            AnyModel::Duplicate(m) => m.decide(t_ns, rng),
            AnyModel::Corrupt(m) => m.decide(t_ns, rng),
            AnyModel::Reorder(m) => m.decide(t_ns, rng),
            AnyModel::Slot(m) => m.decide(t_ns, rng),
            AnyModel::Rate(m) => m.decide(t_ns, rng),
            AnyModel::LinkTrace(m) => m.decide(t_ns, rng),
            AnyModel::Replay(m) => m.decide(t_ns, rng),
        }
    }

    /// [`AnyModel::decide`] for a payload of `len` bytes: the link stages
    /// (`rate`, `trace`) cut it into packets; the other models do not look
    /// at sizes.
    #[inline]
    pub fn decide_len(&mut self, t_ns: u64, len: u64, rng: &mut StageRng) -> Verdict {
        match self {
            AnyModel::Rate(m) => m.decide_len(t_ns, len),
            AnyModel::LinkTrace(m) => m.decide_len(t_ns, len),
            other => other.decide(t_ns, rng),
        }
    }

    /// The link statistics of a link stage (`rate`, `trace`).
    pub fn link_stats(&self) -> Option<&backlog::LinkStats> {
        match self {
            AnyModel::Rate(m) => Some(m.stats()),
            AnyModel::LinkTrace(m) => Some(m.stats()),
            _ => None,
        }
    }

    /// A frame this link stage admitted was dropped after it (by a later
    /// stage, or the release queue); nothing for other stages.
    #[inline]
    pub fn note_dropped_after(&mut self) {
        match self {
            AnyModel::Rate(m) => m.stats_mut().dropped_after(),
            AnyModel::LinkTrace(m) => m.stats_mut().dropped_after(),
            _ => {}
        }
    }

    /// A link stage's utilisation so far (see [`Rate::utilisation`],
    /// [`LinkTrace::utilisation`]).
    pub fn link_utilisation(&self) -> Option<f64> {
        match self {
            AnyModel::Rate(m) => Some(m.utilisation()),
            AnyModel::LinkTrace(m) => Some(m.utilisation()),
            _ => None,
        }
    }

    /// A link stage's queue as of its last frame: packets and wire bytes.
    pub fn link_queued(&self) -> Option<(u64, u64)> {
        match self {
            AnyModel::Rate(m) => Some(m.queued()),
            AnyModel::LinkTrace(m) => Some(m.queued()),
            _ => None,
        }
    }

    /// The exact long-run fraction of frames this model drops (0 for `delay`,
    /// which never drops). For `outage` in time units it depends on the frame
    /// interval, so it is given for frames every `frame_interval_ns`; `None`
    /// only there, for a zero interval.
    pub fn loss_rate_exact(&self, frame_interval_ns: u64) -> Option<f64> {
        match self {
            AnyModel::Bernoulli(m) => Some(m.loss_rate_exact()),
            AnyModel::GeLomax(m) => Some(m.loss_rate_exact()),
            AnyModel::Markov4(m) => Some(m.loss_rate_exact()),
            AnyModel::GilbertElliott(m) => Some(m.loss_rate_exact()),
            AnyModel::Delay(_) | AnyModel::Jitter(_) | AnyModel::Duplicate(_) | AnyModel::Corrupt(_) => Some(0.0),
            AnyModel::Reorder(_) | AnyModel::Slot(_) => Some(0.0),
            AnyModel::Outage(m) => m.loss_rate_approx(frame_interval_ns),
            // A queue's losses depend on the arrivals; a replay's repeat its
            // recording's.
            AnyModel::Rate(_) | AnyModel::LinkTrace(_) => None,
            AnyModel::Replay(m) => Some(m.recording().loss_rate()),
        }
    }

    /// The long-run loss a run of `frames` frames through this stage is
    /// unlikely to have sampled, to be added to the upper end of a loss
    /// interval built from the run's own spread: the part of `ge_lomax`'s
    /// loss in bursts longer than the run likely met
    /// ([`GeLomax::unseen_loss_rate`]). 0 for the other models, whose
    /// bursts (geometric, or outage windows of bounded length) leave
    /// nothing a run's spread misses.
    pub fn unseen_loss_rate(&self, frames: u64) -> f64 {
        match self {
            AnyModel::GeLomax(m) => m.unseen_loss_rate(frames),
            _ => 0.0,
        }
    }

    /// Outage windows opened so far and their total drawn length (all zero
    /// for other models).
    pub fn outage_windows(&self) -> OutageWindows {
        match self {
            AnyModel::Outage(m) => m.windows(),
            _ => OutageWindows::default(),
        }
    }

    /// The exact mean delay this model adds to a frame it passes, in ms
    /// (`E[D]`, docs/spec.md §3.4, §3.7, the clamp at 0 included); 0 for
    /// models that add no delay. For `fifo` order
    /// this is the drawn delay; holding a frame behind its predecessor adds
    /// to it.
    pub fn mean_delay_ms_exact(&self) -> f64 {
        match self {
            AnyModel::Delay(m) => m.mean_ms_exact(),
            AnyModel::Jitter(m) => m.mean_ms_exact(),
            AnyModel::Reorder(m) => m.mean_ms_exact(),
            _ => 0.0,
        }
    }

    /// The exact long-run number of copies per frame reaching the stage
    /// (`duplicate`; `None` for the other models).
    pub fn duplicate_rate_exact(&self) -> Option<f64> {
        match self {
            AnyModel::Duplicate(m) => Some(m.duplicate_rate_exact()),
            _ => None,
        }
    }

    /// The exact long-run fraction of frames reaching the stage that it
    /// corrupts (`corrupt`; `None` for the other models).
    pub fn corrupt_rate_exact(&self) -> Option<f64> {
        match self {
            AnyModel::Corrupt(m) => Some(m.corrupt_rate_exact()),
            _ => None,
        }
    }

    /// Whether this model delays frames (`delay`, `jitter`).
    pub fn is_delay(&self) -> bool {
        matches!(self, AnyModel::Delay(_) | AnyModel::Jitter(_) | AnyModel::Reorder(_))
    }

    /// The exact `q`-quantile of the delay this model draws, in ms, for the
    /// models that delay (`None` otherwise). For `fifo` order this is the
    /// drawn delay, before any hold.
    pub fn delay_quantile_ms_exact(&self, q: f64) -> Option<f64> {
        match self {
            AnyModel::Delay(m) => Some(m.quantile_ms(q)),
            AnyModel::Jitter(m) => Some(m.quantile_ms(q)),
            _ => None,
        }
    }

    /// Whether this model can release frames out of their arrival order.
    pub fn may_reorder(&self) -> bool {
        match self {
            AnyModel::Delay(d) => d.may_reorder(),
            AnyModel::Jitter(j) => j.may_reorder(),
            AnyModel::Reorder(r) => r.may_reorder(),
            AnyModel::Replay(r) => r.may_reorder(),
            _ => false,
        }
    }
}
