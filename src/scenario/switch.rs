//! Switching a running scenario: live control (docs/interface.md, "Live
//! control").
//!
//! A run's scenario is a timeline of phases (docs/spec.md §3.6). A switch
//! to another scenario at offset `t` (from the run's first frame) *rewrites
//! the rest of the timeline*: the phases that have not started by `t` are
//! cut, and the new scenario's phases are appended, its first starting at
//! `t` and the others at `t` plus their own offsets. Nothing else changes:
//!
//! - the phase that is running keeps its stages and their state; it simply
//!   ends at `t`, so a switch takes effect between two frames, never in
//!   the middle of a decision;
//! - each appended phase's stages draw from the streams a phase at that
//!   place of the timeline would have had (seeded from the run's seed, the
//!   phase's index in the run's timeline and the stage's label). A run
//!   switched A → (t1) B → (t2) A therefore gives, frame by frame, the fates
//!   of a run started with the timeline `A@0, B@t1, A@t2` and the same seed;
//! - frames already queued keep their release times (the queue is not
//!   touched here).
//!
//! The new phases are built and validated off the hot path
//! ([`Timeline::new`], with the scenario parser's errors) and handed in
//! whole; [`Scenario::splice`] only moves them into place and seeds their
//! streams, allocating nothing: the phases it cuts go back out in the
//! [`Timeline`] it returns, to be dropped where allocation is allowed.
//!
//! Pausing ([`Scenario::set_paused`]) lets every frame pass untouched with
//! no delay; no stage sees a frame or draws, so after resuming every
//! stage continues its stream where it stopped.

use super::{Decision, Phase, Scenario, ScenarioError, ScenarioSpec};
use crate::model::{stream_seed, StageRng};
use rand::SeedableRng;

/// The most phases one run's timeline holds: its own and every phase
/// switched in since (cut phases do not count).
pub const MAX_RUN_PHASES: usize = 1024;

/// Phases to switch in, with start offsets relative to the switch (the
/// first at 0), built and validated off the hot path.
#[derive(Debug)]
pub struct Timeline {
    name: String,
    /// The new phases first (`new` of them); room after them for every
    /// phase a splice may cut, which it moves in here.
    phases: Vec<Phase>,
    new: usize,
}

impl Timeline {
    /// The phases of `spec` from its phase `from_phase` (index from 0) on,
    /// that phase starting at 0. Errors are those of [`Scenario::new`], and
    /// a phase that does not exist.
    pub fn new(spec: &ScenarioSpec, from_phase: usize) -> Result<Timeline, ScenarioError> {
        let built = Scenario::new(spec, 0)?;
        let count = built.phases.len();
        if from_phase >= count {
            return Err(ScenarioError {
                origin: spec.name.clone(),
                line: None,
                location: Some("scenario".into()),
                field: Some("phase".into()),
                problem: format!("has {count} phase{}; there is no phase {}", if count == 1 { "" } else { "s" }, from_phase + 1),
            });
        }
        let base = built.phases[from_phase].start_offset_ns;
        let mut phases = Vec::with_capacity(count - from_phase + MAX_RUN_PHASES);
        for mut p in built.phases.into_iter().skip(from_phase) {
            p.start_offset_ns -= base;
            phases.push(p);
        }
        let new = phases.len();
        Ok(Timeline { name: spec.name.clone(), phases, new })
    }

    /// The scenario the phases come from.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The phases to switch in (after a splice: none).
    pub fn phases(&self) -> &[Phase] {
        &self.phases[..self.new]
    }

    /// Whether any stage of the new phases can release frames out of
    /// their arrival order.
    pub fn may_reorder(&self) -> bool {
        self.phases().iter().flat_map(|p| &p.stages).any(|s| s.model.may_reorder())
    }

    /// The index (from 0) of the phase of `spec` named `key`, or numbered
    /// `key` (from 1, as reports count them).
    pub fn phase_index(spec: &ScenarioSpec, key: &str) -> Result<usize, ScenarioError> {
        let count = spec.phases.len();
        let by_number = key.trim().parse::<usize>().ok().filter(|n| (1..=count).contains(n)).map(|n| n - 1);
        let by_name = || spec.phases.iter().position(|p| p.name.as_deref() == Some(key));
        by_number.or_else(by_name).ok_or_else(|| {
            let names: Vec<&str> = spec.phases.iter().filter_map(|p| p.name.as_deref()).collect();
            ScenarioError {
                origin: spec.name.clone(),
                line: None,
                location: Some("scenario".into()),
                field: Some("phase".into()),
                problem: format!(
                    "no phase `{key}`: give a number from 1 to {count}{}",
                    if names.is_empty() { String::new() } else { format!(" or a name ({})", names.join(", ")) }
                ),
            }
        })
    }
}

/// What a splice did.
#[derive(Debug)]
pub struct Switched {
    /// When the new phases start, ns from the run's first frame.
    pub from_ns: u64,
    /// The index of the first new phase in the run's timeline.
    pub first_phase: usize,
    /// How many phases that had not started were cut.
    pub cut: usize,
    /// The cut phases and the emptied container: drop it off the hot path.
    pub retired: Timeline,
}

impl Scenario {
    /// Makes room for `extra` more phases, so that splicing them in never
    /// allocates. Call before the run.
    pub fn reserve_phases(&mut self, extra: usize) {
        self.phases.reserve_exact(extra);
    }

    /// Pauses (every frame passes untouched, no stage draws) or resumes.
    pub fn set_paused(&mut self, paused: bool) {
        self.paused = paused;
    }

    pub fn paused(&self) -> bool {
        self.paused
    }

    /// The index of the phase that decided the last frame (0 before any).
    pub fn current_phase(&self) -> usize {
        self.current
    }

    /// The decision of a paused scenario: passed at once, no copies, no flips.
    #[inline]
    pub(super) fn pass_untouched(&mut self) -> Decision {
        self.flips.len = 0;
        self.copies.passed = 0;
        self.copies.dropped = 0;
        Decision::Pass { delay_ns: 0 }
    }

    /// Rewrites the timeline from `from_ns` (ns from the run's first frame;
    /// see the module docs): phases that start at or after it are cut
    /// (never the one running once a frame was `decided`), and
    /// `timeline`'s phases start at `from_ns` (moved just past the running
    /// phase's start if it is not already). Allocates nothing; refused
    /// (the timeline handed back) when the run's phases would exceed the
    /// room reserved ([`Scenario::reserve_phases`]) or `u16::MAX`.
    pub fn splice(&mut self, from_ns: u64, decided: bool, mut timeline: Timeline) -> Result<Switched, Timeline> {
        let lower = if decided { self.current + 1 } else { 0 };
        let k = lower.max(self.phases.partition_point(|p| p.start_offset_ns < from_ns));
        let from_ns = match k {
            0 => from_ns,
            _ => from_ns.max(self.phases[k - 1].start_offset_ns + 1),
        };
        let (cut, new) = (self.phases.len() - k, timeline.new);
        let fits = k + new <= self.phases.capacity() && k + new <= usize::from(u16::MAX) && timeline.phases.capacity() - new >= cut;
        if !fits || new == 0 {
            return Err(timeline);
        }
        for (i, p) in timeline.phases.iter_mut().enumerate() {
            p.start_offset_ns = p.start_offset_ns.saturating_add(from_ns);
            for st in &mut p.stages {
                st.rng = StageRng::seed_from_u64(stream_seed(self.seed, k + i, &st.label));
            }
        }
        while self.phases.len() > k {
            let p = self.phases.pop().expect("more phases than k");
            timeline.phases.push(p);
        }
        self.phases.extend(timeline.phases.drain(..new));
        timeline.new = 0;
        Ok(Switched { from_ns, first_phase: k, cut, retired: timeline })
    }
}

#[cfg(test)]
mod tests {
    use super::super::parse_str;
    use super::*;
    use crate::injector::{Entered, Injector};
    use crate::scheduler::QueueOrder;

    const A: &str = "name = \"A\"\n[[stage]]\npreset = \"PLM-2\"\n";
    const B: &str = "name = \"B\"\n[[stage]]\nmodel = \"bernoulli\"\np = 0.2\n[[stage]]\nmodel = \"delay\"\nmin_ms = 2\ndist = \"hyperexp\"\nweights = [1.0]\nrates_per_ms = [0.5]\n";

    fn spec(text: &str) -> ScenarioSpec {
        parse_str(text, "s.toml", "s").unwrap()
    }

    /// `parts` laid end to end: each part's phases shifted to its start.
    fn timeline_of(parts: &[(&ScenarioSpec, f64)]) -> ScenarioSpec {
        let mut out = parts[0].0.clone();
        out.phases.clear();
        for (s, start_ms) in parts {
            for p in &s.phases {
                out.phases.push(super::super::PhaseSpec { start_ms: start_ms + p.start_ms, ..p.clone() });
            }
        }
        out
    }

    /// Frames every `gap_ns`; before frame `i`, the switches due then are
    /// applied at the frame's time (`at` = `None`: "now").
    fn run_switched(seed: u64, frames: u64, gap_ns: u64, first: &ScenarioSpec, switches: &[(u64, Option<u64>, &ScenarioSpec)]) -> Vec<(Entered, Vec<(u64, u64)>)> {
        let mut sc = Scenario::new(first, seed).unwrap();
        sc.reserve_phases(MAX_RUN_PHASES);
        // Both runs hold frames in the same order of queue: a FIFO ring
        // would hold B's short delays behind A's.
        let mut inj: Injector<u64> = Injector::try_with_order(sc, 1 << 14, QueueOrder::Reorder).unwrap();
        let mut out = Vec::new();
        for i in 0..frames {
            let t = 1_000_000 + i * gap_ns;
            for (before, at, s) in switches {
                if *before == i {
                    inj.switch(t, *at, Timeline::new(s, 0).unwrap()).unwrap();
                }
            }
            out.push(step(&mut inj, t, i));
        }
        out
    }

    fn step(inj: &mut Injector<u64>, t: u64, i: u64) -> (Entered, Vec<(u64, u64)>) {
        let mut released = Vec::new();
        while let Some(r) = inj.pop_due(t) {
            released.push((r.ingress_index, r.release_ns));
        }
        (inj.ingress(t, i), released)
    }

    fn run_static(seed: u64, frames: u64, gap_ns: u64, spec: &ScenarioSpec) -> Vec<(Entered, Vec<(u64, u64)>)> {
        let mut inj: Injector<u64> = Injector::try_with_order(Scenario::new(spec, seed).unwrap(), 1 << 14, QueueOrder::Reorder).unwrap();
        (0..frames).map(|i| step(&mut inj, 1_000_000 + i * gap_ns, i)).collect()
    }

    #[test]
    fn a_switched_run_gives_the_fates_of_the_same_timeline_frame_by_frame() {
        let (a, b) = (spec(A), spec(B));
        let gap = 1_000_000;
        // A, then B from frame 3000 (told "now", between frames 2999 and
        // 3000), then A again from 7 s (told ahead, at frame 5000).
        let switched = run_switched(7, 10_000, gap, &a, &[(3000, None, &b), (5000, Some(7_000_000_000), &a)]);
        let same = run_static(7, 10_000, gap, &timeline_of(&[(&a, 0.0), (&b, 3000.0), (&a, 7000.0)]));
        assert_eq!(switched.len(), same.len());
        for (i, (x, y)) in switched.iter().zip(&same).enumerate() {
            assert_eq!(x, y, "frame {i}");
        }
        // The switch is real: B's delays and A's bursts both appear.
        let delayed = switched.iter().filter(|(e, _)| matches!(e.fate, crate::injector::Fate::Scheduled { delay_ns, .. } if delay_ns > 0)).count();
        assert!(delayed > 2000, "{delayed}");
        // Another seed gives other fates: the comparison can fail.
        assert_ne!(switched, run_static(8, 10_000, gap, &timeline_of(&[(&a, 0.0), (&b, 3000.0), (&a, 7000.0)])));
    }

    #[test]
    fn a_switch_ahead_replaces_what_had_not_started() {
        // A later switch told before an earlier one took effect: the
        // earlier is cut, as if never asked.
        let (a, b) = (spec(A), spec(B));
        let switched = run_switched(3, 4000, 1_000_000, &a, &[(100, Some(3_000_000_000), &b), (200, Some(2_000_000_000), &a)]);
        let same = run_static(3, 4000, 1_000_000, &timeline_of(&[(&a, 0.0), (&a, 2000.0)]));
        assert_eq!(switched, same);
    }

    #[test]
    fn pausing_passes_everything_and_the_streams_resume() {
        let mut inj: Injector<u64> = Injector::new(Scenario::new(&spec(A), 5).unwrap(), 1 << 12);
        let mut reference: Injector<u64> = Injector::new(Scenario::new(&spec(A), 5).unwrap(), 1 << 12);
        for i in 0..1000 {
            inj.ingress(i, i);
            reference.ingress(i, i);
        }
        inj.set_paused(true);
        for i in 1000..2000 {
            assert!(matches!(inj.ingress(i, i).fate, crate::injector::Fate::Scheduled { delay_ns: 0, .. }));
        }
        inj.set_paused(false);
        // The stage drew nothing while paused: it goes on as if the
        // paused frames had never come.
        for i in 2000..3000 {
            let dropped = |f| matches!(f, crate::injector::Fate::Dropped(_));
            assert_eq!(dropped(inj.ingress(i, i).fate), dropped(reference.ingress(i - 1000, i).fate), "frame {i}");
        }
        assert_eq!(inj.scenario().phases()[0].stages()[0].reached(), 2000);
    }

    #[test]
    fn a_phase_that_does_not_exist_and_a_full_timeline_are_refused() {
        let e = Timeline::new(&spec(A), 1).unwrap_err();
        assert!(e.to_string().contains("there is no phase 2"), "{e}");
        let two = spec("name = \"T\"\n[[phase]]\nname = \"calm\"\nstart_ms = 0\n[[phase.stage]]\npreset = \"Normal\"\n[[phase]]\nname = \"storm\"\nstart_ms = 10\n[[phase.stage]]\npreset = \"PLM-3\"\n");
        assert_eq!(Timeline::phase_index(&two, "storm").unwrap(), 1);
        assert_eq!(Timeline::phase_index(&two, "1").unwrap(), 0);
        let e = Timeline::phase_index(&two, "3").unwrap_err();
        assert!(e.to_string().contains("from 1 to 2 or a name (calm, storm)"), "{e}");
        // No room reserved: the timeline comes back, nothing changed.
        let mut sc = Scenario::new(&spec(A), 1).unwrap();
        sc.phases.shrink_to_fit();
        let back = sc.splice(5, true, Timeline::new(&spec(B), 0).unwrap()).unwrap_err();
        assert_eq!((back.phases().len(), sc.phases().len()), (1, 1));
    }
}
