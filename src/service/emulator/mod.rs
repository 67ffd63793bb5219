//! The emulator service: one loop, pinned to one core, over N ≥ 1 lanes
//! (streams). A lane is a forward path (console → robot) and its reverse
//! paths (each a channel of `crate::service::channel`: the robot's
//! feedback, the camera's video, the UDP return); a
//! path is one [`Link`](crate::service::link::Link) between the ports of a
//! [`Channel`](path::Channel), written once ([`path`]). Each turn of a
//! lane releases what is due, polls its reverse paths and takes every
//! frame waiting at its ingress (up to a batch), deciding each; nothing in
//! it allocates, locks or makes a system call beyond the transports' own.
//!
//! | file | what |
//! |---|---|
//! | `path` | the path around a link, generic over its channel; the reverse paths' object |
//! | `forward` | the forward channel (the reverse ones are `crate::service::channel`'s) |
//! | `opening` | what opening a reverse path needs |
//! | `lane` | one stream: its forward path, its reverse paths, its turn and its end |
//! | `spin` | the one loop over the lanes, and the reaper of dead peers |
//! | `busy` | the loop's busy time and the capacity it implies |
//! | `config` | the arguments resolved once: each lane's scenario, seed and queue |
//! | `itp` | lanes of ITP frames over iceoryx2 and UDP: their transports opened, `udp.json` |
//! | `ros2/` | lanes of ROS 2 topics: their flags resolved (`plan`), topics settled and opened, `ros2.json`; the forward and return channels (`topic`) |
//! | `run` | running lanes of any kind: control, placement, the loop, the reports |
//! | `report` | `emulator.json`, the joint report of several lanes, `udp.json` |
//!
//! Each step has its own error ([`config::ConfigError`],
//! [`ros2::plan::Ros2PlanError`], [`opening::OpenError`],
//! [`ros2::TopicError`], [`path::PathError`], [`run::RunError`]);
//! [`EmulatorError`] is any of them, with the stream or lane it came from.

pub mod busy;
pub mod config;
pub mod forward;
pub mod itp;
pub mod lane;
pub mod opening;
pub mod path;
pub mod report;
pub mod ros2;
pub mod run;
pub mod spin;

pub use crate::service::schema::{BadInput, EmulatorReport, LoopBusy};
pub use forward::{classify, Forward};

use crate::service::args::EmulatorArgs;
use config::EmulatorConfig;

/// Why the emulator did not run to its reports.
#[derive(Debug, thiserror::Error)]
pub enum EmulatorError {
    #[error(transparent)]
    Config(#[from] config::ConfigError),
    #[error(transparent)]
    Ros2Plan(#[from] ros2::plan::Ros2PlanError),
    #[error(transparent)]
    Pid(#[from] crate::service::PidError),
    /// The ROS 2 participant's threads, placed off the loop's core.
    #[error(transparent)]
    Place(#[from] crate::host::placement::PlaceError),
    /// The ROS 2 participant.
    #[error(transparent)]
    Dds(#[from] crate::transport::ros2::OpenError),
    /// A lane of ITP frames that did not open.
    #[error("stream {stream}")]
    Stream {
        stream: usize,
        #[source]
        cause: itp::LaneError,
    },
    /// A lane of ROS 2 topics that did not open.
    #[error("lane {lane} ({from} → {to})")]
    Lane {
        lane: usize,
        from: crate::transport::ros2::TopicName,
        to: crate::transport::ros2::TopicName,
        #[source]
        cause: ros2::TopicError,
    },
    #[error(transparent)]
    Run(#[from] run::RunError),
}

/// Wires the emulator: arguments → lanes → the loop → each lane's report
/// (and the joint one of several, and `udp.json` where a side is UDP).
/// Returns lane 0's report.
/// The words the emulator's report speaks of its stream in: lane 0's
/// topics and their messages with `--ros2-topic`, else ITP frames.
pub fn words(args: &EmulatorArgs) -> crate::service::report::Words {
    let topics = args.ros2.on().then(|| ros2::plan::Plan::of(args).ok()).flatten();
    match topics.as_ref().and_then(|p| p.lanes.first()) {
        Some(l) => crate::service::report::Words::ros2(&l.forward.0.to_string(), &l.forward.1.to_string()),
        None => crate::service::report::Words::itp(),
    }
}

pub fn main(args: &EmulatorArgs) -> Result<EmulatorReport, EmulatorError> {
    if args.ros2.on() {
        return Ok(ros2::main(args)?.swap_remove(0));
    }
    let cfg = EmulatorConfig::of(args)?;
    crate::service::write_pid(&cfg.out_dir, "emulator")?;
    let mut reports = itp::main(&cfg)?;
    Ok(reports.swap_remove(0))
}
