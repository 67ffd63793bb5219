//! Command-line arguments.

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

/// netfi: a network fault injector for teleoperation.
#[derive(Debug, Parser)]
#[command(name = "netfi", version, about, propagate_version = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a scenario end to end: console, emulator and simulator as three
    /// processes over iceoryx2, then print the report.
    Run(netfi::service::args::RunArgs),
    /// Inspect and check scenarios in simulated time.
    #[command(subcommand)]
    Scenario(ScenarioCmd),
    /// The console service alone (streams ITP frames).
    Console(netfi::service::args::ConsoleArgs),
    /// The emulator service alone (injects the scenario's faults).
    Emulator(netfi::service::args::EmulatorArgs),
    /// The simulator service alone (receives and measures).
    Simulator(netfi::service::args::SimulatorArgs),
    /// Fit a model's parameters to a target; build or verify the fault parameter database.
    #[command(subcommand)]
    Fit(FitCmd),
    /// Export a scenario to another tool's configuration.
    #[command(subcommand)]
    Export(ExportCmd),
    /// Steer and watch a running emulator: show its scenario, switch it,
    /// pause faults, print its telemetry.
    Ctl(CtlArgs),
    /// Put back what killed runs left on this host: cleared cores (thread
    /// masks, interrupt affinities, the workqueue mask) and iceoryx2
    /// resources of dead processes. Every `netfi run` does this first.
    Restore(RestoreArgs),
    /// The browser front end: build, preview, run and steer scenarios, and
    /// read their reports (served on loopback).
    Ui(UiArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions {
        /// The shell to complete for.
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff) of netfi and its commands; `--dir`
    /// writes one page per command there instead.
    Man {
        /// Write `netfi.1`, `netfi-run.1`, … into this directory.
        #[arg(long)]
        dir: Option<PathBuf>,
    },
    /// Show the report of a finished run from its output directory; with
    /// --html, write it as one self-contained page, `report.html`, there.
    Report(ReportArgs),
    Study(crate::study::StudyArgs),
    /// Record ROS 2 topics as MCAP, and replay a recording at its timing.
    #[command(subcommand)]
    Ros2(netfi::service::ros2::bag::Ros2Cmd),
}

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The run's output directory (what `netfi run --out` was given).
    pub out_dir: PathBuf,
    /// Write `report.html` into the directory (inline SVG plots and CSS,
    /// no external file or URL) and print its path.
    #[arg(long)]
    pub html: bool,
}

#[derive(Debug, Args)]
pub struct UiArgs {
    /// Port to listen on (0: any free port, printed).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
    /// Address to listen on. Anything but loopback lets whoever reaches it
    /// and has the token start runs on this host, over plain HTTP.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: std::net::IpAddr,
    /// Parent directory of the runs' output directories.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// The core the runs' emulators use (default: the last core): the
    /// server keeps off it.
    #[arg(long)]
    pub emulator_core: Option<usize>,
    /// Also answer to this host name (as other machines reach this one;
    /// repeatable). Requests naming any other host are refused, except
    /// `localhost` and IP addresses of this server.
    #[arg(long, value_name = "NAME")]
    pub allow_host: Vec<String>,
    /// Serve without the token printed at start: loopback only (`--bind`
    /// another address is refused), and any program of any user of this
    /// host can then drive it.
    #[arg(long)]
    pub no_token: bool,
}

#[derive(Debug, Args)]
pub struct RestoreArgs {
    /// Act as the guardian of this record: wait until its owners have all
    /// ended, then restore from it (started by the clearing process).
    #[arg(long, hide = true, value_name = "RECORD")]
    pub guard: Option<PathBuf>,
}

#[derive(Debug, Subcommand)]
pub enum ScenarioCmd {
    /// Run a scenario in simulated time and report what it realizes.
    Check(CheckArgs),
    /// List the built-in presets.
    List,
    /// Print a scenario (file or preset) as the TOML it resolves to.
    Show {
        /// A scenario file or a preset name.
        scenario: String,
    },
}

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// A scenario file (TOML) or a preset name (Normal, PLM-1..3, DLM-1..3, CLM-1..3, their calibrated -cal variants; see `netfi scenario list`).
    pub scenario: String,
    /// Frames to simulate at the fixed rate.
    #[arg(long, default_value_t = 1_000_000)]
    pub frames: u64,
    /// Frame rate in Hz.
    #[arg(long, default_value_t = 1000.0)]
    pub rate_hz: f64,
    /// Use the arrival times of a recorded capture instead of a fixed rate.
    #[arg(long, conflicts_with_all = ["frames", "rate_hz"])]
    pub capture: Option<PathBuf>,
    /// The most records of --capture read, 1 to 2^32 (default 4194304,
    /// 2^22); a capture with more is refused before more of it is read.
    #[arg(long, value_name = "RECORDS", requires = "capture", value_parser = clap::builder::RangedU64ValueParser::<u64>::new().range(1..=netfi::service::args::values::MAX_CAPTURE_RECORDS))]
    pub capture_max_records: Option<u64>,
    /// Seed of the scenario's random streams (default: the file's, else random; always printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Release-queue capacity in frames (default: the file's, else 65536).
    #[arg(long)]
    pub queue_capacity: Option<usize>,
    /// Also write every frame's fate to FILE, in a run's `trace.csv`
    /// columns (send and ingress at the simulated arrival, released at the
    /// scheduled time; copies are counted in the report, not given rows).
    #[arg(long, value_name = "FILE")]
    pub trace: Option<std::path::PathBuf>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Subcommand)]
pub enum FitCmd {
    /// Packet loss: a two-state `ge_lomax` with the study's transition matrix.
    Loss {
        /// Target loss rate: 0.3 or 30%.
        target: String,
        /// Also aim at this mean loss-run length, in frames (frees the Lomax shape).
        #[arg(long)]
        run_length: Option<f64>,
        #[command(flatten)]
        common: FitCommon,
    },
    /// Delay: a minimum plus a two-component hyperexponential, reorder.
    Delay {
        /// Target mean delay in ms: 250 or 250ms.
        target: String,
        /// Also aim at this 99th percentile, in ms.
        #[arg(long, conflicts_with = "std_ms")]
        p99_ms: Option<f64>,
        /// Also aim at this standard deviation, in ms.
        #[arg(long)]
        std_ms: Option<f64>,
        /// The minimum delay in ms (default: 0.7 × the target mean).
        #[arg(long)]
        min_ms: Option<f64>,
        #[command(flatten)]
        common: FitCommon,
    },
    /// Communication loss: outage windows with a cooldown, in time units.
    Outage {
        /// Target lost fraction: 0.1 or 10%.
        target: String,
        /// Also aim at this mean outage (window) length, in ms.
        #[arg(long)]
        outage_ms: Option<f64>,
        /// Frame rate the lost fraction is measured at.
        #[arg(long, default_value_t = 1000.0)]
        rate_hz: f64,
        #[command(flatten)]
        common: FitCommon,
    },
    /// Jitter (docs/spec.md §3.7): a delay law around a mean, fitted to a mean and a p99 in closed form.
    Jitter {
        /// Target mean delay in ms: 100 or 100ms.
        target: String,
        /// The 99th percentile of the delay, in ms (above the mean).
        #[arg(long)]
        p99_ms: f64,
        /// The law: normal, pareto or paretonormal.
        #[arg(long, default_value = "normal")]
        dist: String,
        /// Lag-1 correlation in [0, 1): 0.25 or 25% (the mean and p99 do not depend on it).
        #[arg(long, default_value = "0")]
        correlation: String,
        #[command(flatten)]
        common: FitCommon,
    },
    /// Build the fault parameter database (every target of its grid), or verify one.
    Db(FitDbArgs),
}

#[derive(Debug, Args)]
pub struct FitCommon {
    /// Seed of the search and the confirmation (default: random; always printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Keep a study preset's shape and scale one parameter (PLM-*, DLM-*, CLM-*).
    #[arg(long)]
    pub like: Option<String>,
    /// How the search computes a candidate's metrics.
    #[arg(long, value_enum, default_value_t = ObjectiveArg::Exact)]
    pub objective: ObjectiveArg,
    /// Threads (default: the available cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ObjectiveArg {
    /// Closed forms (exact for every metric fitted here).
    Exact,
    /// Monte Carlo estimates with common random numbers (the study's method).
    MonteCarlo,
}

#[derive(Debug, Args)]
pub struct FitDbArgs {
    /// Write the database here (default: standard output).
    #[arg(long, conflicts_with = "verify")]
    pub out: Option<PathBuf>,
    /// Master seed of the entries' seeds (default: the shipped database's, 2026).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Instead of building, check every entry of this database file: its
    /// closed form, an exact re-simulation with its seed, and an independent
    /// re-simulation with another seed.
    #[arg(long, value_name = "PATH")]
    pub verify: Option<PathBuf>,
    /// Threads (default: the available cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

#[derive(Debug, Subcommand)]
pub enum ExportCmd {
    /// The `tc qdisc … netem …` commands for a scenario, with what is approximated.
    Netem(ExportNetemArgs),
}

#[derive(Debug, Args)]
pub struct ExportNetemArgs {
    /// A scenario file (TOML) or a preset name.
    pub scenario: String,
    /// Network interface the qdisc goes on.
    #[arg(long, default_value = "eth0")]
    pub dev: String,
    /// Frame rate the queue limit is sized for, in Hz.
    #[arg(long, default_value_t = 1000.0)]
    pub rate_hz: f64,
    /// Directory where tc looks for distribution tables (default: the
    /// script looks for it where it runs: the distribution's usual places,
    /// those found on this machine first; `TC_LIB_DIR` wins when set).
    #[arg(long)]
    pub table_dir: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct CtlArgs {
    /// The run to steer (its emulator must be running, as this user).
    #[arg(long)]
    pub run_id: String,
    /// Print the emulator's answer as JSON (`watch`: one object per interval).
    #[arg(long, global = true)]
    pub json: bool,
    #[command(subcommand)]
    pub command: CtlCmd,
}

#[derive(Debug, Subcommand)]
pub enum CtlCmd {
    /// The current scenario, phase, pause, and the phases to come.
    Show,
    /// Switch to a scenario file, a preset, or a target (`loss=30%`,
    /// `delay_ms_mean=250`, `outage=10%`): it replaces the rest of the run's
    /// timeline from now or from --at.
    Switch {
        /// A scenario file (TOML), a preset name, or a target.
        scenario: String,
        /// When, from the run's first frame (`12.5s`, `250ms`, a number of
        /// ms), or `+5s` from now (default: now).
        #[arg(long, value_name = "TIME")]
        at: Option<String>,
    },
    /// Go to a phase (number from 1, or name) of the scenario running.
    Phase {
        /// The phase.
        phase: String,
        /// When (as for `switch`).
        #[arg(long, value_name = "TIME")]
        at: Option<String>,
    },
    /// Pause every fault: frames pass untouched, with no added delay.
    Pause,
    /// Resume the faults where they stopped.
    Resume,
    /// Print the telemetry (one row per interval) until the run ends.
    Watch {
        /// Stop after this many intervals.
        #[arg(long)]
        count: Option<u64>,
    },
}
