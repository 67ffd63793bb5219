//! What `netfi run` will do, decided before anything starts: the seed, the
//! frames, the cores, and the arguments of each of the three processes. A
//! pure function of the run's arguments, the scenario and the host's
//! cores, so it can be read and tested without starting anything.

use crate::scenario::ScenarioSpec;
use crate::service::args::{ConsoleArgs, EmulatorArgs, RunArgs, SimulatorArgs};
use crate::transport::udp::DEFAULT_UDP_BUFFER_BYTES;
use crate::transport::{Endpoint, Payload};
use std::path::PathBuf;

pub use crate::service::link::DEFAULT_QUEUE_CAPACITY;
pub use crate::service::seeds::{fresh as fresh_seed, fresh_run_id};

/// Default frame rate of a run, Hz.
pub const DEFAULT_RATE_HZ: f64 = 1000.0;

/// The most streams one run may carry (`--streams`).
pub const MAX_STREAMS: u32 = 64;

/// Sleep between the idle polls of each console and robot of a run of
/// several streams (µs): many processes share the cores left beside the
/// emulator's, and none may spin.
pub const STREAM_NAP_US: u64 = 200;

/// The run id whose services stream `k` uses: the run's own for stream 0,
/// `<run>-s<k>` for the others (`netfi/<run>-s<k>/console`, ...).
pub fn stream_run_id(run_id: &str, k: usize) -> String {
    if k == 0 {
        run_id.to_string()
    } else {
        format!("{run_id}-s{k}")
    }
}

pub use crate::service::seeds::stream as stream_seed;

/// Where stream `k` of a run of `streams` writes: the run's directory for
/// a single stream, `<out>/stream-<k>/` otherwise.
pub fn stream_dir(out: &std::path::Path, streams: usize, k: usize) -> PathBuf {
    if streams <= 1 {
        out.to_path_buf()
    } else {
        out.join(format!("stream-{k}"))
    }
}

/// `K=SCENARIO` (`--stream-scenario`): the stream and its scenario.
pub fn parse_stream_scenario(text: &str, streams: u32) -> anyhow::Result<(usize, String)> {
    let (k, what) = text.split_once('=').ok_or_else(|| anyhow::anyhow!("--stream-scenario {text}: expected K=SCENARIO"))?;
    let k: u32 = k.trim().parse().map_err(|_| anyhow::anyhow!("--stream-scenario {text}: K must be a stream number"))?;
    anyhow::ensure!(k < streams, "--stream-scenario {text}: stream {k} does not exist (streams 0 to {})", streams - 1);
    anyhow::ensure!(!what.is_empty(), "--stream-scenario {text}: no scenario");
    Ok((k as usize, what.to_string()))
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
    pub scenario_path: PathBuf,
    pub console: ConsoleArgs,
    pub simulator: SimulatorArgs,
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
    let emulator = args.emulator_core.or((host.len() >= 2).then(|| host[host.len() - 1]));
    let (console, simulator) = match (args.console_core, args.simulator_core) {
        (None, None) if host.len() >= 4 && args.emulator_core.is_none() => (Some(host[host.len() - 3]), Some(host[host.len() - 2])),
        given => given,
    };
    Cores { emulator, console, simulator }
}

/// How long the stream is planned to last (s), and the frames expected.
pub fn frames(args: &RunArgs) -> (f64, u64) {
    let rate_hz = args.rate_hz.unwrap_or(DEFAULT_RATE_HZ);
    match (&args.capture, args.frames, args.duration_s) {
        (_, Some(n), _) => (n as f64 / rate_hz, n),
        (_, None, Some(d)) => (d, (d * rate_hz).ceil() as u64),
        (Some(_), None, None) if args.rate_hz.is_none() => (90.0, 50_000),
        (Some(_), None, None) => (60.0, (60.0 * rate_hz) as u64),
        (None, None, None) => (10.0, (10.0 * rate_hz) as u64),
    }
}

/// One run, planned.
#[derive(Debug, Clone)]
pub struct Plan {
    pub run_id: String,
    pub out: PathBuf,
    pub spec: ScenarioSpec,
    pub seed: u64,
    /// Where the scenario is written for the emulator to read.
    pub scenario_path: PathBuf,
    pub planned_s: f64,
    pub expected_frames: u64,
    pub cores: Cores,
    pub simulator: SimulatorArgs,
    pub emulator: EmulatorArgs,
    pub console: ConsoleArgs,
    /// Every stream, stream 0 first; one stream is the run itself (its
    /// directory, run id, seed and ends).
    pub streams: Vec<StreamPlan>,
}

impl Plan {
    /// The plan for `args`, with the scenario resolved and the seed and run
    /// id chosen, on a host with `host_cores`.
    pub fn new(args: &RunArgs, spec: ScenarioSpec, seed: u64, run_id: String, host_cores: &[usize]) -> Plan {
        let out = args.out.clone().unwrap_or_else(|| PathBuf::from("out").join(&run_id));
        let scenario_path = out.join("scenario.toml");
        let (planned_s, expected_frames) = frames(args);
        let cores = cores(args, host_cores);
        // Kept off the emulator's core when not pinned themselves.
        let avoid = |own: Option<usize>| if own.is_none() { cores.emulator } else { None };
        let simulator = SimulatorArgs {
            run_id: run_id.clone(),
            core: cores.simulator,
            avoid_core: avoid(cores.simulator),
            stall_ms: 10.0,
            drop_bad_checksum: args.drop_bad_checksum,
            // A core of its own: it may busy-poll.
            spin: cores.simulator.is_some(),
            out: out.clone(),
            nap_us: None,
            video: args.video.clone(),
        };
        let emulator = EmulatorArgs {
            run_id: Some(run_id.clone()),
            scenario: scenario_path.display().to_string(),
            seed: Some(seed),
            queue_capacity: args.queue_capacity,
            core: cores.emulator,
            no_pin: cores.emulator.is_none(),
            rt_priority: args.rt_priority,
            // Passed even when unpinned, so the emulator's report says why nothing
            // was cleared.
            isolate: args.clears_core(),
            drop_bad_checksum: args.drop_bad_checksum,
            expected_frames,
            out: out.clone(),
            ingress: Endpoint::Iceoryx2,
            egress: Endpoint::Iceoryx2,
            payload: Payload::Itp,
            egress_bind: None,
            console_from: None,
            return_scenario: args.return_scenario.clone(),
            return_seed: args.return_seed,
            return_to: None,
            no_return: false,
            idle_end_ms: None,
            udp_buffer_bytes: DEFAULT_UDP_BUFFER_BYTES,
            wait_for_peer_s: None,
            no_feedback: false,
            control: args.control.clone(),
            stream: Default::default(),
            video: args.video.clone(),
            ros2: Default::default(),
        };
        let console = ConsoleArgs {
            run_id: run_id.clone(),
            rate_hz: args.rate_hz,
            frames: args.frames,
            duration_s: args.duration_s,
            capture: args.capture.clone(),
            seed: Some(seed),
            core: cores.console,
            avoid_core: avoid(cores.console),
            out: out.clone(),
            no_direct: args.no_direct,
            wait_for_peer_s: 10.0,
            feedback_wait_s: 5.0,
            live: false,
            nap_us: None,
            video: args.video.clone(),
        };
        let stream0 = StreamPlan {
            index: 0,
            run_id: run_id.clone(),
            out: out.clone(),
            spec: spec.clone(),
            seed,
            scenario_path: scenario_path.clone(),
            console: console.clone(),
            simulator: simulator.clone(),
        };
        Plan { run_id, out, spec, seed, scenario_path, planned_s, expected_frames, cores, simulator, emulator, console, streams: vec![stream0] }
    }

    /// The plan with `specs.len()` streams (`specs[k]`: stream k's
    /// scenario); one spec leaves it as it is. Each stream gets its run id,
    /// seed and directory, its ends nap between polls, and the emulator is
    /// told of the streams.
    pub fn with_streams(mut self, specs: Vec<ScenarioSpec>) -> Plan {
        let n = specs.len();
        if n <= 1 {
            return self;
        }
        self.streams = specs.into_iter().enumerate().map(|(k, spec)| self.stream(n, k, spec)).collect();
        self.emulator.stream.streams = n as u32;
        self.emulator.stream.stream_scenario =
            self.streams.iter().skip(1).map(|s| format!("{}={}", s.index, s.scenario_path.display())).collect();
        self.emulator.scenario = self.streams[0].scenario_path.display().to_string();
        self
    }

    fn stream(&self, n: usize, k: usize, spec: ScenarioSpec) -> StreamPlan {
        let (run_id, out, seed) = (stream_run_id(&self.run_id, k), stream_dir(&self.out, n, k), stream_seed(self.seed, k));
        let console = ConsoleArgs { run_id: run_id.clone(), seed: Some(seed), out: out.clone(), nap_us: Some(STREAM_NAP_US), ..self.console.clone() };
        let simulator = SimulatorArgs { run_id: run_id.clone(), out: out.clone(), spin: false, nap_us: Some(STREAM_NAP_US), ..self.simulator.clone() };
        let scenario_path = out.join("scenario.toml");
        StreamPlan { index: k, run_id, out, spec, seed, scenario_path, console, simulator }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(subcommand)]
        cmd: Cmd,
    }

    #[derive(clap::Subcommand)]
    enum Cmd {
        Run(RunArgs),
        Console(ConsoleArgs),
        Emulator(EmulatorArgs),
        Simulator(SimulatorArgs),
    }

    fn run_args(argv: &[&str]) -> RunArgs {
        match Cli::parse_from([&["netfi", "run"], argv].concat()).cmd {
            Cmd::Run(a) => a,
            _ => unreachable!(),
        }
    }

    fn plan(argv: &[&str], host: &[usize]) -> Plan {
        let spec = crate::load::resolve("Normal").unwrap();
        Plan::new(&run_args(argv), spec, 7, "r1".into(), host)
    }

    #[test]
    fn the_emulator_gets_the_last_core_and_with_four_the_others_get_one_each() {
        assert_eq!(plan(&["Normal"], &[0, 1]).cores, Cores { emulator: Some(1), console: None, simulator: None });
        assert_eq!(plan(&["Normal"], &[0, 1, 2, 3]).cores, Cores { emulator: Some(3), console: Some(1), simulator: Some(2) });
        assert_eq!(plan(&["Normal"], &[0]).cores, Cores { emulator: None, console: None, simulator: None });
        let p = plan(&["Normal", "--emulator-core", "0"], &[0, 1, 2, 3]);
        assert_eq!(p.cores, Cores { emulator: Some(0), console: None, simulator: None });
    }

    #[test]
    fn frames_follow_the_duration_the_count_or_the_default() {
        assert_eq!(frames(&run_args(&["Normal", "--duration-s", "3"])), (3.0, 3000));
        assert_eq!(frames(&run_args(&["Normal", "--frames", "500", "--rate-hz", "100"])), (5.0, 500));
        assert_eq!(frames(&run_args(&["Normal"])), (10.0, 10_000));
        assert_eq!(frames(&run_args(&["Normal", "--capture", "x.lz4"])), (90.0, 50_000));
    }

    #[test]
    fn the_core_is_cleared_unless_asked_not_to_and_only_when_pinned() {
        assert!(plan(&["Normal"], &[0, 1]).emulator.isolate);
        assert!(plan(&["Normal", "--isolate"], &[0, 1]).emulator.isolate);
        assert!(!plan(&["Normal", "--no-isolate"], &[0, 1]).emulator.isolate);
        assert!(plan(&["Normal", "--no-isolate", "--isolate"], &[0, 1]).emulator.isolate, "the later flag wins");
        assert!(plan(&["Normal"], &[0]).emulator.isolate, "no core of its own: passed on, so the report says why nothing was cleared");
    }

    #[test]
    fn each_process_parses_back_what_the_plan_gave_it() {
        let p = plan(&["Normal", "--duration-s", "2", "--rate-hz", "500", "--drop-bad-checksum", "--queue-capacity", "9"], &[0, 1]);
        let parse = |role: &str, argv: Vec<String>| Cli::parse_from([vec!["netfi".to_string(), role.to_string()], argv].concat()).cmd;
        let Cmd::Console(c) = parse("console", p.console.to_argv()) else { unreachable!() };
        assert_eq!(c.to_argv(), p.console.to_argv());
        assert_eq!((c.rate_hz, c.duration_s, c.seed, c.avoid_core, c.core), (Some(500.0), Some(2.0), Some(7), Some(1), None));
        let Cmd::Emulator(e) = parse("emulator", p.emulator.to_argv()) else { unreachable!() };
        assert_eq!(e.to_argv(), p.emulator.to_argv());
        assert_eq!((e.core, e.queue_capacity, e.expected_frames, e.isolate, e.drop_bad_checksum), (Some(1), Some(9), 1000, true, true));
        let Cmd::Simulator(s) = parse("simulator", p.simulator.to_argv()) else { unreachable!() };
        assert_eq!(s.to_argv(), p.simulator.to_argv());
        assert_eq!((s.avoid_core, s.spin, s.drop_bad_checksum), (Some(1), false, true));
    }

    #[test]
    fn a_rate_outside_the_physical_range_is_refused_naming_the_flag() {
        for bad in ["0", "-5", "NaN", "inf", "0.0001", "2e7", "fast"] {
            let flag = format!("--rate-hz={bad}");
            let e = Cli::try_parse_from(["netfi", "run", "Normal", &flag]).err().expect(bad).to_string();
            assert!(e.contains("--rate-hz") && e.contains("0.001 Hz and 10 MHz") || bad == "fast", "{bad}: {e}");
        }
        assert_eq!(run_args(&["Normal", "--rate-hz", "0.001"]).rate_hz, Some(0.001));
        assert_eq!(run_args(&["Normal", "--rate-hz", "10000000"]).rate_hz, Some(1e7));
    }
}
