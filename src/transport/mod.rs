//! The only door to the outside world: moving frames between processes.
//!
//! Everything that touches iceoryx2 lives under [`ipc`], everything that
//! touches a socket under [`udp`]; no other module of the crate names an
//! iceoryx2 type or opens a socket, and the services only wire the types
//! exported here. The sans-IO core never depends on this module.
//!
//! A service sees a transport through two traits, [`FrameSource`] and
//! [`FrameSink`] ([`ports`]). Each transport is a folder with a
//! [`Transport`] impl ([`declare`]: its endpoint scheme, flags, opener and
//! report), listed once in [`registry`]; the emulator's two sides are the
//! registry's values: [`Endpoint`] (parsed by each transport's scheme),
//! [`Ingress`] and [`Egress`] (enums over the transports, written by the
//! registry), opened together by [`open`].
//!
//! # Contract
//!
//! - One run (one console, one emulator, one simulator) is identified by a
//!   validated [`RunId`]. Every iceoryx2 resource of a run lives under the
//!   file prefix `netfi_<run>_`, taken from an explicit configuration
//!   ([`IpcConfig`]); no iceoryx2 configuration file is ever read, so two runs
//!   on one host (or two tests in one process) never see each other.
//! - Three ports per run for its frames, each one publish/subscribe
//!   service carrying [`FrameSample`](crate::sample::FrameSample):
//!   [`Port::CONSOLE`] (console → emulator), [`Port::EMULATOR`] (emulator →
//!   simulator) and [`Port::DIRECT`] (console → simulator, the baseline
//!   hop); a reverse channel declares its own.
//! - Sending and receiving a frame allocate nothing and never block: a full
//!   subscriber queue is reported to the publisher as
//!   [`FrameSendError::QueueFull`] and counted, never overwritten silently.
//! - A killed peer is noticed by [`IpcNode::reap_dead_peers`] (called at a
//!   low rate from the service loop) and its resources are removed, so the
//!   peer can be restarted and reconnects without any action by the others.
//! - Ctrl-C / SIGTERM are latched by the transport and read with
//!   [`IpcNode::termination_requested`]; the services decide how to stop.

#![warn(missing_docs)]

pub mod declare;
pub mod endpoint;
pub mod ipc;
pub mod open;
pub mod ports;
pub mod registry;
pub mod ros2;
pub mod udp;
#[cfg(debug_assertions)]
pub mod unixgram;

pub use declare::{LaneFlags, Sides, Transport, Wiring};
pub use endpoint::EndpointError;
pub use open::{cleanup_stale, names_taken, open_node, NodeError};
pub use ports::{FrameSink, FrameSource, MemoryPort, PortError};
pub use registry::{open, Egress, Endpoint, Ingress, OpenError, Sessions, TransportArgs, TransportArgsError, TransportReports, Transports, endpoint_syntax};
pub use udp::Payload;

pub use ipc::{
    cleanup_dead_nodes, cleanup_dead_runs, set_log_level, CleanupError, Port, CleanupReport,
    DeadPeer, FailedCleanup, FramePublisher, FrameRecvError, FrameSendError, FrameSubscriber,
    IpcConfig, IpcLogLevel, IpcNode, IpcPayload, NodeOpenError, PublisherOpenError, PublisherStats, Role,
    RunId, RunIdError, ServiceOpenError, SubscriberOpenError, SubscriberStats, MAX_NODES_PER_CHANNEL,
    MAX_PUBLISHERS_PER_CHANNEL, MAX_SUBSCRIBERS_PER_CHANNEL, SUBSCRIBER_BUFFER_FRAMES,
};
