//! What `netfi run` will do, decided before anything starts: the seeds, the
//! frames, the cores, and the arguments of each of the three processes. A
//! pure function of the run's arguments, the scenarios the runner resolved
//! and the host's cores, so it can be read and tested without starting
//! anything. Every seed is decided here (by the rules of
//! [`seeds`](crate::service::seeds)) and handed to the processes.

use crate::scenario::ScenarioSpec;
use crate::service::args::run::LAB_ROBOT_WAIT_S;
use crate::service::args::{ArgsError, ConsoleArgs, EmulatorArgs, EmulatorPlacement, Peer, PinArgs, RunArgs, SimulatorArgs};
use crate::service::channel::Want;
use std::collections::BTreeMap;
use crate::service::args::streams;
use crate::service::seeds;
use std::path::{Path, PathBuf};

pub use crate::service::args::values::{DEFAULT_RATE_HZ, MAX_STREAMS};
pub use crate::service::link::DEFAULT_QUEUE_CAPACITY;
pub use crate::service::seeds::{fresh as fresh_seed, fresh_run_id, stream as stream_seed};
pub use crate::service::args::streams::{dir as stream_dir, run_id as stream_run_id};

/// Sleep between the idle polls of each console and robot of a run of
/// several streams (µs): many processes share the cores left beside the
/// emulator's, and none may spin.
pub const STREAM_NAP_US: u64 = 200;

/// How long a console waits for the emulator to subscribe (s).
const CONSOLE_WAIT_FOR_PEER_S: f64 = 10.0;

/// How long a console waits for the end of the robot's feedback (s).
const CONSOLE_FEEDBACK_WAIT_S: f64 = 5.0;

/// What the runner resolved before planning: every stream's scenario
/// (stream 0 first), and each reverse path stream 0 has (by channel, as
/// the channel asks for it) with its scenario.
#[derive(Debug, Clone)]
pub struct Resolved {
    pub streams: Vec<ScenarioSpec>,
    pub paths: Vec<(&'static str, Want, ScenarioSpec)>,
}

/// Every seed of a run, decided once.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Seeds {
    /// The run's, which is stream 0's.
    pub run: u64,
    /// Stream 0's reverse paths', by channel.
    pub paths: BTreeMap<&'static str, u64>,
}

impl Seeds {
    /// The seeds of a run whose seed is `run` and whose paths are `r`'s:
    /// each path's given, else its scenario file's, else derived from the
    /// run's by its channel's tag.
    pub fn of(run: u64, r: &Resolved) -> Seeds {
        Seeds { run, paths: r.paths.iter().map(|(c, w, spec)| (*c, seeds::derived(w.seed, spec, run, w.tag))).collect() }
    }
}

/// One console → robot pair of a run: its services' run id, scenario,
/// seed, directory and the arguments of its two ends.
#[derive(Debug, Clone)]
pub struct StreamPlan {
    pub index: usize,
    pub run_id: String,
    pub out: PathBuf,
    pub spec: ScenarioSpec,
    pub seed: u64,
    /// The copy of its scenario kept for people (`scenario.toml`).
    pub scenario_path: PathBuf,
    /// The copy the emulator reads, this run's own.
    pub own_scenario: PathBuf,
    /// netfi's own console, when it plays the console (`None`: the lab's).
    pub console: Option<ConsoleArgs>,
    /// netfi's own robot, when it plays the robot (`None`: the lab's).
    pub simulator: Option<SimulatorArgs>,
}

/// Where each process runs: a core of its own, or (`None`) not pinned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cores {
    pub emulator: Option<usize>,
    pub console: Option<usize>,
    pub simulator: Option<usize>,
}

/// Placement: the emulator busy-waits on a core of its own (the last). With
/// four cores or more the console and the simulator get one each too; with
/// fewer they share the rest, and are kept off the emulator's core.
pub fn cores(args: &RunArgs, host: &[usize]) -> Cores {
    let p = &args.placement;
    let given = p.emulator.core;
    let emulator = if p.emulator.no_pin { None } else { given.or((host.len() >= 2).then(|| host[host.len() - 1])) };
    let (console, simulator) = match (p.console_core, p.simulator_core) {
        (None, None) if host.len() >= 4 && given.is_none() && emulator.is_some() => (Some(host[host.len() - 3]), Some(host[host.len() - 2])),
        given => given,
    };
    Cores { emulator, console, simulator }
}

/// How long the stream is planned to last (s), and the frames expected.
pub fn frames(args: &RunArgs) -> Result<(f64, u64), ArgsError> {
    args.source.planned()
}

/// One run, planned.
#[derive(Debug, Clone)]
pub struct Plan {
    pub run_id: String,
    pub out: PathBuf,
    /// Stream 0's scenario.
    pub spec: ScenarioSpec,
    /// The run's seed (stream 0's).
    pub seed: u64,
    pub seeds: Seeds,
    /// Where stream 0's scenario is kept for people.
    pub scenario_path: PathBuf,
    pub planned_s: f64,
    /// When the run ends by the clock (the planned end of netfi's own
    /// console's stream, or the duration a run of the lab's console was
    /// given); `None`: when the lab's console ends it, or on Ctrl-C.
    pub until_s: Option<f64>,
    pub expected_frames: u64,
    pub cores: Cores,
    pub emulator: EmulatorArgs,
    /// Every stream, stream 0 first; one stream is the run itself (its
    /// directory, run id, seed and ends).
    pub streams: Vec<StreamPlan>,
}

impl Plan {
    /// The plan for `args`, with the scenarios resolved (`r`), the run's
    /// seed and id chosen, on a host with `host_cores`.
    pub fn new(args: &RunArgs, r: &Resolved, seed: u64, run_id: String, host_cores: &[usize]) -> Result<Plan, ArgsError> {
        let out = args.out.clone().unwrap_or_else(|| PathBuf::from("out").join(&run_id));
        let (planned_s, expected_frames) = frames(args)?;
        let cores = cores(args, host_cores);
        let seeds = Seeds::of(seed, r);
        let run = Run { args, cores, run_id: &run_id, out: &out, seed, n: r.streams.len() };
        let streams: Vec<StreamPlan> = r.streams.iter().enumerate().map(|(k, spec)| run.stream(k, spec.clone())).collect();
        let emulator = emulator(args, &streams, cores, &seeds, expected_frames, &out);
        let s0 = &streams[0];
        let (spec, scenario_path) = (s0.spec.clone(), s0.scenario_path.clone());
        let until_s = match args.peers.console() {
            Peer::Own => Some(planned_s),
            Peer::Lab => args.source.duration_s,
        };
        Ok(Plan { run_id, out, spec, seed, seeds, scenario_path, planned_s, until_s, expected_frames, cores, emulator, streams })
    }
}

/// What every stream of a run is planned from.
struct Run<'a> {
    args: &'a RunArgs,
    cores: Cores,
    run_id: &'a str,
    out: &'a Path,
    seed: u64,
    /// The run's streams.
    n: usize,
}

impl Run<'_> {
    /// Stream `k`, its scenario `spec`.
    fn stream(&self, k: usize, spec: ScenarioSpec) -> StreamPlan {
        let Run { args, cores, n, .. } = *self;
        let (run_id, out, seed) = (streams::run_id(self.run_id, k), streams::dir(self.out, n, k), seeds::stream(self.seed, k));
        // Kept off the emulator's core when not pinned themselves.
        let pin = |core: Option<usize>| PinArgs { core, avoid_core: if core.is_none() { cores.emulator } else { None } };
        // Many ends on few cores nap between polls.
        let nap_us = (n > 1).then_some(STREAM_NAP_US);
        let console = ConsoleArgs {
            run_id: run_id.clone(),
            source: args.source.clone(),
            seed: Some(seed),
            pin: pin(cores.console),
            out: out.clone(),
            no_direct: args.no_direct,
            wait_for_peer_s: CONSOLE_WAIT_FOR_PEER_S,
            feedback_wait_s: CONSOLE_FEEDBACK_WAIT_S,
            live: false,
            nap_us,
            channels: args.channels.end_args(),
        };
        let simulator = SimulatorArgs {
            run_id: run_id.clone(),
            pin: pin(cores.simulator),
            stall_ms: 10.0,
            drop_bad_checksum: args.drop_bad_checksum,
            // A core of its own: it may busy-poll.
            spin: cores.simulator.is_some() && n == 1,
            out: out.clone(),
            nap_us,
            channels: args.channels.end_args(),
        };
        let (scenario_path, own_scenario) = (out.join("scenario.toml"), out.join(format!("scenario.{run_id}.toml")));
        let console = (args.peers.console() == Peer::Own).then_some(console);
        let simulator = (args.peers.robot() == Peer::Own).then_some(simulator);
        StreamPlan { index: k, run_id, out, spec, seed, scenario_path, own_scenario, console, simulator }
    }
}

/// The emulator's arguments: every stream's scenario as the run's own
/// copy, and every seed decided.
fn emulator(args: &RunArgs, streams: &[StreamPlan], cores: Cores, seeds: &Seeds, expected_frames: u64, out: &Path) -> EmulatorArgs {
    let mut e = EmulatorArgs::new(Some(streams[0].run_id.clone()), streams[0].own_scenario.display().to_string());
    e.scenario.seed = Some(seeds.run);
    e.scenario.queue_capacity = args.scenario.queue_capacity;
    e.placement = EmulatorPlacement {
        core: cores.emulator,
        no_pin: cores.emulator.is_none(),
        rt_priority: args.placement.emulator.rt_priority,
        // Passed even when unpinned, so the emulator's report says why nothing
        // was cleared.
        isolate: args.placement.clears_core(),
    };
    e.drop_bad_checksum = args.drop_bad_checksum;
    e.expected_frames = expected_frames;
    e.out = out.to_path_buf();
    e.channels = args.channels.clone();
    // Several streams: each lane's reverse paths' seeds follow from its own
    // seed by the same rule in the emulator, unless one was given for all.
    if streams.len() == 1 {
        for (c, seed) in &seeds.paths {
            *e.channels.seed_mut(c).expect("a channel of the registry") = Some(*seed);
        }
    }
    e.control = args.control.clone();
    // Where the emulator meets the lab's programs, and how long it waits
    // for the lab's robot on iceoryx2.
    let p = &args.peers;
    e.ends = p.ends.clone();
    e.transports = p.transports.clone();
    e.ros2 = p.ros2.clone();
    let robot_subscribes = p.ends.egress.of::<crate::transport::ipc::Iceoryx2>().is_some() && !p.ros2.on();
    // The lab's programs report nothing of their own: the motion is
    // followed where the emulator takes and releases the frames.
    e.kinematics = p.lab();
    e.wait_for_peer_s = p.wait_for_peer_s.or((p.robot() == Peer::Lab && robot_subscribes).then_some(LAB_ROBOT_WAIT_S));
    e.stream.streams = streams.len() as u32;
    e.stream.stream_scenario = streams.iter().skip(1).map(|s| format!("{}={}", s.index, s.own_scenario.display())).collect();
    e
}

#[cfg(test)]
mod tests;
