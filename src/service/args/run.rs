//! `netfi run`'s arguments: the groups it shares with the services, and
//! its own.

use super::error::ArgsError;
use super::groups::{ControlArgs, EmulatorPlacement, ReturnArgs, ScenarioArgs, SourceArgs, StreamArgs};
use super::help;
use super::values;
use crate::service::video::VideoArgs;
use clap::Args;
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
            if let Some(core) = core.filter(|c| !host.contains(c)) {
                return Err(ArgsError::CoreNotAllowed { flag, core, cores: host.to_vec() });
            }
        }
        Ok(())
    }
}

#[derive(Debug, Clone, Args)]
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
    pub return_path: ReturnArgs,
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
    pub video: VideoArgs,
}

impl RunArgs {
    /// Checks what the flags' own parsers cannot: the video flags, video
    /// with one stream, and a stream that fits in a run.
    pub fn validate(&self) -> Result<(), ArgsError> {
        self.video.validate().map_err(ArgsError::Video)?;
        if self.video.on() && self.stream.streams > 1 {
            return Err(ArgsError::VideoOneStream { streams: self.stream.streams });
        }
        self.stream.named_scenarios()?;
        self.source.planned().map(|_| ())
    }
}
