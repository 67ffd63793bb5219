//! Command-line arguments of `netfi run` and of the services, shared by
//! `netfi <service>` and the stand-alone `netfi-console`, `netfi-emulator`,
//! `netfi-simulator`.
//!
//! Each group of flags is declared once ([`groups`]; a transport's own in
//! its folder, `crate::transport`) and flattened
//! into every command that takes it; every numeric flag's range is checked
//! where it is parsed ([`values`]). Each process's arguments render as the
//! argv that parses back to them ([`argv`]), which is how `netfi run`
//! starts the services, and how the UI, a study and the benchmarks start
//! `netfi run` and `netfi emulator`.
//!
//! | file | what |
//! |---|---|
//! | `groups` | scenario, source of frames, the lane's endpoints, placement, control, streams (a reverse channel's own are in its folder, `crate::service::channel`) |
//! | `services` | `ConsoleArgs`, `EmulatorArgs`, `SimulatorArgs` |
//! | `run` | `RunArgs` |
//! | `help` | what a shared flag means to one command |
//! | `streams` | the run id and directory of each stream of a run |
//! | `error` | arguments that do not go together |

pub mod error;
pub mod groups;
pub mod help;
pub mod run;
pub mod streams;
pub mod services;

pub use crate::flags::{argv, values};
pub use crate::flags::{Argv, Render};
pub use error::ArgsError;
pub use groups::{ControlArgs, EmulatorPlacement, EndsArgs, PinArgs, ScenarioArgs, SourceArgs, StreamArgs};
pub use run::{check_core, refusal, Peer, PeersArgs, RunArgs, RunPlacement};
pub use services::{ConsoleArgs, EmulatorArgs, SimulatorArgs};
pub use values::{millis, parse_rate_hz, seconds, MAX_STREAMS, RATE_HZ_RANGE};

#[cfg(test)]
pub(crate) mod tests;
