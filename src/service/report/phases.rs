//! The run's stretches under one condition: its timeline (the phases of its
//! scenario, rewritten by each live switch, docs/interface.md "Live
//! control") and its pauses, rebuilt from the scenario and the control
//! events, then each stretch's frames taken from the trace: the loss with
//! its interval, and the delays against that stretch's own law.
//!
//! A pure function of the trace's rows, the scenario and the events: no
//! file, no clock. A frame belongs to the phase whose start is at or before
//! its ingress time (ns from the run's first frame), as the injector
//! decides it; to a pause when it entered after the pause and before the
//! resume took effect.

use super::delay::{delay_check_against, Delays, Law};
use super::PhaseFigures;
use crate::check::StageReport;
use crate::scenario::{ScenarioSpec, Timeline};
use crate::service::control::{Action, ControlEvent};
use crate::stats::BatchMeans;
use std::sync::Arc;

/// One phase of the run's timeline: when it starts (ns from the run's
/// first frame), and the scenario and phase (index from 0) it comes from.
#[derive(Debug, Clone)]
pub struct TimelinePhase {
    pub start_ns: u64,
    pub spec: Arc<ScenarioSpec>,
    pub phase: usize,
}

/// The run's timeline as the emulator ran it, and its pauses.
#[derive(Debug, Clone)]
pub struct RunTimeline {
    pub phases: Vec<TimelinePhase>,
    /// `(t_ns, paused)`: from `t_ns` on, faults were paused or not; in time order.
    pub toggles: Vec<(u64, bool)>,
}

/// A stretch of the run: `[from_ns, to_ns)` (to the end when `None`) in
/// the run's phase `phase` (index from 0), paused or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stretch {
    pub from_ns: u64,
    pub to_ns: Option<u64>,
    pub phase: usize,
    pub paused: bool,
}

impl RunTimeline {
    /// The timeline of a run of `spec` steered by `events` (in the order
    /// they took effect). An event that does not say what it did (a report
    /// of an older netfi) is read from its words where it names a preset;
    /// otherwise the timeline is unknown, and the error says which event.
    pub fn of(spec: &ScenarioSpec, events: &[ControlEvent]) -> Result<RunTimeline, String> {
        let own = Arc::new(spec.clone());
        let mut phases: Vec<TimelinePhase> = (0..spec.phases.len())
            .map(|i| TimelinePhase { start_ns: crate::model::units::ms_to_ns(spec.phases[i].start_ms), spec: own.clone(), phase: i })
            .collect();
        let mut toggles = Vec::new();
        for e in events {
            let at = e.at_ns();
            match action(e)? {
                Act::Pause(paused) => toggles.push((at, paused)),
                Act::Switch { spec, from_phase, run_phase } => {
                    let spec = Arc::new(spec);
                    // As the emulator's splice: the phases that had not
                    // started by the switch are cut.
                    let k = run_phase.unwrap_or_else(|| phases.partition_point(|p| p.start_ns < at).max(1));
                    if from_phase >= spec.phases.len() || k == 0 || k > phases.len() {
                        return Err(format!("the control event at t = {:.3} s ({}) does not fit the run's timeline", e.t_s, e.what));
                    }
                    phases.truncate(k);
                    let base = crate::model::units::ms_to_ns(spec.phases[from_phase].start_ms);
                    for i in from_phase..spec.phases.len() {
                        let start_ns = at + (crate::model::units::ms_to_ns(spec.phases[i].start_ms) - base);
                        phases.push(TimelinePhase { start_ns, spec: spec.clone(), phase: i });
                    }
                }
            }
        }
        toggles.sort_by_key(|t| t.0);
        Ok(RunTimeline { phases, toggles })
    }

    /// Whether the run had one condition throughout: one phase, no pause.
    pub fn is_single(&self) -> bool {
        self.phases.len() == 1 && !self.toggles.iter().any(|t| t.1)
    }

    /// The run cut at every phase start and every pause and resume that
    /// changed something, in time order.
    pub fn stretches(&self) -> Vec<Stretch> {
        let mut cuts: Vec<u64> = self.phases.iter().skip(1).map(|p| p.start_ns).chain(self.toggles.iter().map(|t| t.0)).collect();
        cuts.push(0);
        cuts.sort_unstable();
        cuts.dedup();
        let mut out: Vec<Stretch> = Vec::new();
        for (i, &from) in cuts.iter().enumerate() {
            let to = cuts.get(i + 1).copied();
            let phase = self.phases.partition_point(|p| p.start_ns <= from).saturating_sub(1);
            let paused = self.toggles.iter().take_while(|t| t.0 <= from).last().is_some_and(|t| t.1);
            match out.last_mut() {
                // A pause or resume that changed nothing does not cut.
                Some(last) if last.phase == phase && last.paused == paused => last.to_ns = to,
                _ => out.push(Stretch { from_ns: from, to_ns: to, phase, paused }),
            }
        }
        out
    }

    /// Which stretch `t_ns` falls in.
    fn stretch_of(stretches: &[Stretch], t_ns: u64) -> usize {
        stretches.partition_point(|s| s.from_ns <= t_ns).saturating_sub(1)
    }
}

/// What a control event did.
enum Act {
    Pause(bool),
    Switch { spec: ScenarioSpec, from_phase: usize, run_phase: Option<usize> },
}

fn action(e: &ControlEvent) -> Result<Act, String> {
    let unknown = || format!("the control event at t = {:.3} s ({}) does not say what it switched to (a report of an older netfi)", e.t_s, e.what);
    match &e.action {
        Some(Action::Pause) => Ok(Act::Pause(true)),
        Some(Action::Resume) => Ok(Act::Pause(false)),
        Some(Action::Switch { scenario, from_phase, run_phase }) => {
            let spec = crate::scenario::parse_str(scenario, "control event", "switched").map_err(|err| format!("{}: {err}", unknown()))?;
            Ok(Act::Switch { spec, from_phase: from_phase.saturating_sub(1), run_phase: Some(run_phase.saturating_sub(1)) })
        }
        None if e.what.starts_with("pause") => Ok(Act::Pause(true)),
        None if e.what == "resume" => Ok(Act::Pause(false)),
        None => {
            let rest = e.what.strip_prefix("switch to ").ok_or_else(unknown)?;
            let (name, phase) = match rest.split_once(", phase ") {
                Some((n, p)) => (n, p.split_whitespace().next().and_then(|p| p.parse::<usize>().ok()).ok_or_else(unknown)?),
                None => (rest, 1),
            };
            let spec = crate::scenario::preset(name).ok_or_else(unknown)?;
            Ok(Act::Switch { spec, from_phase: phase.saturating_sub(1), run_phase: None })
        }
    }
}

/// Each frame's ingress time (ns, CLOCK_MONOTONIC) and whether it was
/// dropped, in ingress order, packed in one word each (copies and
/// malformed frames left out); and the first frame's ingress time.
#[derive(Debug, Default, Clone)]
pub struct Fates {
    words: Vec<u64>,
    origin_ns: Option<u64>,
}

impl Fates {
    /// Adds a frame the scenario decided, which entered at `ingress_ns`.
    pub fn push(&mut self, ingress_ns: u64, dropped: bool) {
        self.entered(ingress_ns);
        self.words.push((ingress_ns << 1) | u64::from(dropped));
    }

    /// Notes a frame that entered at `ingress_ns`, decided or not (a
    /// malformed one, refused before the scenario, starts the timeline too).
    pub fn entered(&mut self, ingress_ns: u64) {
        self.origin_ns.get_or_insert(ingress_ns);
    }

    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.words.len()
    }

    /// The first frame's ingress time: the origin of the run's timeline.
    pub fn origin_ns(&self) -> Option<u64> {
        self.origin_ns
    }

    fn iter(&self) -> impl Iterator<Item = (u64, bool)> + '_ {
        self.words.iter().map(|w| (w >> 1, w & 1 == 1))
    }
}

/// The figures of each stretch of `timeline`: frames and loss from
/// `fates`, the delays from `delays` (those of received frames, with their
/// ingress times) against the phase's own law. `stages` are the run's
/// stage reports, for the model's loss of each phase.
pub fn figures(timeline: &RunTimeline, fates: &Fates, delays: &Delays, stages: &[StageReport]) -> Vec<PhaseFigures> {
    let Some(origin) = fates.origin_ns() else { return Vec::new() };
    let stretches = timeline.stretches();
    let n = stretches.len();
    // Each stretch's drops in order, for the batch means, and its delays.
    let mut drops: Vec<Vec<bool>> = vec![Vec::new(); n];
    for (t, dropped) in fates.iter() {
        drops[RunTimeline::stretch_of(&stretches, t.saturating_sub(origin))].push(dropped);
    }
    let mut own: Vec<Delays> = (0..n).map(|_| Delays::default()).collect();
    for ((&t, &d), &s) in delays.ingress_ns.iter().zip(&delays.injected).zip(&delays.seen) {
        let k = RunTimeline::stretch_of(&stretches, t.saturating_sub(origin));
        own[k].injected.push(d);
        own[k].seen.push(s);
    }
    // Each phase's delay law, built once.
    let laws: Vec<Option<Law>> = timeline.phases.iter().map(phase_law).collect();
    stretches
        .iter()
        .zip(drops)
        .zip(own)
        .map(|((st, d), delays)| {
            let p = &timeline.phases[st.phase];
            let mut bm = BatchMeans::new(d.len() as u64);
            d.iter().for_each(|x| bm.record(*x));
            let unseen = if st.paused { 0.0 } else { unseen_loss_rate(p, stages, st.phase + 1, bm.trials()) };
            let (loss_rate, ci) = bm.rate_ci95_with(unseen);
            let law = if st.paused { None } else { laws[st.phase].as_ref() };
            PhaseFigures {
                run_phase: st.phase + 1,
                scenario: p.spec.name.clone(),
                scenario_phase: p.phase + 1,
                phase_name: p.spec.phases[p.phase].name.clone(),
                paused: st.paused,
                from_ns: st.from_ns,
                to_ns: st.to_ns,
                frames: bm.trials(),
                dropped: bm.events(),
                loss_rate,
                loss_rate_ci95: ci,
                loss_rate_unseen_model: (unseen > 0.0).then_some(unseen),
                loss_rate_model: if st.paused { Some(0.0) } else { phase_loss_model(stages, st.phase + 1) },
                delay_check: delay_check_against(law, delays, law.is_some()),
            }
        })
        .collect()
}

/// [`crate::check::unseen_loss_rate`] for `frames` frames of a stretch of
/// the run's phase `run_phase` (from 1), `p`: each stage's share of the
/// phase's frames as the run's stage counts give it.
fn unseen_loss_rate(p: &TimelinePhase, stages: &[StageReport], run_phase: usize, frames: u64) -> f64 {
    let own: Vec<&StageReport> = stages.iter().filter(|s| s.phase == run_phase).collect();
    let first = own.first().map_or(0, |s| s.reached);
    let specs = &p.spec.phases[p.phase].stages;
    own.iter()
        .filter_map(|r| {
            let share = if first > 0 { r.reached as f64 / first as f64 } else { 1.0 };
            let model = specs.get(r.stage.checked_sub(1)?)?.model.build().ok()?;
            Some(share * model.unseen_loss_rate((frames as f64 * share).round() as u64))
        })
        .sum()
}

/// The long-run loss of the run's phase `phase` (from 1) by its models:
/// `1 − Π(1 − m_i)` over its stages (each stage's loss is over the frames
/// that reach it), where every stage's model loss is known.
fn phase_loss_model(stages: &[StageReport], phase: usize) -> Option<f64> {
    let own: Vec<&StageReport> = stages.iter().filter(|s| s.phase == phase).collect();
    if own.is_empty() {
        return None;
    }
    own.iter().try_fold(1.0, |pass, s| Some(pass * (1.0 - s.loss_rate_model?))).map(|pass| 1.0 - pass)
}

/// The delay law of a phase: its one delay stage, where it has one.
fn phase_law(p: &TimelinePhase) -> Option<Law> {
    Law::of_phase(Timeline::new(&p.spec, p.phase).ok()?.phases().first()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(t_ms: u64, what: &str, action: Option<Action>) -> ControlEvent {
        ControlEvent { t_s: t_ms as f64 / 1e3, what: what.into(), t_ns: Some(t_ms * 1_000_000), action }
    }

    fn switch(t_ms: u64, scenario: &str, run_phase: usize) -> ControlEvent {
        let spec = crate::scenario::preset(scenario).unwrap();
        ev(t_ms, &format!("switch to {scenario}"), Some(Action::Switch { scenario: spec.to_toml(), from_phase: 1, run_phase }))
    }

    fn plm2() -> ScenarioSpec {
        crate::scenario::preset("PLM-2").unwrap()
    }

    #[test]
    fn switches_and_pauses_cut_the_run_into_stretches() {
        let events = [
            switch(1000, "DLM-1", 2),
            ev(2000, "pause: every frame passes untouched", Some(Action::Pause)),
            ev(2500, "resume", Some(Action::Resume)),
            // A pause and a resume that change nothing cut nothing.
            ev(2600, "resume", Some(Action::Resume)),
        ];
        let t = RunTimeline::of(&plm2(), &events).unwrap();
        assert!(!t.is_single());
        let names: Vec<&str> = t.phases.iter().map(|p| p.spec.name.as_str()).collect();
        assert_eq!(names, ["PLM-2", "DLM-1"]);
        let ms = 1_000_000;
        assert_eq!(
            t.stretches(),
            [
                Stretch { from_ns: 0, to_ns: Some(1000 * ms), phase: 0, paused: false },
                Stretch { from_ns: 1000 * ms, to_ns: Some(2000 * ms), phase: 1, paused: false },
                Stretch { from_ns: 2000 * ms, to_ns: Some(2500 * ms), phase: 1, paused: true },
                Stretch { from_ns: 2500 * ms, to_ns: None, phase: 1, paused: false },
            ]
        );
        assert!(RunTimeline::of(&plm2(), &[]).unwrap().is_single());
    }

    #[test]
    fn a_switch_cuts_the_phases_that_had_not_started_as_the_emulator_does() {
        let two = crate::scenario::parse_str(
            "name = \"T\"\n[[phase]]\nstart_ms = 0\n[[phase.stage]]\npreset = \"Normal\"\n[[phase]]\nstart_ms = 3000\n[[phase.stage]]\npreset = \"PLM-3\"\n",
            "t",
            "t",
        )
        .unwrap();
        // Switched at 1 s, before T's second phase began: it is cut.
        let t = RunTimeline::of(&two, &[switch(1000, "DLM-2", 2)]).unwrap();
        let got: Vec<(u64, &str)> = t.phases.iter().map(|p| (p.start_ns / 1_000_000, p.spec.name.as_str())).collect();
        assert_eq!(got, [(0, "T"), (1000, "DLM-2")]);
        // An older report's words: the preset it names, cut the same way.
        let old = ControlEvent { t_s: 1.0, what: "switch to DLM-2".into(), t_ns: None, action: None };
        let t = RunTimeline::of(&two, &[old]).unwrap();
        assert_eq!(t.phases.len(), 2);
        // Words that name no preset leave the timeline unknown, saying which event.
        let file = ControlEvent { t_s: 1.5, what: "switch to my.toml".into(), t_ns: None, action: None };
        let e = RunTimeline::of(&two, &[file]).unwrap_err();
        assert!(e.contains("t = 1.500 s (switch to my.toml)"), "{e}");
    }

    /// 1 kHz frames for 3 s, PLM-2 then DLM-1 from 1 s then paused from
    /// 2 s: frames dropped in the first second only, every other one.
    #[test]
    fn each_stretch_has_its_own_frames_loss_and_delay_law() {
        let events = [switch(1000, "DLM-1", 2), ev(2000, "pause: every frame passes untouched", Some(Action::Pause))];
        let t = RunTimeline::of(&plm2(), &events).unwrap();
        let origin = 5_000_000_000u64;
        let mut fates = Fates::default();
        let mut delays = Delays::default();
        let law = Law::of_phase(Timeline::new(&crate::scenario::preset("DLM-1").unwrap(), 0).unwrap().phases().first().unwrap()).unwrap();
        for i in 0..3000u64 {
            let t = origin + i * 1_000_000;
            let dropped = i < 1000 && i % 2 == 0;
            fates.push(t, dropped);
            if !dropped {
                // DLM-1's draws at its own quantiles while it ran, none else.
                let d = if (1000..2000).contains(&i) { (law.quantile_ms((i - 1000) as f64 / 1000.0 + 0.0005) * 1e6) as u64 } else { 0 };
                delays.ingress_ns.push(t);
                delays.injected.push(d);
                delays.seen.push(d + 10_000);
            }
        }
        let f = figures(&t, &fates, &delays, &[]);
        assert_eq!(f.len(), 3);
        assert_eq!((f[0].scenario.as_str(), f[0].frames, f[0].dropped, f[0].paused), ("PLM-2", 1000, 500, false));
        assert!((f[0].loss_rate - 0.5).abs() < 1e-12 && f[0].loss_rate_ci95[0] < 0.5 && f[0].loss_rate_ci95[1] > 0.5, "{:?}", f[0]);
        assert_eq!((f[1].scenario.as_str(), f[1].run_phase, f[1].frames, f[1].dropped), ("DLM-1", 2, 1000, 0));
        let dc = f[1].delay_check.as_ref().expect("DLM-1 delays");
        assert_eq!(dc.injected_within_model_band, Some(true), "{dc:?}");
        assert!(f[0].delay_check.is_none(), "PLM-2 injected no delay");
        assert_eq!((f[2].paused, f[2].frames, f[2].loss_rate_model, f[2].to_ns), (true, 1000, Some(0.0), None));
        assert!(f[2].delay_check.is_none());
        // The same delays against the first phase's law would be off it:
        // the check can fail.
        let dlm2 = Law::of_phase(Timeline::new(&crate::scenario::preset("DLM-2").unwrap(), 0).unwrap().phases().first().unwrap());
        let off = delay_check_against(dlm2.as_ref(), Delays { ingress_ns: vec![], injected: delays.injected[500..1500].to_vec(), seen: delays.seen[500..1500].to_vec() }, false).unwrap();
        assert_eq!(off.injected_within_model_band, Some(false));
    }

    #[test]
    fn a_phase_model_loss_combines_its_stages() {
        let st = |phase: usize, m: Option<f64>| -> StageReport {
            serde_json::from_value(serde_json::json!({
                "phase": phase, "stage": 1, "label": "x", "model": "bernoulli", "reached": 0, "dropped": 0, "loss_rate": 0.0, "loss_rate_model": m
            }))
            .unwrap()
        };
        let stages = [st(1, Some(0.5)), st(1, Some(0.0)), st(2, Some(0.2)), st(2, Some(0.5)), st(3, None)];
        assert_eq!(phase_loss_model(&stages, 1), Some(0.5));
        assert!((phase_loss_model(&stages, 2).unwrap() - 0.6).abs() < 1e-12);
        assert_eq!(phase_loss_model(&stages, 3), None);
        assert_eq!(phase_loss_model(&stages, 4), None);
    }
}
