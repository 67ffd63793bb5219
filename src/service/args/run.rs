//! `netfi run`'s arguments: the groups it shares with the services, and
//! its own.

use super::argv::{self, Argv, Render};
use super::error::ArgsError;
use super::groups::{ControlArgs, EmulatorPlacement, EndsArgs, ScenarioArgs, SourceArgs, StreamArgs};
use super::help;
use super::values;
use crate::service::channel::{ChannelArgs, LaneShape};
use clap::{Args, CommandFactory, Parser};
use std::ffi::OsString;
use std::path::PathBuf;

/// Where each process of a run runs.
#[derive(Debug, Clone, Default, PartialEq, Eq, Args)]
#[command(
    mut_arg("core", |a| a.long("emulator-core").help(help::RUN_PLACEMENT[0])),
    mut_arg("no_pin", |a| a.help(help::RUN_PLACEMENT[1])),
    mut_arg("isolate", |a| a.overrides_with("no_isolate").help(help::RUN_PLACEMENT[2]))
)]
pub struct RunPlacement {
    #[command(flatten)]
    pub emulator: EmulatorPlacement,
    /// Leave the emulator's core as it is: other threads may then preempt
    /// the emulator's loop.
    #[arg(long)]
    pub no_isolate: bool,
    /// Core for the console (default: not pinned).
    #[arg(long, value_parser = values::core())]
    pub console_core: Option<usize>,
    /// Core for the simulator (default: not pinned).
    #[arg(long, value_parser = values::core())]
    pub simulator_core: Option<usize>,
}

impl RunPlacement {
    /// Whether the emulator's core is to be cleared: the default, and what
    /// `--isolate` restates; `--no-isolate` turns it off (the later of the
    /// two wins).
    pub fn clears_core(&self) -> bool {
        self.emulator.isolate || !self.no_isolate
    }

    /// Checks that every core named is one this process may run on
    /// (`host`), before anything starts.
    pub fn check_cores(&self, host: &[usize]) -> Result<(), ArgsError> {
        let named = [("--emulator-core", self.emulator.core), ("--console-core", self.console_core), ("--simulator-core", self.simulator_core)];
        for (flag, core) in named {
            check_core(flag, core, host)?;
        }
        Ok(())
    }

    /// The loud words for a console or simulator pinned to the emulator's
    /// own core (the run goes on: a one-core experiment may mean it).
    pub fn shared_core_warnings(&self) -> Vec<String> {
        let Some(e) = self.emulator.core else { return Vec::new() };
        [("--console-core", self.console_core), ("--simulator-core", self.simulator_core)]
            .into_iter()
            .filter(|(_, c)| *c == Some(e))
            .map(|(flag, _)| format!("WARNING: {flag} {e} is the emulator's core: the busy-waiting loop and that process share it, and every figure of netfi's own cost says so"))
            .collect()
    }
}

/// Checks that `core` (named by `flag`), if any, is one this process may
/// run on (`host`): the one check of a named core, before anything starts.
pub fn check_core(flag: &'static str, core: Option<usize>, host: &[usize]) -> Result<(), ArgsError> {
    match core.filter(|c| !host.contains(c)) {
        Some(core) => Err(ArgsError::CoreNotAllowed { flag, core, cores: host.to_vec() }),
        None => Ok(()),
    }
}

/// `netfi run`'s arguments: one run, as a value. It renders as the argv
/// that parses back to it ([`RunArgs::to_argv`], [`RunArgs::from_argv`]),
/// which is how the UI, a study and the benchmarks start runs.
#[derive(Debug, Clone, PartialEq, Args)]
#[command(mut_arg("seed", |a| a.help(help::RUN_SEED)), mut_arg("no_feedback", |a| a.help(help::RUN_NO_FEEDBACK)))]
pub struct RunArgs {
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    #[command(flatten)]
    pub source: SourceArgs,
    #[command(flatten)]
    pub placement: RunPlacement,
    /// Drop frames with a wrong ITP checksum in the emulator and simulator.
    #[arg(long)]
    pub drop_bad_checksum: bool,
    /// Output directory (default: out/<run-id>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write into an output directory that belongs to another user (or
    /// lies in one): refused otherwise, as that user could plant files or
    /// links there.
    #[arg(long)]
    pub out_owned_by_other: bool,
    /// Also write the report as JSON here (always written to <out>/report.json).
    #[arg(long)]
    pub report_json: Option<PathBuf>,
    /// Run id (default: generated).
    #[arg(long)]
    pub run_id: Option<String>,
    /// Print the JSON report instead of the table.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub channels: ChannelArgs,
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
    pub peers: PeersArgs,
}

impl Render for RunPlacement {
    /// The emulator's `--core` is `--emulator-core` here.
    fn render(&self, a: &mut Argv) {
        let e = &self.emulator;
        a.opt("--emulator-core", e.core)
            .switch("--no-pin", e.no_pin)
            .opt("--rt-priority", e.rt_priority)
            .switch("--isolate", e.isolate)
            .switch("--no-isolate", self.no_isolate)
            .opt("--console-core", self.console_core)
            .opt("--simulator-core", self.simulator_core);
    }
}

impl Render for RunArgs {
    /// The scenario positional first, then only what differs from the
    /// defaults. A scenario that reads as a flag (`-x.toml`) goes last,
    /// after `--`.
    fn render(&self, a: &mut Argv) {
        let s = &self.scenario;
        let dashed = s.scenario.starts_with('-');
        if !dashed {
            a.words([s.scenario.clone()]);
        }
        a.opt("--seed", s.seed)
            .opt("--queue-capacity", s.queue_capacity)
            .group(&self.source)
            .group(&self.placement)
            .switch("--drop-bad-checksum", self.drop_bad_checksum)
            .opt("--out", self.out.as_ref().map(|p| p.display()))
            .switch("--out-owned-by-other", self.out_owned_by_other)
            .opt("--report-json", self.report_json.as_ref().map(|p| p.display()))
            .opt("--run-id", self.run_id.as_ref())
            .switch("--json", self.json)
            .group(&self.channels)
            .switch("--no-direct", self.no_direct)
            .group(&self.control)
            .group(&self.stream)
            .group(&self.peers);
        if dashed {
            a.words(["--".to_string(), s.scenario.clone()]);
        }
    }
}

/// `netfi run`'s command line without the program's name, read as `netfi
/// run` reads it.
#[derive(Parser)]
#[command(name = "netfi run", no_binary_name = true)]
struct RunCommand {
    #[command(flatten)]
    run: RunArgs,
}

impl RunArgs {
    /// A run of `scenario`, everything else at its default (as `netfi run
    /// SCENARIO`).
    pub fn new(scenario: impl Into<String>) -> RunArgs {
        RunArgs {
            scenario: ScenarioArgs::named(scenario),
            source: SourceArgs::default(),
            placement: RunPlacement::default(),
            drop_bad_checksum: false,
            out: None,
            out_owned_by_other: false,
            report_json: None,
            run_id: None,
            json: false,
            channels: ChannelArgs::default(),
            no_direct: false,
            control: ControlArgs::default(),
            stream: StreamArgs::default(),
            peers: PeersArgs::default(),
        }
    }

    /// The argv after `netfi run` that starts this run.
    pub fn to_argv(&self) -> Vec<String> {
        argv::render(self)
    }

    /// The run that `argv` (the words after `netfi run`) asks for, read as
    /// `netfi run` reads it: clap's error where it refuses them (see
    /// [`refusal`]). The flags' own ranges are checked; what
    /// [`RunArgs::validate`] checks is not.
    pub fn from_argv<I, T>(argv: I) -> Result<RunArgs, clap::Error>
    where
        I: IntoIterator<Item = T>,
        T: Into<OsString> + Clone,
    {
        RunCommand::try_parse_from(argv).map(|c| c.run)
    }

    /// The run's lanes, as the reverse channels see them.
    pub fn lane_shape(&self) -> LaneShape<'_> {
        let p = &self.peers;
        LaneShape { ingress: &p.ends.ingress, egress: &p.ends.egress, transports: &p.transports, streams: self.stream.streams }
    }

    /// `netfi run`'s command as clap declares it: each argument's id (its
    /// field's name), flag and aliases.
    pub fn command() -> clap::Command {
        RunCommand::command()
    }

    /// Checks what the flags' own parsers cannot: who plays each end and
    /// where, each reverse channel's flags against the run's lanes, and a
    /// stream that fits in a run.
    pub fn validate(&self) -> Result<(), ArgsError> {
        self.peers.check(self.stream.streams)?;
        self.channels.check(&self.lane_shape())?;
        self.stream.named_scenarios()?;
        self.source.planned().map(|_| ())
    }
}

/// Why clap refused a command line, in one line: the first paragraph of
/// its message, without `error: ` (no usage, no hint to `--help`).
pub fn refusal(e: &clap::Error) -> String {
    let text = e.render().to_string();
    text.split("\n\n").next().unwrap_or(&text).trim().trim_start_matches("error: ").to_string()
}

/// Who plays a run's console, or its robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Peer {
    /// netfi's own: the console's synthetic motion (or `--capture`), the
    /// simulated robot.
    #[default]
    Own,
    /// The lab's own program, joined at the emulator's endpoint: the run
    /// starts none.
    Lab,
}

/// Who plays the run's console and robot, and where the emulator meets
/// them: netfi's own over iceoryx2 (the default), or the lab's programs at
/// the emulator's endpoints, with every transport's own flags.
#[derive(Debug, Clone, Default, PartialEq, Args)]
pub struct PeersArgs {
    /// Who plays the console: `own` (netfi's; the default with an iceoryx2
    /// ingress) or `lab` (the lab's program, sending to --ingress; the
    /// default with any other ingress and with --ros2-topic). The run ends
    /// when the lab's console ends its stream (its end marker, or
    /// --idle-end-ms on a stream without one), at --duration-s when given,
    /// or on Ctrl-C.
    #[arg(long, value_enum)]
    pub console: Option<Peer>,
    /// Who plays the robot: `own` (netfi's simulator; the default with an
    /// iceoryx2 egress) or `lab` (the lab's program, receiving at
    /// --egress).
    #[arg(long, value_enum)]
    pub robot: Option<Peer>,
    #[command(flatten)]
    pub ends: EndsArgs,
    #[command(flatten)]
    pub transports: crate::transport::TransportArgs,
    #[command(flatten)]
    pub ros2: crate::transport::ros2::Ros2Args,
    /// With the lab's robot on iceoryx2: wait up to this many seconds (at
    /// most an hour; default 60) for it to subscribe before taking the
    /// console's frames, so none is released into nothing; a robot that does
    /// not come ends the run, naming it.
    #[arg(long, value_name = "S", value_parser = values::wait_seconds)]
    pub wait_for_peer_s: Option<f64>,
}

/// How long the emulator waits for the lab's robot on iceoryx2 when not told.
pub const LAB_ROBOT_WAIT_S: f64 = 60.0;

impl PeersArgs {
    /// Whether the emulator's two sides are the run's own iceoryx2 ports.
    fn iceoryx2(&self) -> (bool, bool) {
        let d = EndsArgs::default();
        let ros2 = self.ros2.on();
        (self.ends.ingress == d.ingress && !ros2, self.ends.egress == d.egress && !ros2)
    }

    /// Who plays the console.
    pub fn console(&self) -> Peer {
        self.console.unwrap_or(if self.iceoryx2().0 { Peer::Own } else { Peer::Lab })
    }

    /// Who plays the robot.
    pub fn robot(&self) -> Peer {
        self.robot.unwrap_or(if self.iceoryx2().1 { Peer::Own } else { Peer::Lab })
    }

    /// Whether a program of the lab's plays either end.
    pub fn lab(&self) -> bool {
        self.console() == Peer::Lab || self.robot() == Peer::Lab
    }

    /// Checks that netfi's own ends meet the emulator on iceoryx2 (they
    /// speak nothing else), and that the lab's join one stream.
    pub fn check(&self, streams: u32) -> Result<(), ArgsError> {
        let (i, e) = self.iceoryx2();
        if self.console() == Peer::Own && !i {
            return Err(ArgsError::OwnEndElsewhere { end: "console", flag: "--ingress", at: self.at(true) });
        }
        if self.robot() == Peer::Own && !e {
            return Err(ArgsError::OwnEndElsewhere { end: "robot", flag: "--egress", at: self.at(false) });
        }
        if self.lab() && streams > 1 {
            return Err(ArgsError::LabStreams { streams });
        }
        Ok(())
    }

    fn at(&self, ingress: bool) -> String {
        match (self.ros2.on(), ingress) {
            (true, _) => "ROS 2 topics (--ros2-topic)".into(),
            (false, true) => self.ends.ingress.to_string(),
            (false, false) => self.ends.egress.to_string(),
        }
    }
}

impl Render for PeersArgs {
    fn render(&self, a: &mut Argv) {
        let value = |p: Option<Peer>| p.and_then(|p| clap::ValueEnum::to_possible_value(&p).map(|v| v.get_name().to_string()));
        a.opt("--console", value(self.console))
            .opt("--robot", value(self.robot))
            .group(&self.ends)
            .group(&self.transports)
            .group(&self.ros2)
            .opt("--wait-for-peer-s", self.wait_for_peer_s);
    }
}
