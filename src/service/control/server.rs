//! The control thread: serves the run's control service, validates each
//! request with the scenario parser, hands built phases to the loop and
//! records what the loop applied (`events.jsonl`).

use super::port::{Applied, Command, Shared};
use super::protocol::{resolve, Action, ControlEvent, PhaseOf, Request, Response, State};
use crate::clock::now_ns;
use crate::scenario::{ScenarioSpec, Timeline, MAX_RUN_PHASES};
use crate::scheduler::QueueOrder;
use crate::transport::ipc::control::{ControlServer, TelemetryPublisher, TelemetrySample};
use crate::transport::{IpcConfig, IpcNode, Role};
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{mpsc, Arc};
use std::time::Duration;

/// How the control thread is set up.
#[derive(Debug, Clone)]
pub struct Settings {
    pub run: IpcConfig,
    /// The scenario the run started with.
    pub spec: ScenarioSpec,
    pub queue_order: QueueOrder,
    /// Where `events.jsonl` goes.
    pub out_dir: PathBuf,
    /// Telemetry interval, ns; `None`: no telemetry.
    pub telemetry_interval_ns: Option<u64>,
    /// The stages the run's link cannot apply ([`crate::service::link::Carried::UNSUPPORTED`]):
    /// a switch to a scenario with one is refused.
    pub unsupported: &'static [crate::model::ModelKind],
}

/// One phase of the run's timeline, as the control thread mirrors it.
#[derive(Debug, Clone)]
struct Mirrored {
    start_ns: u64,
    spec: Arc<ScenarioSpec>,
    /// Index in `spec` (from 0).
    phase: usize,
}

/// A request sent to the loop, waiting for its outcome.
struct Sent {
    id: u64,
    what: String,
    spec: Option<(Arc<ScenarioSpec>, usize)>,
}

/// The control thread's state.
pub(super) struct Server {
    settings: Settings,
    commands: rtrb::Producer<Command>,
    applied: rtrb::Consumer<Applied>,
    shared: Arc<Shared>,
    telemetry: mpsc::Receiver<TelemetrySample>,
    timeline: Vec<Mirrored>,
    events: Vec<ControlEvent>,
    /// `events.jsonl`, as `events.jsonl.partial` until the run ends with
    /// every line written (then renamed; a write that fails leaves it cut).
    log: Option<crate::durable::PartialFile>,
    log_failed: bool,
    next_id: u64,
    /// Commands sent and not yet reported applied.
    sent: Vec<Sent>,
}

/// How long a request waits for the loop to take its command.
const APPLY_WAIT: Duration = Duration::from_secs(2);
/// How often the control thread wakes.
const TICK: Duration = Duration::from_millis(5);

impl Server {
    pub(super) fn new(settings: Settings, commands: rtrb::Producer<Command>, applied: rtrb::Consumer<Applied>, shared: Arc<Shared>, telemetry: mpsc::Receiver<TelemetrySample>) -> Server {
        let spec = Arc::new(settings.spec.clone());
        let timeline = (0..spec.phases.len())
            .map(|i| Mirrored { start_ns: crate::model::units::ms_to_ns(spec.phases[i].start_ms), spec: spec.clone(), phase: i })
            .collect();
        Server { settings, commands, applied, shared, telemetry, timeline, events: Vec::new(), log: None, log_failed: false, next_id: 0, sent: Vec::new() }
    }

    pub(super) fn run(mut self, ready: mpsc::Sender<Result<(), super::StartError>>) -> Vec<ControlEvent> {
        let opened = (|| -> Result<_, super::StartError> {
            let node = IpcNode::open(&self.settings.run, Role::Tool)?;
            let server = ControlServer::open(&node)?;
            let publisher = match self.settings.telemetry_interval_ns {
                Some(_) => Some(TelemetryPublisher::open(&node)?),
                None => None,
            };
            let path = self.settings.out_dir.join("events.jsonl");
            let log = crate::durable::PartialFile::create(&path)?;
            Ok((node, server, publisher, log))
        })();
        let (_node, server, publisher, log) = match opened {
            Ok(o) => o,
            Err(e) => {
                let _ = ready.send(Err(e));
                return Vec::new();
            }
        };
        self.log = Some(log);
        let _ = ready.send(Ok(()));
        while !self.shared.stop.load(Ordering::Acquire) {
            server.serve(|req| match req {
                Ok(req) => self.answer(req),
                Err(e) => refuse(&e),
            });
            self.drain_applied(None);
            if let Some(p) = &publisher {
                while let Ok(mut s) = self.telemetry.try_recv() {
                    s.phase = self.shared.phase.load(Ordering::Relaxed) as u32 + 1;
                    s.flags = if self.shared.paused.load(Ordering::Relaxed) { TelemetrySample::FLAG_PAUSED } else { 0 };
                    p.send(&s);
                }
            }
            std::thread::sleep(TICK);
        }
        self.drain_applied(None);
        self.finish_events()
    }

    /// The events that took effect: a switch scheduled after the run's
    /// last frame never did.
    fn finish_events(mut self) -> Vec<ControlEvent> {
        if let Some(log) = self.log.take().filter(|_| !self.log_failed) {
            if let Err(e) = log.commit() {
                eprintln!("emulator: {e}");
            }
        }
        let end_s = self.now_offset_ns() as f64 / 1e9;
        self.events.retain(|e| e.t_s <= end_s);
        self.events
    }

    fn now_offset_ns(&self) -> u64 {
        match self.shared.start_ns.load(Ordering::Relaxed) {
            0 => 0,
            s => now_ns().saturating_sub(s - 1),
        }
    }

    fn answer(&mut self, req: &[u8]) -> Vec<u8> {
        // The transport hands over only requests within its limit.
        debug_assert!(req.len() <= crate::transport::ipc::control::MAX_MESSAGE_BYTES);
        let resp = match serde_json::from_slice::<Request>(req) {
            Ok(r) => self.handle(r),
            Err(e) => Err(format!("bad request: {e}")),
        };
        let resp = match resp {
            Ok(message) => Response { ok: true, message, state: Some(self.state()) },
            Err(message) => Response { ok: false, message, state: None },
        };
        serde_json::to_vec(&resp).expect("a response always serializes")
    }

    fn handle(&mut self, req: Request) -> Result<String, String> {
        match req {
            Request::Show => Ok(String::new()),
            Request::Pause => self.send_pause(true),
            Request::Resume => self.send_pause(false),
            Request::Switch { scenario, at_ms } => {
                let at_ns = at(at_ms)?;
                let spec = resolve(&scenario).map_err(|e| e.to_string())?;
                self.send_switch(Arc::new(spec), 0, at_ns)
            }
            Request::Phase { phase, at_ms } => {
                let at_ns = at(at_ms)?;
                let spec = self.current().spec.clone();
                let index = Timeline::phase_index(&spec, &phase).map_err(|e| e.to_string())?;
                self.send_switch(spec, index, at_ns)
            }
        }
    }

    fn current(&self) -> &Mirrored {
        let now = self.now_offset_ns();
        &self.timeline[self.timeline.iter().rposition(|m| m.start_ns <= now).unwrap_or(0)]
    }

    fn send_switch(&mut self, spec: Arc<ScenarioSpec>, from_phase: usize, at_ns: Option<u64>) -> Result<String, String> {
        let timeline = Timeline::new(&spec, from_phase).map_err(|e| e.to_string())?;
        check_real_time(&timeline, self.settings.unsupported)?;
        if self.settings.queue_order == QueueOrder::Fifo && timeline.may_reorder() {
            return Err(format!(
                "scenario `{}` can release frames out of order, but this run's release queue is FIFO (it was started with `--fifo-queue`, or without live control); start it without `--fifo-queue` to switch to it",
                spec.name
            ));
        }
        let what = match (spec.phases.len(), from_phase) {
            (1, _) => format!("switch to {}", spec.name),
            (_, p) => format!("switch to {}, phase {}{}", spec.name, p + 1, spec.phases[p].name.as_deref().map(|n| format!(" ({n})")).unwrap_or_default()),
        };
        let id = self.next_id;
        self.next_id += 1;
        if self.commands.push(Command::Switch { id, at_ns, timeline }).is_err() {
            return Err("the emulator has not taken the earlier commands yet; try again".into());
        }
        self.wait_applied(Sent { id, what, spec: Some((spec, from_phase)) })
    }

    fn send_pause(&mut self, paused: bool) -> Result<String, String> {
        let id = self.next_id;
        self.next_id += 1;
        if self.commands.push(Command::Pause { id, paused }).is_err() {
            return Err("the emulator has not taken the earlier commands yet; try again".into());
        }
        let what = if paused { "pause: every frame passes untouched" } else { "resume" };
        self.wait_applied(Sent { id, what: what.into(), spec: None })
    }

    /// Waits for the loop to apply `sent`; its message.
    fn wait_applied(&mut self, sent: Sent) -> Result<String, String> {
        let t0 = std::time::Instant::now();
        let id = sent.id;
        // Kept until applied: recorded even if the loop takes it after the
        // answer gave up waiting.
        self.sent.push(sent);
        loop {
            if let Some(r) = self.drain_applied(Some(id)) {
                return r;
            }
            if t0.elapsed() >= APPLY_WAIT {
                return Err(format!("the emulator's loop did not take the command within {} s (is the run ending?)", APPLY_WAIT.as_secs()));
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }

    /// Records what the loop applied; the outcome of command `wait_for`, if
    /// it is among them.
    fn drain_applied(&mut self, wait_for: Option<u64>) -> Option<Result<String, String>> {
        let mut outcome = None;
        while let Ok(done) = self.applied.pop() {
            let id = match &done {
                Applied::Switched { id, .. } | Applied::Refused { id } | Applied::Paused { id, .. } => *id,
            };
            let Some(at) = self.sent.iter().position(|s| s.id == id) else { continue };
            let sent = self.sent.remove(at);
            let r = self.record(done, sent);
            if Some(id) == wait_for {
                outcome = Some(r);
            }
        }
        outcome
    }

    fn record(&mut self, done: Applied, sent: Sent) -> Result<String, String> {
        match done {
            Applied::Refused { .. } => Err(format!("the run's timeline is full: it holds at most {MAX_RUN_PHASES} phases switched in; nothing changed")),
            Applied::Paused { paused, t_ns, .. } => {
                self.event(t_ns, sent.what.clone(), if paused { Action::Pause } else { Action::Resume });
                Ok(format!("{} at t = {:.3} s", if paused { "paused" } else { "resumed" }, t_ns as f64 / 1e9))
            }
            Applied::Switched { s, .. } => {
                let (spec, from) = sent.spec.expect("a switch carries its scenario");
                // Switches told ahead that had not begun are replaced.
                let cancelled: Vec<ControlEvent> = self.events.iter().filter(|e| e.at_ns() >= s.from_ns && is_switch(e)).cloned().collect();
                self.events.retain(|e| e.at_ns() < s.from_ns || !is_switch(e));
                for c in cancelled {
                    self.log_line(&ControlEvent { what: format!("cancelled before it began: {}", c.what), action: None, ..c });
                }
                self.timeline.truncate(s.first_phase);
                let base = crate::model::units::ms_to_ns(spec.phases[from].start_ms);
                for i in from..spec.phases.len() {
                    let start = s.from_ns + (crate::model::units::ms_to_ns(spec.phases[i].start_ms) - base);
                    self.timeline.push(Mirrored { start_ns: start, spec: spec.clone(), phase: i });
                }
                let action = Action::Switch { scenario: spec.to_toml(), from_phase: from + 1, run_phase: s.first_phase + 1 };
                self.event(s.from_ns, sent.what.clone(), action);
                // `s.retired` (the cut phases) is dropped here, off the loop.
                let when = if s.from_ns > self.now_offset_ns() { "will take effect" } else { "took effect" };
                Ok(format!("{}: {when} at t = {:.3} s (run phase {})", sent.what, s.from_ns as f64 / 1e9, s.first_phase + 1))
            }
        }
    }

    fn event(&mut self, t_ns: u64, what: String, action: Action) {
        let e = ControlEvent { t_s: t_ns as f64 / 1e9, what, t_ns: Some(t_ns), action: Some(action) };
        self.log_line(&e);
        self.events.push(e);
    }

    /// One line of `events.jsonl`, flushed at once.
    fn log_line(&mut self, e: &ControlEvent) {
        if let Some(f) = self.log.as_mut().filter(|_| !self.log_failed) {
            let written = serde_json::to_writer(&mut *f, e).map_err(std::io::Error::from).and_then(|()| f.write_all(b"\n"));
            // A line that could not be written whole leaves the file cut.
            self.log_failed = written.and_then(|()| f.flush()).is_err();
        }
    }

    fn state(&self) -> State {
        let started = self.shared.start_ns.load(Ordering::Relaxed) != 0;
        let now = self.now_offset_ns();
        // The phase the timeline has at this moment (the loop moves to it
        // with its next frame).
        let phase = self.timeline.iter().rposition(|m| m.start_ns <= now).unwrap_or(0);
        let cur = &self.timeline[phase];
        State {
            t_s: now as f64 / 1e9,
            started,
            frames_entered: self.shared.entered.load(Ordering::Relaxed),
            paused: self.shared.paused.load(Ordering::Relaxed),
            phase: phase + 1,
            scenario: cur.spec.name.clone(),
            scenario_phase: cur.phase + 1,
            phase_name: cur.spec.phases[cur.phase].name.clone(),
            upcoming: self.timeline[phase + 1..].iter().map(|m| (m.start_ns as f64 / 1e9, m.spec.name.clone(), m.phase + 1)).collect(),
            queue_order: format!("{:?}", self.settings.queue_order).to_lowercase(),
            scenario_phases: cur
                .spec
                .phases
                .iter()
                .enumerate()
                .map(|(i, p)| PhaseOf { number: i + 1, name: p.name.clone(), start_s: p.start_ms / 1e3 })
                .collect(),
        }
    }
}

/// Whether `e` is a switch (pauses are not cut by a later switch).
fn is_switch(e: &ControlEvent) -> bool {
    !matches!(e.action, Some(Action::Pause | Action::Resume))
}

/// `at_ms` as ns from the run's first frame.
fn at(at_ms: Option<f64>) -> Result<Option<u64>, String> {
    match at_ms {
        None => Ok(None),
        Some(ms) if ms.is_finite() && (0.0..=crate::model::units::MAX_PHASE_START_MS).contains(&ms) => Ok(Some(crate::model::units::ms_to_ns(ms))),
        Some(ms) => Err(format!("--at must be a time from 0 to one year after the run's first frame, got {ms} ms")),
    }
}

/// Refuses stages the real-time link does not apply.
fn check_real_time(t: &Timeline, kinds: &[crate::model::ModelKind]) -> Result<(), String> {
    match t.phases().iter().flat_map(|p| p.stages()).map(|s| s.kind()).find(|k| kinds.contains(k)) {
        Some(kind) => Err(format!(
            "scenario `{}`: the `{}` stage is simulated by `netfi scenario check` but this run's link cannot apply it",
            t.name(),
            kind.name()
        )),
        None => Ok(()),
    }
}

/// The answer to a request the transport refused before reading it (too
/// large): an error, and nothing changes.
fn refuse(e: &crate::transport::ipc::control::RequestError) -> Vec<u8> {
    let resp = Response { ok: false, message: format!("bad request: {e}"), state: None };
    serde_json::to_vec(&resp).expect("a response always serializes")
}
