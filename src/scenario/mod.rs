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
//!
//! Copies (`duplicate`, docs/spec.md §3.8): a stage whose verdict is
//! [`Verdict::Duplicate`] sends the frame on and a copy after it, through the
//! same later stages. [`Scenario::decide`] runs the original to the end of
//! the pipeline first, then each copy from the stage after the one that made
//! it (copies of copies after their parents), and keeps the copies' fates in
//! [`Scenario::copies`] until the next frame. A phase has at most
//! [`MAX_DUPLICATE_STAGES`] duplicate stages, so a frame has at most
//! [`MAX_COPIES`] copies, held in a fixed array: no allocation per frame.
//!
//! Flips (`corrupt`, docs/spec.md §3.9): the bits each `corrupt` stage a
//! frame passes asked to flip are collected in a [`Flips`] (at most
//! [`MAX_CORRUPT_STAGES`] per phase): the original's in
//! [`Scenario::flips`], each copy's in [`Copies`] (a copy inherits the flips
//! made before it was copied). The scenario never touches bytes.

mod parse;
mod presets;
mod spec;
mod switch;

pub use parse::{parse_str, parse_str_with, preset, FileError, NoFiles, ScenarioError, ScenarioFiles};
pub(crate) use parse::write_located;
pub(crate) use parse::field_of_message;
pub use presets::preset_stages;
pub use spec::{PhaseSpec, ScenarioSpec, StageSpec};
pub use switch::{Switched, Timeline, MAX_RUN_PHASES};
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

/// The most `duplicate` stages one phase may have.
pub const MAX_DUPLICATE_STAGES: usize = 4;
/// The most copies of one frame: each duplicate stage at most doubles what
/// reaches it.
pub const MAX_COPIES: usize = (1 << MAX_DUPLICATE_STAGES) - 1;

/// The most `corrupt` stages one phase may have.
pub const MAX_CORRUPT_STAGES: usize = 4;

/// The bits to flip in one frame (indices into its bytes, bit `i % 8` of
/// byte `i / 8`), those of each `corrupt` stage that corrupted it (at most
/// [`crate::model::corrupt::MAX_HITS`] each), in stage order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Flips {
    bits: [u16; MAX_CORRUPT_STAGES * crate::model::corrupt::MAX_HITS],
    len: u8,
}

impl Flips {
    /// The bit indices, for [`crate::frame::flip_bits`].
    #[inline]
    pub fn bits(&self) -> &[u16] {
        &self.bits[..usize::from(self.len)]
    }
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    #[inline]
    fn push(&mut self, bit: u16) {
        // `Scenario::new` caps corrupt stages per phase at the array's size.
        self.bits[usize::from(self.len)] = bit;
        self.len += 1;
    }
}

/// The copies of the frame last decided: the total delay of each copy that
/// passed the whole pipeline (from the frame's ingress, in the order they
/// were made), and how many later stages dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Copies {
    delays_ns: [u64; MAX_COPIES],
    flips: [Flips; MAX_COPIES],
    /// The first stage each copy that passed went through.
    starts: [u16; MAX_COPIES],
    passed: u8,
    dropped: u8,
}

impl Copies {
    /// Delays of the copies that passed.
    pub fn delays_ns(&self) -> &[u64] {
        &self.delays_ns[..usize::from(self.passed)]
    }
    /// The flips of each copy that passed, in the order of
    /// [`Copies::delays_ns`].
    pub fn flips(&self) -> &[Flips] {
        &self.flips[..usize::from(self.passed)]
    }
    /// Copies that a later stage dropped.
    pub fn dropped(&self) -> u64 {
        u64::from(self.dropped)
    }
    /// All copies made: passed + dropped.
    pub fn made(&self) -> u64 {
        u64::from(self.passed) + u64::from(self.dropped)
    }
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
    duplicated: u64,
    corrupted: u64,
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
    /// Copies this stage made so far (`duplicate`).
    pub fn duplicated(&self) -> u64 {
        self.duplicated
    }
    /// Frames this stage corrupted so far (`corrupt`).
    pub fn corrupted(&self) -> u64 {
        self.corrupted
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
    copies: Copies,
    flips: Flips,
    /// Copies waiting to run through the rest of the pipeline: (first
    /// stage, time there, flips so far). Scratch for [`Scenario::decide`].
    pending: [(usize, u64, Flips); MAX_COPIES],
    /// Every frame passes untouched and no stage draws ([`Scenario::set_paused`]).
    paused: bool,
    /// The phase that decided the last frame (`None` while paused: no
    /// stage saw it).
    last_phase: Option<usize>,
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
            for (kind, most, why) in [
                (ModelKind::Duplicate, MAX_DUPLICATE_STAGES, " (each may double what reaches it)"),
                (ModelKind::Corrupt, MAX_CORRUPT_STAGES, ""),
            ] {
                let n = ps.stages.iter().filter(|s| s.model.kind() == kind).count();
                if n > most {
                    return Err(err(loc, Some("model".into()), format!("{n} `{}` stages: at most {most} per phase{why}", kind.name())));
                }
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
                    duplicated: 0,
                    corrupted: 0,
                });
            }
            phases.push(Phase { name: ps.name.clone(), start_offset_ns, stages });
        }
        Ok(Scenario { name: spec.name.clone(), seed, phases, current: 0, copies: Copies::default(),
            flips: Flips::default(),
            pending: [(0, 0, Flips::default()); MAX_COPIES],
            paused: false,
            last_phase: None,
        })
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
    /// The returned decision is the original frame's; its copies, if a
    /// `duplicate` stage made any, are in [`Scenario::copies`] until the next
    /// call.
    #[inline]
    pub fn decide(&mut self, offset_ns: u64, t_ns: u64) -> Decision {
        self.decide_payload(offset_ns, t_ns, None)
    }

    /// [`Scenario::decide`] for a payload of `len` bytes: the link stages
    /// (`rate`, `trace`, docs/spec.md §3.12–3.13) cut it into packets of
    /// their MTU instead of using their configured `payload_bytes`; the
    /// other stages do not look at sizes.
    #[inline]
    pub fn decide_len(&mut self, offset_ns: u64, t_ns: u64, len: u64) -> Decision {
        self.decide_payload(offset_ns, t_ns, Some(len))
    }

    /// Inlined whole into the caller's loop (the injector's ingress), the
    /// original's pass through the stages with it; the copies' passes, when
    /// there are any, are out of line ([`run_copies`]).
    #[inline(always)]
    fn decide_payload(&mut self, offset_ns: u64, t_ns: u64, len: Option<u64>) -> Decision {
        while self.current + 1 < self.phases.len() && self.phases[self.current + 1].start_offset_ns <= offset_ns {
            self.current += 1;
        }
        let phase = self.current;
        if self.paused {
            self.last_phase = None;
            return self.pass_untouched();
        }
        self.last_phase = Some(phase);
        // The copy arrays live in the scenario and are not cleared per frame:
        // only their counts are reset, so a frame without copies or flips
        // costs no more than before.
        let Scenario { phases, copies, flips, pending, .. } = self;
        let stages = &mut phases[phase].stages;
        let mut queued = 0usize;
        flips.len = 0;
        let decision = match run_stages(stages, 0, t_ns, len, flips, pending, &mut queued) {
            Ok(t) => Decision::Pass { delay_ns: t - t_ns },
            // Both indices fit: `new` caps phases and stages at u16::MAX.
            Err(si) => Decision::Drop { phase: phase as u16, stage: si as u16 },
        };
        copies.passed = 0;
        copies.dropped = 0;
        if queued > 0 {
            run_copies(stages, t_ns, len, copies, pending, queued);
        }
        decision
    }

    /// The flips of the frame last decided (empty unless a `corrupt` stage
    /// corrupted it).
    #[inline]
    pub fn flips(&self) -> &Flips {
        &self.flips
    }

    /// The copies of the frame last decided.
    #[inline]
    pub fn copies(&self) -> &Copies {
        &self.copies
    }

    /// The frame last decided passed every stage, and was then dropped
    /// after them (the release queue was full): `copy` `None` for the
    /// original, `Some(k)` for its `k`-th copy that passed (in the order of
    /// [`Copies::delays_ns`]). The link stages it crossed count it as
    /// dropped after them, so their reports agree with the frame's fate.
    pub fn dropped_after_pipeline(&mut self, copy: Option<usize>) {
        let Some(phase) = self.last_phase else { return };
        let from = copy.map_or(0, |k| usize::from(self.copies.starts[k]));
        note_dropped_after(&mut self.phases[phase].stages[from..]);
    }

    /// The stage that dropped a frame, by the indices of [`Decision::Drop`].
    pub fn stage(&self, phase: u16, stage: u16) -> &Stage {
        &self.phases[usize::from(phase)].stages[usize::from(stage)]
    }
}

/// Runs the `queued` copies waiting in `pending` (of a frame that entered at
/// `t_ns`) through the rest of `stages`, in the order they were made (copies
/// of copies queue after their parents), into `copies`. Out of line: a frame
/// without copies, most of them, keeps the caller's loop short.
#[inline(never)]
fn run_copies(
    stages: &mut [Stage],
    t_ns: u64,
    len: Option<u64>,
    copies: &mut Copies,
    pending: &mut [(usize, u64, Flips); MAX_COPIES],
    mut queued: usize,
) {
    let mut next = 0;
    while next < queued {
        let (from, t, mut copy_flips) = pending[next];
        next += 1;
        match run_stages(stages, from, t, len, &mut copy_flips, pending, &mut queued) {
            Ok(end) => {
                copies.delays_ns[usize::from(copies.passed)] = end - t_ns;
                copies.flips[usize::from(copies.passed)] = copy_flips;
                // `new` caps a phase's stages at u16::MAX.
                copies.starts[usize::from(copies.passed)] = from as u16;
                copies.passed += 1;
            }
            Err(_) => copies.dropped += 1,
        }
    }
}

/// Runs a frame through `stages[from..]` starting at `t`: `Ok(time at the
/// end)` or `Err(index of the stage that dropped it)`. A copy made on the way
/// is queued in `pending` to start at the next stage. Inlined always: out of
/// line, its call and register saves cost a frame about 30 instructions.
#[inline(always)]
fn run_stages(
    stages: &mut [Stage],
    from: usize,
    t_ns: u64,
    len: Option<u64>,
    flips: &mut Flips,
    pending: &mut [(usize, u64, Flips); MAX_COPIES],
    queued: &mut usize,
) -> Result<u64, usize> {
    let mut t = t_ns;
    let mut dropped_at = None;
    for (si, st) in stages.iter_mut().enumerate().skip(from) {
        st.reached += 1;
        let verdict = match len {
            None => st.model.decide(t, &mut st.rng),
            Some(len) => st.model.decide_len(t, len, &mut st.rng),
        };
        match verdict {
            Verdict::Pass { delay_ns } => t = t.saturating_add(delay_ns),
            Verdict::Drop => {
                st.dropped += 1;
                dropped_at = Some(si);
                break;
            }
            Verdict::Duplicate => {
                st.duplicated += 1;
                // At most MAX_DUPLICATE_STAGES duplicate stages, each at
                // most doubling what reaches it: the array cannot overflow.
                pending[*queued] = (si + 1, t, *flips);
                *queued += 1;
            }
            Verdict::Corrupt(hits) => {
                st.corrupted += 1;
                for &bit in hits.bits() {
                    flips.push(bit);
                }
            }
        }
    }
    match dropped_at {
        Some(si) => {
            note_dropped_after(&mut stages[from..si]);
            Err(si)
        }
        None => Ok(t),
    }
}

/// A frame that crossed `stages` was dropped after them: each link stage
/// among them counts it (their reports then agree with its fate).
#[inline]
fn note_dropped_after(stages: &mut [Stage]) {
    for st in stages.iter_mut().filter(|st| st.kind().is_link()) {
        st.model.note_dropped_after();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario(text: &str, seed: u64) -> Scenario {
        Scenario::new(&parse_str(text, "s.toml", "s").unwrap(), seed).unwrap()
    }

    #[test]
    fn a_copy_goes_through_the_later_stages_only() {
        // Always duplicate, then a constant 5 ms delay: the original and its
        // copy both arrive 5 ms later; the stage before draws once.
        let mut sc = scenario(
            "[[stage]]\nmodel = \"bernoulli\"\np = 0\n[[stage]]\nmodel = \"duplicate\"\np = 1\n[[stage]]\nmodel = \"delay\"\nmin_ms = 5\n",
            1,
        );
        assert_eq!(sc.decide(0, 1_000), Decision::Pass { delay_ns: 5_000_000 });
        assert_eq!(sc.copies().delays_ns(), &[5_000_000]);
        assert_eq!(sc.copies().made(), 1);
        let st = sc.phases()[0].stages();
        assert_eq!((st[0].reached(), st[1].reached(), st[2].reached()), (1, 1, 2));
        assert_eq!(st[1].duplicated(), 1);
        // The next frame's copies replace these.
        let mut no = scenario("[[stage]]\nmodel = \"duplicate\"\np = 0\n", 1);
        no.decide(0, 0);
        assert_eq!(no.copies().made(), 0);
    }

    #[test]
    fn copies_of_copies_and_dropped_copies() {
        // Two certain duplications: 1 original + 3 copies; a certain loss
        // after them drops all four.
        let two = "[[stage]]\nmodel = \"duplicate\"\np = 1\n[[stage]]\nmodel = \"duplicate\"\np = 1\n";
        let mut sc = scenario(two, 1);
        assert_eq!(sc.decide(0, 0), Decision::Pass { delay_ns: 0 });
        assert_eq!((sc.copies().delays_ns().len(), sc.copies().dropped()), (3, 0));
        let mut lossy = scenario(&format!("{two}[[stage]]\nmodel = \"bernoulli\"\np = 1\n"), 1);
        assert_eq!(lossy.decide(0, 0), Decision::Drop { phase: 0, stage: 2 });
        assert_eq!((lossy.copies().delays_ns().len(), lossy.copies().dropped()), (0, 3));
        assert_eq!(lossy.phases()[0].stages()[2].dropped(), 4);
    }

    #[test]
    fn flips_are_collected_and_copies_inherit_them() {
        // Corrupt always, duplicate always, corrupt always: the original and
        // the copy share the first flip, and each has its own second.
        let c = "[[stage]]\nmodel = \"corrupt\"\np = 1\n";
        let mut sc = scenario(&format!("{c}[[stage]]\nmodel = \"duplicate\"\np = 1\n{c}"), 4);
        assert_eq!(sc.decide(0, 0), Decision::Pass { delay_ns: 0 });
        let own = *sc.flips();
        let copy = sc.copies().flips()[0];
        assert_eq!((own.bits().len(), copy.bits().len()), (2, 2));
        assert_eq!(own.bits()[0], copy.bits()[0]);
        assert!(own.bits().iter().chain(copy.bits()).all(|&b| b < crate::model::corrupt::FRAME_BITS));
        // A frame that meets no corrupt verdict has none, and they do not leak.
        let mut sc = scenario("[[stage]]\nmodel = \"corrupt\"\np = 0\n", 4);
        sc.decide(0, 0);
        assert!(sc.flips().is_empty());
        let five = c.repeat(MAX_CORRUPT_STAGES + 1);
        let e = Scenario::new(&parse_str(&five, "s.toml", "s").unwrap(), 1).unwrap_err();
        assert!(e.problem.contains("`corrupt` stages: at most 4"), "{e}");
    }

    #[test]
    fn a_payload_size_reaches_the_link_stages() {
        // 8 Mbit/s: a byte per µs. A 4000-byte payload goes as three packets
        // (1500, 1500, 1000) and leaves after 4 ms; the configured 124 bytes
        // take 124 µs.
        let mut sc = scenario("[[stage]]\nmodel = \"bernoulli\"\np = 0\n[[stage]]\nmodel = \"rate\"\nrate_bit_s = 8e6\n", 1);
        assert_eq!(sc.decide_len(0, 0, 4000), Decision::Pass { delay_ns: 4_000_000 });
        assert_eq!(sc.decide(0, 10_000_000), Decision::Pass { delay_ns: 124_000 });
        let stats = sc.phases()[0].stages()[1].model().link_stats().unwrap();
        assert_eq!((stats.frames, stats.packets, stats.bytes), (2, 4, 4124));
    }

    #[test]
    fn the_duplicate_stages_of_a_phase_are_bounded() {
        let five = "[[stage]]\nmodel = \"duplicate\"\np = 1\n".repeat(MAX_DUPLICATE_STAGES + 1);
        let spec = parse_str(&five, "s.toml", "s").unwrap();
        let e = Scenario::new(&spec, 1).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("model"), "{e}");
        assert!(e.problem.contains("at most 4"), "{e}");
        // The most copies: 2^4 − 1, all held in the fixed array.
        let four = "[[stage]]\nmodel = \"duplicate\"\np = 1\n".repeat(MAX_DUPLICATE_STAGES);
        let mut sc = scenario(&four, 1);
        sc.decide(0, 0);
        assert_eq!(sc.copies().delays_ns().len(), MAX_COPIES);
    }
}
