//! Scenarios (docs/spec.md §3, §3.6, §4): pipelines of stages, optionally a
//! timeline of phases, built from TOML text or the study's presets.
//!
//! Dependencies go one way: `scenario` uses `model` and, for target stages
//! (`loss = "30%"`), the fault parameter database in [`crate::fit::db`];
//! `fit` uses only `model`. Reading files is [`crate::load`]'s.
//!
//! Random streams: every stage draws from its own [`StageRng`], seeded from
//! the scenario seed, the phase index and the stage's *label* (its `name`, or
//! `<model>#<n>` with n counting earlier stages of the same model in the
//! phase). Adding, removing or changing a stage of another model therefore
//! never changes a stage's draws; give stages explicit names to keep that
//! property when inserting a stage of the same model. A dropped frame goes no
//! further, so later stages draw nothing for it.

mod parse;
mod presets;
mod spec;

pub use parse::{parse_str, preset, ScenarioError};
pub use presets::preset_stages;
pub use spec::{PhaseSpec, ScenarioSpec, StageSpec};
// Names that live in `model` (which `fit` uses without depending on
// `scenario`), re-exported where scenario code has always found them.
pub use crate::model::presets::{canonical_name, preset_label, PRESET_NAMES};
pub use crate::model::{splitmix64, stream_seed, ModelSpec};

use crate::model::{AnyModel, ModelKind, StageRng, Verdict};
use rand::SeedableRng;

/// What the pipeline decided for one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Delivered after `delay_ns` in total.
    Pass { delay_ns: u64 },
    /// Dropped by stage `stage` of phase `phase` (indices from 0).
    Drop { phase: u16, stage: u16 },
}

/// One runnable stage: a model, its random stream and its counters.
#[derive(Debug, Clone)]
pub struct Stage {
    model: AnyModel,
    rng: StageRng,
    label: String,
    preset: Option<String>,
    reached: u64,
    dropped: u64,
}

impl Stage {
    pub fn model(&self) -> &AnyModel {
        &self.model
    }
    pub fn kind(&self) -> ModelKind {
        self.model.kind()
    }
    pub fn label(&self) -> &str {
        &self.label
    }
    pub fn preset(&self) -> Option<&str> {
        self.preset.as_deref()
    }
    /// Frames that reached this stage so far.
    pub fn reached(&self) -> u64 {
        self.reached
    }
    /// Frames this stage dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

/// One phase of the timeline.
#[derive(Debug, Clone)]
pub struct Phase {
    name: Option<String>,
    start_offset_ns: u64,
    stages: Vec<Stage>,
}

impl Phase {
    pub fn name(&self) -> Option<&str> {
        self.name.as_deref()
    }
    pub fn start_offset_ns(&self) -> u64 {
        self.start_offset_ns
    }
    pub fn stages(&self) -> &[Stage] {
        &self.stages
    }
}

/// A runnable scenario. Pure: its only inputs are the frame times passed in.
#[derive(Debug, Clone)]
pub struct Scenario {
    name: String,
    seed: u64,
    phases: Vec<Phase>,
    current: usize,
}

impl Scenario {
    /// Builds the runnable scenario with `seed`.
    pub fn new(spec: &ScenarioSpec, seed: u64) -> Result<Scenario, ScenarioError> {
        let err = |location: String, field: Option<String>, problem: String| ScenarioError {
            origin: spec.name.clone(),
            line: None,
            location: Some(location),
            field,
            problem,
        };
        if spec.phases.is_empty() {
            return Err(err("scenario".into(), None, "has no phase".into()));
        }
        if spec.phases.len() > usize::from(u16::MAX) {
            return Err(err("scenario".into(), None, format!("has {} phases; at most {} are supported", spec.phases.len(), u16::MAX)));
        }
        let mut phases = Vec::with_capacity(spec.phases.len());
        let mut prev_start = None;
        for (pi, ps) in spec.phases.iter().enumerate() {
            let loc = format!("phase {}", pi + 1);
            let max = crate::model::units::MAX_PHASE_START_MS;
            if !ps.start_ms.is_finite() || ps.start_ms < 0.0 || ps.start_ms > max || (pi == 0 && ps.start_ms != 0.0) {
                return Err(err(
                    loc,
                    Some("start_ms".into()),
                    format!("the first phase starts at 0; others at a finite time from 0 to {max} ms (one year)"),
                ));
            }
            let start_offset_ns = crate::model::units::ms_to_ns(ps.start_ms);
            if let Some(prev) = prev_start {
                if start_offset_ns <= prev {
                    return Err(err(loc, Some("start_ms".into()), "phases must start in increasing order".into()));
                }
            }
            prev_start = Some(start_offset_ns);
            if ps.stages.len() > usize::from(u16::MAX) {
                return Err(err(loc, None, format!("has {} stages; at most {} are supported", ps.stages.len(), u16::MAX)));
            }
            let labels = StageSpec::labels(&ps.stages);
            let mut stages = Vec::with_capacity(ps.stages.len());
            for (si, (st, label)) in ps.stages.iter().zip(labels).enumerate() {
                let sloc = format!("{loc}, stage {} ({})", si + 1, st.model.kind().name());
                if stages.iter().any(|s: &Stage| s.label == label) {
                    return Err(err(sloc, Some("name".into()), format!("label `{label}` is used twice in this phase; stage names must be unique")));
                }
                let model = st.model.build().map_err(|e| err(sloc.clone(), Some(e.field), e.problem))?;
                stages.push(Stage {
                    model,
                    rng: StageRng::seed_from_u64(stream_seed(seed, pi, &label)),
                    label,
                    preset: st.preset.clone(),
                    reached: 0,
                    dropped: 0,
                });
            }
            phases.push(Phase { name: ps.name.clone(), start_offset_ns, stages });
        }
        Ok(Scenario { name: spec.name.clone(), seed, phases, current: 0 })
    }

    pub fn name(&self) -> &str {
        &self.name
    }
    pub fn seed(&self) -> u64 {
        self.seed
    }
    pub fn phases(&self) -> &[Phase] {
        &self.phases
    }

    /// Whether any stage can release frames out of their arrival order.
    pub fn may_reorder(&self) -> bool {
        self.phases.iter().flat_map(|p| &p.stages).any(|s| s.model.may_reorder())
    }

    /// Whether the scenario injects nothing at all.
    pub fn is_empty(&self) -> bool {
        self.phases.iter().all(|p| p.stages.is_empty())
    }

    /// Decides one frame. `offset_ns` is the frame's ingress time relative to
    /// the run's start (it selects the phase; it must not decrease from call
    /// to call); `t_ns` is its ingress time on the clock the models see.
    #[inline]
    pub fn decide(&mut self, offset_ns: u64, t_ns: u64) -> Decision {
        while self.current + 1 < self.phases.len() && self.phases[self.current + 1].start_offset_ns <= offset_ns {
            self.current += 1;
        }
        let phase = &mut self.phases[self.current];
        let mut t = t_ns;
        for (si, st) in phase.stages.iter_mut().enumerate() {
            st.reached += 1;
            match st.model.decide(t, &mut st.rng) {
                Verdict::Pass { delay_ns } => t = t.saturating_add(delay_ns),
                Verdict::Drop => {
                    st.dropped += 1;
                    // Both indices fit: `new` caps phases and stages at u16::MAX.
                    return Decision::Drop { phase: self.current as u16, stage: si as u16 };
                }
            }
        }
        Decision::Pass { delay_ns: t - t_ns }
    }

    /// The stage that dropped a frame, by the indices of [`Decision::Drop`].
    pub fn stage(&self, phase: u16, stage: u16) -> &Stage {
        &self.phases[usize::from(phase)].stages[usize::from(stage)]
    }
}
