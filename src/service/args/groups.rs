//! The groups of flags that more than one command takes, each declared
//! once and flattened into every command that takes it; each renders its
//! own flags ([`Render`]). Where a flag means something slightly different
//! to one command, that command says so with clap's `mut_arg` (see
//! [`super::help`]).

use super::argv::{Argv, Render};
use super::error::ArgsError;
use super::values::{self, DEFAULT_RATE_HZ, MAX_RUN_S};
use clap::Args;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// The scenario, its seed and the release queue: `netfi run` (the
/// scenario positional) and `netfi emulator` (`--scenario`).
#[derive(Debug, Clone, PartialEq, Eq, Args)]
pub struct ScenarioArgs {
    /// A scenario file (TOML) or a preset name (Normal, PLM-1..3, DLM-1..3, CLM-1..3, their calibrated -cal variants; see `netfi scenario list`).
    pub scenario: String,
    /// Seed of the scenario's random streams (default: the scenario file's,
    /// else random; printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Release-queue capacity in frames, 1 to 2^24 (default: the scenario
    /// file's, else 65536).
    #[arg(long, value_parser = values::queue_capacity())]
    pub queue_capacity: Option<usize>,
}

impl ScenarioArgs {
    /// The scenario `scenario`, its seed and queue left to the file or the default.
    pub fn named(scenario: impl Into<String>) -> ScenarioArgs {
        ScenarioArgs { scenario: scenario.into(), seed: None, queue_capacity: None }
    }
}

impl Render for ScenarioArgs {
    fn render(&self, a: &mut Argv) {
        a.val("--scenario", &self.scenario).opt("--seed", self.seed).opt("--queue-capacity", self.queue_capacity);
    }
}

/// Where the frames come from and how many: `netfi run` and `netfi console`.
#[derive(Debug, Clone, Default, PartialEq, Args)]
pub struct SourceArgs {
    /// Frame rate in Hz, 0.001 to 1e6 (default 1000; with --capture, the
    /// capture is replayed at this fixed rate instead of its own timing).
    #[arg(long, value_parser = values::parse_rate_hz)]
    pub rate_hz: Option<f64>,
    /// Frames to stream instead of a duration, 1 to 10^13.
    #[arg(long, conflicts_with = "duration_s", value_parser = values::frames())]
    pub frames: Option<u64>,
    /// Seconds to stream, or a duration with its unit (`250ms`, `2min`), at
    /// most a week; default 10 s; with --capture, the whole capture.
    #[arg(long, visible_alias = "duration", value_parser = values::run_seconds)]
    pub duration_s: Option<f64>,
    /// Replay a recorded capture (LZ4 ITP records) instead of synthetic motion.
    #[arg(long)]
    pub capture: Option<PathBuf>,
    /// The most records of --capture read, 1 to 2^32 (default 4194304, 2^22:
    /// 70 min at 1 kHz, about 600 MB in memory); a capture with more is
    /// refused before more of it is read.
    #[arg(long, value_name = "RECORDS", value_parser = values::capture_max_records())]
    pub capture_max_records: Option<u64>,
}

impl SourceArgs {
    /// How long the stream is planned to last (s), and the frames expected;
    /// a stream longer than a run may last is an error.
    pub fn planned(&self) -> Result<(f64, u64), ArgsError> {
        if self.capture_max_records.is_some() && self.capture.is_none() {
            return Err(ArgsError::CaptureLimitAlone);
        }
        let rate_hz = self.rate_hz.unwrap_or(DEFAULT_RATE_HZ);
        let planned = match (&self.capture, self.frames, self.duration_s) {
            (_, Some(n), _) => (n as f64 / rate_hz, n),
            (_, None, Some(d)) => (d, (d * rate_hz).ceil() as u64),
            (Some(_), None, None) if self.rate_hz.is_none() => (90.0, 50_000),
            (Some(_), None, None) => (60.0, (60.0 * rate_hz) as u64),
            (None, None, None) => (10.0, (10.0 * rate_hz) as u64),
        };
        if planned.0 > MAX_RUN_S {
            let seconds = crate::model::units::show(planned.0);
            return Err(ArgsError::TooLong { frames: planned.1, rate_hz, seconds, max_s: MAX_RUN_S });
        }
        Ok(planned)
    }
}

impl Render for SourceArgs {
    fn render(&self, a: &mut Argv) {
        a.opt("--rate-hz", self.rate_hz)
            .opt("--frames", self.frames)
            .opt("--duration-s", self.duration_s)
            .opt("--capture", self.capture.as_ref().map(|c| c.display()))
            .opt("--capture-max-records", self.capture_max_records);
    }
}

/// Where a console or a robot runs.
#[derive(Debug, Clone, Default, PartialEq, Eq, Args)]
pub struct PinArgs {
    /// Core to pin this process to.
    #[arg(long, value_parser = values::core())]
    pub core: Option<usize>,
    /// Run on any core but this one (the emulator's), when not pinned.
    #[arg(long, conflicts_with = "core", value_parser = values::core())]
    pub avoid_core: Option<usize>,
}

impl Render for PinArgs {
    fn render(&self, a: &mut Argv) {
        a.opt("--core", self.core).opt("--avoid-core", self.avoid_core);
    }
}

/// Where the emulator's loop runs: `netfi emulator`, and `netfi run`
/// (where `--core` is `--emulator-core`, and the core is cleared unless
/// `--no-isolate`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Args)]
pub struct EmulatorPlacement {
    /// Core to pin the emulator's loop to (default: the last core).
    #[arg(long, value_parser = values::core())]
    pub core: Option<usize>,
    /// Do not pin the emulator at all.
    #[arg(long, conflicts_with = "core")]
    pub no_pin: bool,
    /// Run the emulator's loop at this SCHED_FIFO priority (1–99; needs root
    /// or CAP_SYS_NICE), so no ordinary process on its core preempts it.
    #[arg(long, value_parser = values::rt_priority())]
    pub rt_priority: Option<i32>,
    /// Clear the emulator's core for the run: move other processes'
    /// threads, movable kernel threads and device interrupts off it, and
    /// put them back at the end (root or CAP_SYS_NICE for others' threads).
    #[arg(long)]
    pub isolate: bool,
}

impl Render for EmulatorPlacement {
    fn render(&self, a: &mut Argv) {
        a.opt("--core", self.core).switch("--no-pin", self.no_pin).opt("--rt-priority", self.rt_priority).switch("--isolate", self.isolate);
    }
}

/// The emulator's live control and telemetry (`netfi ctl`), as `netfi
/// emulator` and `netfi run` take them.
#[derive(Debug, Clone, PartialEq, Eq, Args)]
pub struct ControlArgs {
    /// Publish telemetry (counts, loss, delay and lateness percentiles)
    /// every this many milliseconds on the run's telemetry service, up to
    /// an hour (3600000); 0: none.
    #[arg(long, default_value_t = crate::service::telemetry::DEFAULT_INTERVAL_MS, value_name = "MS", value_parser = values::telemetry_ms())]
    pub telemetry_ms: u64,
    /// Hold frames in the reordering release queue even if the scenario
    /// cannot reorder. A run under live control (a run id, no
    /// `--no-control`) always does, so that `netfi ctl switch` may switch
    /// it to any scenario.
    #[arg(long)]
    pub reorder_queue: bool,
    /// Keep the FIFO release ring for a scenario that cannot reorder, even
    /// under live control (a switch to a scenario that reorders is then
    /// refused).
    #[arg(long, conflicts_with = "reorder_queue")]
    pub fifo_queue: bool,
    /// Serve no control and no telemetry service (`netfi ctl` cannot reach
    /// the run).
    #[arg(long)]
    pub no_control: bool,
}

impl Default for ControlArgs {
    /// Control served, telemetry at its default interval.
    fn default() -> Self {
        ControlArgs { telemetry_ms: crate::service::telemetry::DEFAULT_INTERVAL_MS, reorder_queue: false, fifo_queue: false, no_control: false }
    }
}

impl Render for ControlArgs {
    fn render(&self, a: &mut Argv) {
        a.unless_default("--telemetry-ms", self.telemetry_ms, ControlArgs::default().telemetry_ms)
            .switch("--reorder-queue", self.reorder_queue)
            .switch("--fifo-queue", self.fifo_queue)
            .switch("--no-control", self.no_control);
    }
}

/// How many console → robot streams the one emulator serves, and their
/// scenarios: the same two flags for `netfi run` and `netfi emulator`
/// (whose help says what they mean to it, [`super::help::EMULATOR_STREAMS`]).
#[derive(Debug, Clone, PartialEq, Eq, Args)]
pub struct StreamArgs {
    /// Console → robot pairs through the one emulator (1 to 64), each with
    /// its own services, scenario, seed, accounting and files
    /// (`<out>/stream-K/` when more than one).
    #[arg(long, default_value_t = 1, value_parser = values::streams())]
    pub streams: u32,
    /// Stream K's scenario (file or preset), as `K=SCENARIO`; repeatable.
    /// Streams not named take the run's scenario.
    #[arg(long, value_name = "K=SCENARIO")]
    pub stream_scenario: Vec<String>,
}

impl Default for StreamArgs {
    /// One stream, its scenario the run's.
    fn default() -> Self {
        StreamArgs { streams: 1, stream_scenario: Vec::new() }
    }
}

impl StreamArgs {
    /// Whether more than one stream, or any stream's own scenario, is asked for.
    pub fn several(&self) -> bool {
        self.streams > 1 || !self.stream_scenario.is_empty()
    }

    /// The scenario each stream named by `--stream-scenario` is given.
    pub fn named_scenarios(&self) -> Result<BTreeMap<usize, String>, ArgsError> {
        self.stream_scenario.iter().map(|text| parse_stream_scenario(text, self.streams)).collect()
    }
}

/// `K=SCENARIO` (`--stream-scenario`): the stream and its scenario.
pub fn parse_stream_scenario(text: &str, streams: u32) -> Result<(usize, String), ArgsError> {
    let bad = |why: String| ArgsError::StreamScenario { text: text.to_string(), why };
    let (k, what) = text.split_once('=').ok_or_else(|| bad("expected K=SCENARIO".into()))?;
    let k: u32 = k.trim().parse().map_err(|_| bad("K must be a stream number".into()))?;
    if k >= streams {
        return Err(bad(format!("stream {k} does not exist (streams 0 to {})", streams - 1)));
    }
    if what.is_empty() {
        return Err(bad("no scenario".into()));
    }
    Ok((k as usize, what.to_string()))
}

impl Render for StreamArgs {
    fn render(&self, a: &mut Argv) {
        a.opt("--streams", (self.streams > 1).then_some(self.streams));
        for k in &self.stream_scenario {
            a.val("--stream-scenario", k);
        }
    }
}

/// The emulator's two sides, of any transport (`netfi emulator`), and when
/// a stream with no end marker of its own ends.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct EndsArgs {
    /// Where frames come from: `iceoryx2` (the console's port) or
    /// `udp://ADDR:PORT` (a socket bound there; `udp://:PORT` binds loopback).
    #[arg(long, default_value = "iceoryx2", value_name = "ENDPOINT")]
    pub ingress: crate::transport::Endpoint,
    /// Where survivors go: `iceoryx2` (the simulator's port) or
    /// `udp://ADDR:PORT` (the robot's address).
    #[arg(long, default_value = "iceoryx2", value_name = "ENDPOINT")]
    pub egress: crate::transport::Endpoint,
    /// With a UDP ingress or ROS 2 topics (whose streams have no end marker):
    /// end the run as if the console had ended, once no frame has arrived for
    /// this many milliseconds, at most a week (default: run until
    /// SIGINT/SIGTERM, or, on ROS 2, until the publishers are gone).
    #[arg(long, value_name = "MS", value_parser = values::idle_end_millis)]
    pub idle_end_ms: Option<f64>,
}

impl Default for EndsArgs {
    /// iceoryx2 on both sides.
    fn default() -> Self {
        let iceoryx2: crate::transport::Endpoint = "iceoryx2".parse().expect("iceoryx2 is an endpoint");
        EndsArgs { ingress: iceoryx2.clone(), egress: iceoryx2, idle_end_ms: None }
    }
}

impl EndsArgs {
    /// Whether both sides are the run's own iceoryx2 ports.
    pub fn own(&self) -> bool {
        *self == EndsArgs { idle_end_ms: self.idle_end_ms, ..EndsArgs::default() }
    }
}

impl Render for EndsArgs {
    /// Only what differs from the defaults.
    fn render(&self, a: &mut Argv) {
        let d = EndsArgs::default();
        a.opt("--ingress", (self.ingress != d.ingress).then_some(&self.ingress))
            .opt("--egress", (self.egress != d.egress).then_some(&self.egress))
            .opt("--idle-end-ms", self.idle_end_ms);
    }
}
