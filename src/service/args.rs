//! Command-line arguments of the services, shared by `netfi <service>` and
//! the stand-alone `netfi-console`, `netfi-emulator`, `netfi-simulator`.
//! Each service's arguments also render themselves as the argv `netfi run`
//! starts the service with ([`ConsoleArgs::to_argv`], …), so a flag is
//! named in one file.

use crate::transport::udp::{UdpOptions, DEFAULT_UDP_BUFFER_BYTES};
use crate::transport::{Endpoint, Payload, Wiring};
use anyhow::bail;
use clap::Args;
use std::fmt::Display;
use std::net::SocketAddr;
use std::path::PathBuf;

/// The frame rates a run accepts, Hz: 0.001 Hz to 10 MHz.
pub const RATE_HZ_RANGE: std::ops::RangeInclusive<f64> = 0.001..=10e6;

/// Parses `--rate-hz`: a finite rate in [`RATE_HZ_RANGE`].
pub fn parse_rate_hz(text: &str) -> Result<f64, String> {
    let r: f64 = text.trim().parse().map_err(|_| format!("--rate-hz takes a number of Hz, got `{text}`"))?;
    if r.is_finite() && RATE_HZ_RANGE.contains(&r) {
        Ok(r)
    } else {
        Err(format!("--rate-hz must be between 0.001 Hz and 10 MHz (10000000 Hz), got {r}"))
    }
}

/// Parses a time flag named `_s`: seconds, or a number with its unit
/// (`250ms`, `10s`, `2min`).
pub fn seconds(text: &str) -> Result<f64, String> {
    crate::model::parse_duration(text, crate::model::TimeUnit::S)
}

/// Parses a time flag named `_ms`: milliseconds, or a number with its unit
/// (`500us`, `250ms`, `2s`).
pub fn millis(text: &str) -> Result<f64, String> {
    crate::model::parse_duration(text, crate::model::TimeUnit::Ms)
}

/// An argv under construction: flags with values, and switches.
#[derive(Debug, Default)]
struct Argv(Vec<String>);

impl Argv {
    fn val(mut self, flag: &str, v: impl Display) -> Self {
        self.0.extend([flag.to_string(), v.to_string()]);
        self
    }

    fn opt(self, flag: &str, v: Option<impl Display>) -> Self {
        match v {
            Some(v) => self.val(flag, v),
            None => self,
        }
    }

    fn switch(mut self, flag: &str, on: bool) -> Self {
        if on {
            self.0.push(flag.to_string());
        }
        self
    }
}

#[derive(Debug, Clone, Args)]
pub struct ConsoleArgs {
    /// Run id shared by the three processes (letters, digits, '-', '_').
    #[arg(long)]
    pub run_id: String,
    /// Frame rate in Hz (synthetic motion, or a capture replayed at a fixed rate).
    #[arg(long, value_parser = parse_rate_hz)]
    pub rate_hz: Option<f64>,
    /// Frames to send (default: --duration-s worth).
    #[arg(long, conflicts_with = "duration_s")]
    pub frames: Option<u64>,
    /// Seconds to stream, or a duration with its unit (`250ms`, `2min`);
    /// default 10 s; with --capture, the whole capture.
    #[arg(long, visible_alias = "duration", value_parser = seconds)]
    pub duration_s: Option<f64>,
    /// Replay a recorded capture (LZ4 ITP records) instead of synthetic motion;
    /// original timing unless --rate-hz is given.
    #[arg(long)]
    pub capture: Option<PathBuf>,
    /// Seed of the synthetic motion (default: random, printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Core to pin the console to.
    #[arg(long)]
    pub core: Option<usize>,
    /// Run on any core but this one (the emulator's), when not pinned.
    #[arg(long, conflicts_with = "core")]
    pub avoid_core: Option<usize>,
    /// Directory for `console.json`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Do not also send each frame directly to the simulator (the baseline hop).
    #[arg(long)]
    pub no_direct: bool,
    /// Seconds to wait for the emulator to subscribe before streaming.
    #[arg(long, default_value_t = 10.0, value_parser = seconds)]
    pub wait_for_peer_s: f64,
    /// Seconds to wait, after the last frame, for the end of the robot's
    /// feedback (while an emulator publishes it).
    #[arg(long, default_value_t = 5.0, value_parser = seconds)]
    pub feedback_wait_s: f64,
    /// Print the round trip and the robot's divergence once a second.
    #[arg(long)]
    pub live: bool,
    /// Sleep this many microseconds between polls instead of yielding the
    /// core (many consoles sharing few cores, `netfi run --streams`).
    #[arg(long, value_name = "US")]
    pub nap_us: Option<u64>,
    #[command(flatten)]
    pub video: crate::service::video::VideoArgs,
}

#[derive(Debug, Clone, Args)]
#[command(
    mut_arg("streams", |a| a.help(EMULATOR_STREAMS_HELP[0])),
    mut_arg("stream_scenario", |a| a.help(EMULATOR_STREAMS_HELP[1]))
)]
pub struct EmulatorArgs {
    /// Run id shared with the console and simulator (needed when either side
    /// is iceoryx2).
    #[arg(long)]
    pub run_id: Option<String>,
    /// A scenario file or preset name.
    #[arg(long)]
    pub scenario: String,
    /// Seed (default: the scenario file's, else random; printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Release-queue capacity in frames (default: the file's, else 65536).
    #[arg(long)]
    pub queue_capacity: Option<usize>,
    /// Core to pin the emulator's loop to (default: the last core).
    #[arg(long)]
    pub core: Option<usize>,
    /// Do not pin the emulator at all.
    #[arg(long, conflicts_with = "core")]
    pub no_pin: bool,
    /// Run the emulator's loop at this SCHED_FIFO priority (1–99; needs root
    /// or CAP_SYS_NICE), so no ordinary process on its core preempts it.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: Option<i32>,
    /// Clear the emulator's core for the run: move other processes'
    /// threads, movable kernel threads and device interrupts off it, and
    /// put them back at the end (root or CAP_SYS_NICE for others' threads).
    #[arg(long)]
    pub isolate: bool,
    /// Drop frames with a wrong ITP checksum (default: count and pass them).
    #[arg(long)]
    pub drop_bad_checksum: bool,
    /// Frames expected (sizes the trace table and the loss interval's batches).
    #[arg(long, default_value_t = 100_000)]
    pub expected_frames: u64,
    /// Directory for the trace, histograms and `emulator.json`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Where frames come from: `iceoryx2` (the console's port) or
    /// `udp://ADDR:PORT` (a socket bound there; `udp://:PORT` binds loopback).
    #[arg(long, default_value = "iceoryx2", value_name = "ENDPOINT")]
    pub ingress: Endpoint,
    /// Where survivors go: `iceoryx2` (the simulator's port) or
    /// `udp://ADDR:PORT` (the robot's address).
    #[arg(long, default_value = "iceoryx2", value_name = "ENDPOINT")]
    pub egress: Endpoint,
    /// What a UDP datagram carries: one ITP frame (validated), or any bytes
    /// up to 64 KiB (UDP on both sides).
    #[arg(long, value_enum, default_value_t = Payload::Itp)]
    pub payload: Payload,
    /// Local address the UDP egress sends from (default: an ephemeral port,
    /// on loopback when the robot is on loopback).
    #[arg(long, value_name = "ADDR:PORT")]
    pub egress_bind: Option<SocketAddr>,
    /// The console's address: a UDP ingress takes datagrams from it only
    /// (default: the first sender, then locked). Others are counted and
    /// dropped as `foreign_sender`.
    #[arg(long, value_name = "ADDR:PORT")]
    pub console_from: Option<SocketAddr>,
    /// Pass datagrams coming back from the robot side through this scenario
    /// (file or preset) instead of relaying them untouched.
    #[arg(long, value_name = "SCENARIO")]
    pub return_scenario: Option<String>,
    /// Seed of the return path's scenario (default: the file's, else derived
    /// from --seed; printed).
    #[arg(long)]
    pub return_seed: Option<u64>,
    /// Send return datagrams here instead of to the console's
    /// address (`udp://ADDR:PORT`).
    #[arg(long, value_name = "ENDPOINT")]
    pub return_to: Option<Endpoint>,
    /// Do not relay datagrams from the robot side at all.
    #[arg(long)]
    pub no_return: bool,
    /// With a UDP ingress: end the run as if the console had ended, once no
    /// datagram has arrived for this many milliseconds (default: run until
    /// SIGINT/SIGTERM).
    #[arg(long, value_name = "MS", value_parser = millis)]
    pub idle_end_ms: Option<f64>,
    /// Requested kernel receive/send buffer of each UDP socket, bytes.
    #[arg(long, default_value_t = DEFAULT_UDP_BUFFER_BYTES)]
    pub udp_buffer_bytes: usize,
    /// Open the egress first and wait up to this many seconds for a robot
    /// to subscribe to it before opening the ingress, so no frame is
    /// released into nothing (a stand-alone emulator for foreign clients).
    #[arg(long, value_name = "S", value_parser = seconds)]
    pub wait_for_peer_s: Option<f64>,
    /// With iceoryx2 on both sides: do not open the feedback loop
    /// (`feedback` → `feedback_out`).
    #[arg(long)]
    pub no_feedback: bool,
    #[command(flatten)]
    pub control: ControlArgs,
    #[command(flatten)]
    pub stream: StreamArgs,
    #[command(flatten)]
    pub video: crate::service::video::VideoArgs,
    #[command(flatten)]
    pub ros2: crate::service::emulator::ros2::Ros2Args,
}

/// How many console → robot streams the one emulator serves, and their
/// scenarios: the same two flags for `netfi run` and `netfi emulator`
/// (whose help says what they mean to it, [`EMULATOR_STREAMS_HELP`]).
#[derive(Debug, Clone, PartialEq, Eq, Args)]
pub struct StreamArgs {
    /// Console → robot pairs through the one emulator (1 to 64), each with
    /// its own services, scenario, seed, accounting and files
    /// (`<out>/stream-K/` when more than one).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=crate::service::plan::MAX_STREAMS as i64))]
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

    fn argv(&self, a: Argv) -> Argv {
        let a = a.opt("--streams", (self.streams > 1).then_some(self.streams));
        self.stream_scenario.iter().fold(a, |a, k| a.val("--stream-scenario", k))
    }
}

/// `netfi emulator`'s help of `--streams` and `--stream-scenario`.
pub const EMULATOR_STREAMS_HELP: [&str; 2] = [
    "Serve this many console → robot streams in one loop (iceoryx2 on both sides): stream K's services are those of run `<run-id>-s<K>` (stream 0: the run's own), its files go to `<out>/stream-K/`",
    "Stream K's scenario (file or preset), as `K=SCENARIO`; repeatable. Streams not named take --scenario",
];

/// The emulator's live control and telemetry (`netfi ctl`), as `netfi
/// emulator` and `netfi run` take them.
#[derive(Debug, Clone, Args)]
pub struct ControlArgs {
    /// Publish telemetry (counts, loss, delay and lateness percentiles)
    /// every this many milliseconds on the run's telemetry service; 0: none.
    #[arg(long, default_value_t = crate::service::telemetry::DEFAULT_INTERVAL_MS, value_name = "MS")]
    pub telemetry_ms: u64,
    /// Hold frames in the reordering release queue even if the scenario
    /// cannot reorder, so that `netfi ctl switch` may switch the run to one
    /// that does.
    #[arg(long)]
    pub reorder_queue: bool,
    /// Serve no control and no telemetry service (`netfi ctl` cannot reach
    /// the run).
    #[arg(long)]
    pub no_control: bool,
}

impl ControlArgs {
    fn argv(&self, a: Argv) -> Argv {
        a.val("--telemetry-ms", self.telemetry_ms).switch("--reorder-queue", self.reorder_queue).switch("--no-control", self.no_control)
    }
}

#[derive(Debug, Clone, Args)]
pub struct SimulatorArgs {
    #[arg(long)]
    pub run_id: String,
    /// Core to pin the simulator to.
    #[arg(long)]
    pub core: Option<usize>,
    /// Run on any core but this one (the emulator's), when not pinned.
    #[arg(long, conflicts_with = "core")]
    pub avoid_core: Option<usize>,
    /// A gap between received frames longer than this is a stall.
    #[arg(long, default_value_t = 10.0, value_parser = millis)]
    pub stall_ms: f64,
    /// Ignore frames with a wrong ITP checksum (default: count and apply them).
    #[arg(long)]
    pub drop_bad_checksum: bool,
    /// Busy-poll without yielding (only on a core of its own).
    #[arg(long)]
    pub spin: bool,
    /// Directory for `received.csv`, `end_to_end.hlog` and `simulator.json`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Sleep this many microseconds between idle polls instead of yielding
    /// the core (many robots sharing few cores, `netfi run --streams`).
    #[arg(long, value_name = "US")]
    pub nap_us: Option<u64>,
    #[command(flatten)]
    pub video: crate::service::video::VideoArgs,
}

#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// A scenario file (TOML) or a preset name (Normal, PLM-1..3, DLM-1..3, CLM-1..3, their calibrated -cal variants; see `netfi scenario list`).
    pub scenario: String,
    /// Seconds to stream, or a duration with its unit (`250ms`, `2min`);
    /// default 10 s; with --capture, the whole capture.
    #[arg(long, visible_alias = "duration", value_parser = seconds)]
    pub duration_s: Option<f64>,
    /// Frames to stream instead of a duration.
    #[arg(long, conflicts_with = "duration_s")]
    pub frames: Option<u64>,
    /// Frame rate in Hz, 0.001 to 10e6 (default 1000; with --capture, replays at this fixed rate).
    #[arg(long, value_parser = parse_rate_hz)]
    pub rate_hz: Option<f64>,
    /// Seed of the scenario and the synthetic motion (default: random, printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Replay a recorded capture instead of synthetic motion.
    #[arg(long)]
    pub capture: Option<PathBuf>,
    /// Core for the emulator (default: the last core).
    #[arg(long)]
    pub emulator_core: Option<usize>,
    /// Run the emulator at this SCHED_FIFO priority (1–99; needs root or
    /// CAP_SYS_NICE): ordinary processes on its core cannot preempt it.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: Option<i32>,
    /// Clear the emulator's core for the run (the default): move other
    /// processes' threads, movable kernel threads (e.g. a VM's memory
    /// monitor) and device interrupts off it, and put them back at the end
    /// (root or CAP_SYS_NICE for other users' threads).
    #[arg(long, overrides_with = "no_isolate")]
    pub isolate: bool,
    /// Leave the emulator's core as it is: other threads may then preempt
    /// the emulator's loop.
    #[arg(long)]
    pub no_isolate: bool,
    /// Core for the console (default: not pinned).
    #[arg(long)]
    pub console_core: Option<usize>,
    /// Core for the simulator (default: not pinned).
    #[arg(long)]
    pub simulator_core: Option<usize>,
    /// Release-queue capacity in frames.
    #[arg(long)]
    pub queue_capacity: Option<usize>,
    /// Drop frames with a wrong ITP checksum in the emulator and simulator.
    #[arg(long)]
    pub drop_bad_checksum: bool,
    /// Output directory (default: out/<run-id>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write the report as JSON here (always written to <out>/report.json).
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    /// Run id (default: generated).
    #[arg(long)]
    pub run_id: Option<String>,
    /// Print the JSON report instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Pass the robot's feedback back to the console through this scenario
    /// (file or preset; default Normal: nothing injected).
    #[arg(long, value_name = "SCENARIO")]
    pub return_scenario: Option<String>,
    /// Seed of the return scenario (default: derived from the run's seed).
    #[arg(long)]
    pub return_seed: Option<u64>,
    /// Do not send the direct (baseline) copy of each frame to the simulator:
    /// halves the console's and simulator's work at very high rates, at the
    /// price of the in-run baseline and the console-side kinematics.
    #[arg(long)]
    pub no_direct: bool,
    #[command(flatten)]
    pub control: ControlArgs,
    #[command(flatten)]
    pub stream: StreamArgs,
    #[command(flatten)]
    pub video: crate::service::video::VideoArgs,
}

impl ConsoleArgs {
    /// The argv that starts a console with these arguments.
    pub fn to_argv(&self) -> Vec<String> {
        let a = Argv::default().val("--run-id", &self.run_id).val("--out", self.out.display()).opt("--seed", self.seed);
        a.opt("--rate-hz", self.rate_hz)
            .opt("--frames", self.frames)
            .opt("--duration-s", self.duration_s)
            .opt("--capture", self.capture.as_ref().map(|c| c.display()))
            .switch("--no-direct", self.no_direct)
            .opt("--core", self.core)
            .opt("--avoid-core", self.avoid_core)
            .val("--wait-for-peer-s", self.wait_for_peer_s)
            .val("--feedback-wait-s", self.feedback_wait_s)
            .switch("--live", self.live)
            .opt("--nap-us", self.nap_us)
            .0
            .into_iter()
            .chain(self.video.argv())
            .collect()
    }
}

impl EmulatorArgs {
    /// The argv that starts an emulator with these arguments (iceoryx2 on
    /// both sides: what `netfi run` starts).
    pub fn to_argv(&self) -> Vec<String> {
        let a = Argv::default().opt("--run-id", self.run_id.as_ref()).val("--scenario", &self.scenario).opt("--seed", self.seed);
        let a = a.val("--out", self.out.display()).val("--expected-frames", self.expected_frames);
        let a = a
            .opt("--core", self.core)
            .switch("--no-pin", self.no_pin)
            .opt("--queue-capacity", self.queue_capacity)
            .opt("--rt-priority", self.rt_priority)
            .switch("--isolate", self.isolate)
            .switch("--drop-bad-checksum", self.drop_bad_checksum)
            .opt("--return-scenario", self.return_scenario.as_ref())
            .opt("--return-seed", self.return_seed)
            .opt("--wait-for-peer-s", self.wait_for_peer_s)
            .switch("--no-feedback", self.no_feedback);
        let a = self.stream.argv(self.control.argv(a));
        a.0.into_iter().chain(self.video.argv()).collect()
    }

    /// Checks that the options fit the endpoints, with errors that say what
    /// would be accepted.
    pub fn validate(&self) -> anyhow::Result<()> {
        let (i, e) = (self.ingress.is_udp(), self.egress.is_udp());
        if self.stream.several() && (i || e) {
            bail!("--streams and --stream-scenario need iceoryx2 on both sides");
        }
        self.video.validate()?;
        if self.video.on() && (i || e) {
            bail!("--video-mbps needs iceoryx2 on both sides: the video channels are iceoryx2's");
        }
        if self.video.on() && self.stream.streams > 1 {
            bail!("--video-mbps goes with one stream: the video path is stream 0's, and --streams {} asks for more", self.stream.streams);
        }
        if let Some(s) = self.wait_for_peer_s {
            if !(s.is_finite() && s >= 0.0) {
                bail!("--wait-for-peer-s must be a non-negative number of seconds, got {s}");
            }
            if e {
                bail!("--wait-for-peer-s waits for a robot on the iceoryx2 egress; a UDP robot does not subscribe");
            }
        }
        if !(i || e) {
            if self.run_id.is_none() {
                bail!("--run-id is required with the iceoryx2 ingress and egress");
            }
            if self.return_to.is_some() || self.no_return {
                bail!("--return-to and --no-return apply to the UDP return path; with iceoryx2 on both sides the feedback goes to the console's `feedback_out` (--no-feedback turns it off)");
            }
            if self.no_feedback && (self.return_scenario.is_some() || self.return_seed.is_some()) {
                bail!("--no-feedback cannot be combined with --return-scenario or --return-seed");
            }
            return Ok(());
        }
        if self.no_feedback {
            bail!("--no-feedback applies to the iceoryx2 feedback loop (iceoryx2 on both sides)");
        }
        if self.payload == Payload::Raw && !(i && e) {
            bail!("--payload raw needs UDP on both sides (--ingress udp://… --egress udp://…): an iceoryx2 port carries ITP frames only");
        }
        let return_opts = self.return_scenario.is_some() || self.return_to.is_some() || self.return_seed.is_some();
        if return_opts && !(i && e) {
            bail!("--return-scenario, --return-to and --return-seed apply to the return path, which needs UDP on both sides (or iceoryx2 on both, for the feedback loop)");
        }
        if self.no_return && return_opts {
            bail!("--no-return cannot be combined with --return-scenario, --return-to or --return-seed");
        }
        if self.idle_end_ms.is_some() && !i {
            bail!("--idle-end-ms applies to a UDP ingress; an iceoryx2 console ends its stream itself");
        }
        if let Some(ms) = self.idle_end_ms {
            if !(ms.is_finite() && ms > 0.0) {
                bail!("--idle-end-ms must be a positive number of milliseconds, got {ms}");
            }
        }
        if self.egress_bind.is_some() && !e {
            bail!("--egress-bind applies to a UDP egress");
        }
        if self.console_from.is_some() && !i {
            bail!("--console-from applies to a UDP ingress");
        }
        if let Some(a) = self.egress.udp() {
            if a.port() == 0 || a.ip().is_unspecified() {
                bail!("--egress {}: the robot's address needs a specific address and a port other than 0", self.egress);
            }
        }
        if !(i && e) && self.run_id.is_none() {
            bail!("--run-id is needed for the iceoryx2 side (ingress {}, egress {})", self.ingress, self.egress);
        }
        Ok(())
    }

    /// How to open the transports, for a release queue of `queue_capacity`.
    pub fn wiring(&self, queue_capacity: usize) -> Wiring {
        Wiring {
            run_id: self.run_id.clone(),
            payload: self.payload,
            udp: UdpOptions { reuse_address: true, buffer_bytes: Some(self.udp_buffer_bytes) },
            egress_bind: self.egress_bind,
            console_from: self.console_from,
            queue_capacity,
            idle_end_ns: self.idle_end_ms.map(|ms| (ms * 1e6) as u64),
            wait_for_peer_ns: self.wait_for_peer_s.map(|s| (s * 1e9) as u64),
        }
    }
}

impl SimulatorArgs {
    /// The argv that starts a simulator with these arguments.
    pub fn to_argv(&self) -> Vec<String> {
        Argv::default()
            .val("--run-id", &self.run_id)
            .val("--out", self.out.display())
            .opt("--core", self.core)
            .switch("--spin", self.spin)
            .opt("--avoid-core", self.avoid_core)
            .switch("--drop-bad-checksum", self.drop_bad_checksum)
            .val("--stall-ms", self.stall_ms)
            .opt("--nap-us", self.nap_us)
            .0
            .into_iter()
            .chain(self.video.argv())
            .collect()
    }
}

impl RunArgs {
    /// Whether the emulator's core is to be cleared: the default, and what
    /// `--isolate` restates; `--no-isolate` turns it off (the later of the
    /// two wins).
    pub fn clears_core(&self) -> bool {
        self.isolate || !self.no_isolate
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{CommandFactory, Parser};

    #[derive(Parser)]
    struct Cli {
        #[command(subcommand)]
        cmd: Cmd,
    }

    #[derive(clap::Subcommand)]
    enum Cmd {
        Run(RunArgs),
        Emulator(EmulatorArgs),
    }

    #[test]
    fn the_run_and_the_emulator_take_the_same_stream_flags_each_with_its_help() {
        let want = StreamArgs { streams: 3, stream_scenario: vec!["1=PLM-1".into()] };
        let flags = ["--streams", "3", "--stream-scenario", "1=PLM-1"];
        let Cmd::Run(r) = Cli::parse_from([&["netfi", "run", "Normal"][..], &flags].concat()).cmd else { unreachable!() };
        assert_eq!(r.stream, want);
        let Cmd::Emulator(e) = Cli::parse_from([&["netfi", "emulator", "--scenario", "Normal"][..], &flags].concat()).cmd else { unreachable!() };
        assert_eq!(e.stream, want);
        // What `netfi run` starts the emulator with says the same.
        assert!(e.to_argv().windows(4).any(|w| w == flags), "{:?}", e.to_argv());
        let Cmd::Run(one) = Cli::parse_from(["netfi", "run", "Normal"]).cmd else { unreachable!() };
        assert_eq!(one.stream, StreamArgs::default());
        let cmd = Cli::command();
        let help = |sub: &str, arg: &str| {
            let sub = cmd.find_subcommand(sub).unwrap();
            sub.get_arguments().find(|a| a.get_id() == arg).and_then(|a| a.get_help()).map(|h| h.to_string()).unwrap()
        };
        assert_eq!(help("emulator", "streams"), EMULATOR_STREAMS_HELP[0]);
        assert_eq!(help("emulator", "stream_scenario"), EMULATOR_STREAMS_HELP[1]);
        assert!(help("run", "streams").starts_with("Console → robot pairs through the one emulator (1 to 64)"));
        assert!(help("run", "stream_scenario").ends_with("Streams not named take the run's scenario"));
    }
}
