//! Command-line arguments of the services, shared by `netfi <service>` and
//! the stand-alone `netfi-console`, `netfi-emulator`, `netfi-simulator`.

use crate::service::udp::{Endpoint, Payload};
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Debug, Clone, Args)]
pub struct ConsoleArgs {
    /// Run id shared by the three processes (letters, digits, '-', '_').
    #[arg(long)]
    pub run_id: String,
    /// Frame rate in Hz (synthetic motion, or a capture replayed at a fixed rate).
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// Frames to send (default: --duration-s worth).
    #[arg(long, conflicts_with = "duration_s")]
    pub frames: Option<u64>,
    /// Seconds to stream (default 10; with --capture, the whole capture).
    #[arg(long)]
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
    #[arg(long, default_value_t = 10.0)]
    pub wait_for_peer_s: f64,
}

#[derive(Debug, Clone, Args)]
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
    /// Pass datagrams coming back from the robot side through this scenario
    /// (file or preset) instead of relaying them untouched.
    #[arg(long, value_name = "SCENARIO")]
    pub return_scenario: Option<String>,
    /// Seed of the return path's scenario (default: the file's, else derived
    /// from --seed; printed).
    #[arg(long)]
    pub return_seed: Option<u64>,
    /// Send return datagrams here instead of to the console's latest source
    /// address (`udp://ADDR:PORT`).
    #[arg(long, value_name = "ENDPOINT")]
    pub return_to: Option<Endpoint>,
    /// Do not relay datagrams from the robot side at all.
    #[arg(long)]
    pub no_return: bool,
    /// With a UDP ingress: end the run as if the console had ended, once no
    /// datagram has arrived for this many milliseconds (default: run until
    /// SIGINT/SIGTERM).
    #[arg(long, value_name = "MS")]
    pub idle_end_ms: Option<f64>,
    /// Requested kernel receive/send buffer of each UDP socket, bytes.
    #[arg(long, default_value_t = crate::service::udp::DEFAULT_UDP_BUFFER_BYTES)]
    pub udp_buffer_bytes: usize,
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
    #[arg(long, default_value_t = 10.0)]
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
}

#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// A scenario file (TOML) or a preset name (Normal, PLM-1..3, DLM-1..3, CLM-1..3, their calibrated -cal variants; see `netfi scenario list`).
    pub scenario: String,
    /// Seconds to stream (default 10; with --capture, the whole capture).
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Frames to stream instead of a duration.
    #[arg(long, conflicts_with = "duration_s")]
    pub frames: Option<u64>,
    /// Frame rate in Hz (default 1000; with --capture, replays at this fixed rate).
    #[arg(long)]
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
    /// Do not send the direct (baseline) copy of each frame to the simulator:
    /// halves the console's and simulator's work at very high rates, at the
    /// price of the in-run baseline and the console-side kinematics.
    #[arg(long)]
    pub no_direct: bool,
}
