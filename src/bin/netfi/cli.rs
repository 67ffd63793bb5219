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
    /// A scenario file (TOML) or a preset name (Normal, PLM-1..3, DLM-1..3, CLM-1..3).
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
    /// Seed of the scenario's random streams (default: the file's, else random; always printed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Release-queue capacity in frames (default: the file's, else 65536).
    #[arg(long)]
    pub queue_capacity: Option<usize>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}
