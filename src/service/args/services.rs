//! The arguments of the three services, each its groups and its own flags.

use super::argv::{Argv, Render};
use super::error::ArgsError;
use super::groups::{ControlArgs, EmulatorPlacement, EndsArgs, PinArgs, ScenarioArgs, SourceArgs, StreamArgs};
use super::help;
use crate::transport::ros2::Ros2Args;
use super::values;
use crate::service::channel::{ChannelArgs, ChannelEndArgs, LaneShape};
use crate::transport::{LaneFlags, TransportArgs, Wiring};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Clone, PartialEq, Args)]
pub struct ConsoleArgs {
    /// Run id shared by the three processes (letters, digits, '-', '_').
    #[arg(long)]
    pub run_id: String,
    #[command(flatten)]
    pub source: SourceArgs,
    /// Seed of the synthetic motion (default: random, printed).
    #[arg(long)]
    pub seed: Option<u64>,
    #[command(flatten)]
    pub pin: PinArgs,
    /// Directory for `console.json`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Do not also send each frame directly to the simulator (the baseline hop).
    #[arg(long)]
    pub no_direct: bool,
    /// Seconds to wait for the emulator to subscribe before streaming, at most an hour.
    #[arg(long, default_value_t = 10.0, value_parser = values::wait_seconds)]
    pub wait_for_peer_s: f64,
    /// Seconds to wait, after the last frame, for the end of the robot's
    /// feedback (while an emulator publishes it), at most an hour.
    #[arg(long, default_value_t = 5.0, value_parser = values::wait_seconds)]
    pub feedback_wait_s: f64,
    /// Print the round trip and the robot's divergence once a second.
    #[arg(long)]
    pub live: bool,
    /// Sleep this many microseconds (up to 1000000) between polls instead
    /// of yielding the core (many consoles sharing few cores, `netfi run
    /// --streams`).
    #[arg(long, value_name = "US", value_parser = values::nap_us())]
    pub nap_us: Option<u64>,
    #[command(flatten)]
    pub channels: ChannelEndArgs,
}

impl Render for ConsoleArgs {
    fn render(&self, a: &mut Argv) {
        a.val("--run-id", &self.run_id)
            .val("--out", self.out.display())
            .opt("--seed", self.seed)
            .group(&self.source)
            .switch("--no-direct", self.no_direct)
            .group(&self.pin)
            .val("--wait-for-peer-s", self.wait_for_peer_s)
            .val("--feedback-wait-s", self.feedback_wait_s)
            .switch("--live", self.live)
            .opt("--nap-us", self.nap_us)
            .group(&self.channels);
    }
}

impl ConsoleArgs {
    /// The argv that starts a console with these arguments.
    pub fn to_argv(&self) -> Vec<String> {
        super::argv::render(self)
    }
}

#[derive(Debug, Clone, PartialEq, Args)]
#[command(
    mut_arg("scenario", |a| a.long("scenario").help(help::EMULATOR_SCENARIO)),
    mut_arg("return_scenario", |a| a.help(help::EMULATOR_RETURN[0])),
    mut_arg("return_seed", |a| a.help(help::EMULATOR_RETURN[1])),
    mut_arg("streams", |a| a.help(help::EMULATOR_STREAMS[0])),
    mut_arg("stream_scenario", |a| a.help(help::EMULATOR_STREAMS[1]))
)]
pub struct EmulatorArgs {
    /// Run id shared with the console and simulator (needed when either side
    /// is iceoryx2).
    #[arg(long)]
    pub run_id: Option<String>,
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    #[command(flatten)]
    pub placement: EmulatorPlacement,
    /// Drop frames with a wrong ITP checksum (default: count and pass them).
    #[arg(long)]
    pub drop_bad_checksum: bool,
    /// Follow the motion in the ITP frames taken in (the console's) and
    /// released (towards the robot): motion per arm, clutch activations,
    /// stalls and their divergence, in `emulator.json` (`kinematics`).
    /// `netfi run` sets it when the lab plays the console or the robot.
    #[arg(long)]
    pub kinematics: bool,
    /// Frames expected, 1 to 10^13 (sizes the trace table and the loss
    /// interval's batches).
    #[arg(long, default_value_t = 100_000, value_parser = values::expected_frames())]
    pub expected_frames: u64,
    /// Directory for the trace, histograms and `emulator.json`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Open the egress first and wait up to this many seconds (at most an
    /// hour) for a robot to subscribe to it before opening the ingress, so
    /// no frame is released into nothing (a stand-alone emulator for
    /// foreign clients).
    #[arg(long, value_name = "S", value_parser = values::wait_seconds)]
    pub wait_for_peer_s: Option<f64>,
    #[command(flatten)]
    pub channels: ChannelArgs,
    #[command(flatten)]
    pub ends: EndsArgs,
    #[command(flatten)]
    pub transports: TransportArgs,
    #[command(flatten)]
    pub control: ControlArgs,
    #[command(flatten)]
    pub stream: StreamArgs,
    #[command(flatten)]
    pub ros2: Ros2Args,
}

impl Render for EmulatorArgs {
    fn render(&self, a: &mut Argv) {
        a.opt("--run-id", self.run_id.as_ref())
            .group(&self.scenario)
            .val("--out", self.out.display())
            .val("--expected-frames", self.expected_frames)
            .group(&self.placement)
            .switch("--drop-bad-checksum", self.drop_bad_checksum)
            .switch("--kinematics", self.kinematics)
            .group(&self.channels)
            .opt("--wait-for-peer-s", self.wait_for_peer_s)
            .group(&self.ends)
            .group(&self.transports)
            .group(&self.control)
            .group(&self.stream)
            .group(&self.ros2);
    }
}

impl EmulatorArgs {
    /// An emulator of `scenario` (iceoryx2 on both sides, run `run_id`),
    /// everything else at its default.
    pub fn new(run_id: Option<String>, scenario: impl Into<String>) -> EmulatorArgs {
        EmulatorArgs {
            run_id,
            scenario: ScenarioArgs::named(scenario),
            placement: EmulatorPlacement::default(),
            drop_bad_checksum: false,
            kinematics: false,
            expected_frames: 100_000,
            out: PathBuf::from("out"),
            wait_for_peer_s: None,
            channels: ChannelArgs::default(),
            ends: EndsArgs::default(),
            transports: TransportArgs::default(),
            control: ControlArgs::default(),
            stream: StreamArgs::default(),
            ros2: Ros2Args::default(),
        }
    }

    /// The argv that starts an emulator with these arguments.
    pub fn to_argv(&self) -> Vec<String> {
        super::argv::render(self)
    }

    /// Checks that the options fit the endpoints, with errors that say what
    /// would be accepted.
    pub fn validate(&self) -> Result<(), ArgsError> {
        if self.stream.several() && !self.ends.own() {
            return Err(ArgsError::StreamsNeedIceoryx2);
        }
        self.channels.check(&self.lane_shape())?;
        let (ingress, egress) = (&self.ends.ingress, &self.ends.egress);
        let flags = LaneFlags { run_id: self.run_id.as_deref(), wait_for_peer: self.wait_for_peer_s.is_some(), idle_end: self.ends.idle_end_ms.is_some() };
        Ok(self.transports.check(ingress, egress, flags)?)
    }

    /// The lanes' shape, as the reverse channels see it.
    pub fn lane_shape(&self) -> LaneShape<'_> {
        LaneShape { ingress: &self.ends.ingress, egress: &self.ends.egress, transports: &self.transports, streams: self.stream.streams }
    }

    /// How to open the transports, for a release queue of `queue_capacity`,
    /// a wait for a receiver cut short by `stop`.
    pub fn wiring<'a>(&'a self, queue_capacity: usize, stop: &'a dyn Fn() -> bool) -> Wiring<'a> {
        Wiring {
            run_id: self.run_id.as_deref(),
            queue_capacity,
            wait_for_peer_ns: self.wait_for_peer_s.map(|s| (s * 1e9) as u64),
            idle_end_ns: self.ends.idle_end_ms.map(|ms| (ms * 1e6) as u64),
            stop,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Args)]
pub struct SimulatorArgs {
    /// Run id shared by the three processes (letters, digits, '-', '_').
    #[arg(long)]
    pub run_id: String,
    #[command(flatten)]
    pub pin: PinArgs,
    /// A gap between received frames longer than this is a stall (more
    /// than 0, at most an hour).
    #[arg(long, default_value_t = 10.0, value_parser = values::stall_millis)]
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
    /// Sleep this many microseconds (up to 1000000) between idle polls
    /// instead of yielding the core (many robots sharing few cores, `netfi
    /// run --streams`).
    #[arg(long, value_name = "US", value_parser = values::nap_us())]
    pub nap_us: Option<u64>,
    #[command(flatten)]
    pub channels: ChannelEndArgs,
}

impl Render for SimulatorArgs {
    fn render(&self, a: &mut Argv) {
        a.val("--run-id", &self.run_id)
            .val("--out", self.out.display())
            .group(&self.pin)
            .switch("--spin", self.spin)
            .switch("--drop-bad-checksum", self.drop_bad_checksum)
            .val("--stall-ms", self.stall_ms)
            .opt("--nap-us", self.nap_us)
            .group(&self.channels);
    }
}

impl SimulatorArgs {
    /// The argv that starts a simulator with these arguments.
    pub fn to_argv(&self) -> Vec<String> {
        super::argv::render(self)
    }
}
