//! Live control of a running emulator (docs/interface.md, "Live control"):
//! `netfi ctl --run-id R show | switch | phase | pause | resume | watch`.
//!
//! Two halves, joined by two wait-free single-producer rings (`rtrb`):
//!
//! - the **control thread** ([`start`]), off the loop's core, serves the
//!   run's control service: it parses and validates each request with the
//!   scenario parser (a bad one is answered with the parser's error and
//!   changes nothing), builds the new phases ([`Timeline`]) and hands them
//!   to the loop; it records what the loop applied as events (streamed to
//!   `events.jsonl` beside the trace, and returned for the report), and
//!   publishes the telemetry intervals the trace writer closes;
//! - the loop's end, [`ControlPort`], which the emulator's loop polls every
//!   4096 turns, as it looks at the stop flag: it moves the waiting
//!   commands into the injector ([`crate::injector::Injector::switch`]:
//!   no allocation, no lock) and sends back what it did, with the
//!   phases a switch cut, to be dropped on the control thread.
//!
//! So a switch takes effect between two frames, frames already queued keep
//! their release times, and the loop never parses, allocates or waits.

use crate::clock::now_ns;
use crate::scenario::{parse_str, preset, ScenarioError, ScenarioSpec, Switched, Timeline, MAX_RUN_PHASES, PRESET_NAMES};
use crate::scheduler::QueueOrder;
use crate::service::link::{Carried, Link};
use crate::transport::ipc::control::{ControlServer, TelemetryPublisher, TelemetrySample};
use crate::transport::{IpcConfig, IpcNode, Role};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

/// One control action, as the run report lists it (`events`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlEvent {
    /// When it took effect, seconds from the run's first frame (the clock of
    /// the phases and of `--at`).
    pub t_s: f64,
    /// What was done, in words.
    pub what: String,
    /// The same time in ns, exactly (absent in reports of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_ns: Option<u64>,
    /// What was done, exactly enough to rebuild the run's timeline from
    /// its scenario and its events (absent in reports of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action: Option<Action>,
}

/// A control action as the loop applied it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Action {
    /// The rest of the run's timeline replaced, from the event's time, by
    /// `scenario` (as TOML) from its phase `from_phase` on; its first
    /// phase became the run's phase `run_phase` (both from 1).
    Switch { scenario: String, from_phase: usize, run_phase: usize },
    Pause,
    Resume,
}

/// A request to the control service (JSON, tagged by `cmd`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Request {
    /// The current scenario, phase and pause.
    Show,
    /// Switch to a scenario from `at_ms` (from the run's first frame), or now.
    Switch {
        scenario: Target,
        #[serde(default)]
        at_ms: Option<f64>,
    },
    /// Go to a phase (number from 1, or name) of the current scenario.
    Phase {
        phase: String,
        #[serde(default)]
        at_ms: Option<f64>,
    },
    /// Every frame passes untouched until `resume`.
    Pause,
    Resume,
}

/// What to switch to: a preset's name, or scenario text (a file's
/// contents, or a target stage such as `[[stage]]\nloss = "30%"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Target {
    Preset(String),
    Toml { text: String, origin: String, name: String },
}

/// The answer: `ok` with a message and the state, or the error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Response {
    pub ok: bool,
    #[serde(default)]
    pub message: String,
    #[serde(default)]
    pub state: Option<State>,
}

/// What `show` prints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// Seconds since the run's first frame (0 before it).
    pub t_s: f64,
    /// Whether a frame has entered yet.
    pub started: bool,
    pub frames_entered: u64,
    pub paused: bool,
    /// The phase running, in the run's timeline (from 1).
    pub phase: usize,
    /// The scenario it comes from, and its phase there (from 1, and name).
    pub scenario: String,
    pub scenario_phase: usize,
    pub phase_name: Option<String>,
    /// The phases still to come: `(t_s, scenario, phase from 1)`.
    pub upcoming: Vec<(f64, String, usize)>,
    /// `fifo` or `reorder`: a FIFO run cannot switch to a reordering scenario.
    pub queue_order: String,
    /// The phases of the scenario running, each as `netfi ctl phase` names
    /// it (absent from older emulators' answers).
    #[serde(default)]
    pub scenario_phases: Vec<PhaseOf>,
}

/// One phase of a scenario: its number (from 1), its name, and its start
/// in the scenario (s).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseOf {
    pub number: usize,
    pub name: Option<String>,
    pub start_s: f64,
}

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

/// A command for the loop.
enum Command {
    Switch { id: u64, at_ns: Option<u64>, timeline: Timeline },
    Pause { id: u64, paused: bool },
}

/// What the loop did with a command.
enum Applied {
    Switched { id: u64, s: Switched },
    Refused { id: u64 },
    Paused { id: u64, paused: bool, t_ns: u64 },
}

/// What the loop tells the control thread at every poll.
#[derive(Default)]
struct Shared {
    /// The first frame's time + 1 (0: none yet).
    start_ns: AtomicU64,
    entered: AtomicU64,
    phase: AtomicU64,
    paused: AtomicBool,
    stop: AtomicBool,
}

/// Commands in flight at once (one per request; requests are answered one
/// at a time).
const RING: usize = 8;

/// The loop's end: polled every 4096 turns.
pub struct ControlPort {
    commands: rtrb::Consumer<Command>,
    applied: rtrb::Producer<Applied>,
    shared: Arc<Shared>,
}

impl ControlPort {
    /// Applies the commands waiting (between two frames) and publishes the
    /// loop's state. No allocation, lock or system call but the clock.
    pub fn poll<T: Carried>(&mut self, link: &mut Link<T>) {
        let inj = link.injector_mut();
        while let Ok(cmd) = self.commands.pop() {
            let now = now_ns();
            let done = match cmd {
                Command::Switch { id, at_ns, timeline } => match inj.switch(now, at_ns, timeline) {
                    Ok(s) => Applied::Switched { id, s },
                    Err(_refused) => Applied::Refused { id },
                },
                Command::Pause { id, paused } => {
                    inj.set_paused(paused);
                    Applied::Paused { id, paused, t_ns: inj.start_ns().map_or(0, |s| now.saturating_sub(s)) }
                }
            };
            // The ring holds twice the commands that can be in flight.
            let _ = self.applied.push(done);
        }
        let s = &self.shared;
        s.start_ns.store(inj.start_ns().map_or(0, |t| t + 1), Ordering::Relaxed);
        s.entered.store(inj.next_ingress_index(), Ordering::Relaxed);
        s.phase.store(inj.scenario().current_phase() as u64, Ordering::Relaxed);
        s.paused.store(inj.scenario().paused(), Ordering::Relaxed);
    }
}

/// The control thread's handle.
pub struct ControlHandle {
    shared: Arc<Shared>,
    thread: std::thread::JoinHandle<Vec<ControlEvent>>,
    telemetry: Option<mpsc::Sender<TelemetrySample>>,
}

impl ControlHandle {
    /// Keeps the control thread off `core` (the loop's); `false` where it
    /// cannot be.
    pub fn keep_off_core(&self, core: usize) -> bool {
        use std::os::unix::thread::JoinHandleExt;
        crate::host::keep_thread_off_core(self.thread.as_pthread_t(), core)
    }

    /// The telemetry aggregator to hand to the trace writer, if telemetry is on.
    pub fn aggregator(&self, interval_ns: u64) -> Option<Box<dyn crate::trace::Tap>> {
        let tx = self.telemetry.clone()?;
        Some(Box::new(crate::service::telemetry::Aggregator::new(interval_ns, tx)))
    }

    /// Stops the control thread; the events that took effect.
    pub fn finish(self) -> Vec<ControlEvent> {
        self.shared.stop.store(true, Ordering::Release);
        drop(self.telemetry);
        self.thread.join().unwrap_or_default()
    }
}

/// Starts the control thread (before the loop's core is pinned) and
/// returns the loop's end and the handle. Fails if the control or
/// telemetry service cannot be opened.
pub fn start(settings: Settings) -> anyhow::Result<(ControlPort, ControlHandle)> {
    let (cmd_tx, cmd_rx) = rtrb::RingBuffer::new(RING);
    let (app_tx, app_rx) = rtrb::RingBuffer::new(2 * RING);
    let shared = Arc::new(Shared::default());
    let (tel_tx, tel_rx) = mpsc::channel();
    let (ready_tx, ready_rx) = mpsc::channel();
    let server = Server::new(settings, cmd_tx, app_rx, shared.clone(), tel_rx);
    let thread = std::thread::Builder::new().name("netfi-control".into()).spawn(move || server.run(ready_tx))?;
    match ready_rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            let _ = thread.join();
            return Err(e);
        }
        Err(_) => anyhow::bail!("the control thread ended before opening its services"),
    }
    let port = ControlPort { commands: cmd_rx, applied: app_tx, shared: shared.clone() };
    Ok((port, ControlHandle { shared, thread, telemetry: Some(tel_tx) }))
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
struct Server {
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
    fn new(settings: Settings, commands: rtrb::Producer<Command>, applied: rtrb::Consumer<Applied>, shared: Arc<Shared>, telemetry: mpsc::Receiver<TelemetrySample>) -> Server {
        let spec = Arc::new(settings.spec.clone());
        let timeline = (0..spec.phases.len())
            .map(|i| Mirrored { start_ns: crate::model::units::ms_to_ns(spec.phases[i].start_ms), spec: spec.clone(), phase: i })
            .collect();
        Server { settings, commands, applied, shared, telemetry, timeline, events: Vec::new(), log: None, log_failed: false, next_id: 0, sent: Vec::new() }
    }

    fn run(mut self, ready: mpsc::Sender<anyhow::Result<()>>) -> Vec<ControlEvent> {
        let opened = (|| -> anyhow::Result<_> {
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

impl ControlEvent {
    /// When it took effect, ns from the run's first frame: exact where the
    /// event says, else from its seconds.
    pub fn at_ns(&self) -> u64 {
        self.t_ns.unwrap_or_else(|| (self.t_s * 1e9).round() as u64)
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

/// The scenario a request names, with the scenario parser's errors.
pub fn resolve(t: &Target) -> Result<ScenarioSpec, ScenarioError> {
    match t {
        Target::Preset(name) => preset(name).ok_or_else(|| ScenarioError {
            origin: name.clone(),
            line: None,
            location: None,
            field: None,
            problem: format!("not a preset (presets: {})", PRESET_NAMES.join(", ")),
        }),
        Target::Toml { text, origin, name } => parse_str(text, origin, name),
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

/// Headroom of phases a run reserves for switches.
pub const PHASE_ROOM: usize = MAX_RUN_PHASES;
