//! iceoryx2 zero-copy publish/subscribe between the processes of one run.
//!
//! # Service type
//!
//! All ports use `iceoryx2::service::ipc::Service`: inter-process, with the
//! single-threaded port policy, so a send or receive takes no mutex. The price
//! is that [`FramePublisher`] and [`FrameSubscriber`] are not `Send`: create
//! each endpoint on the thread that uses it (an [`IpcNode`] itself may be
//! moved). `ipc_threadsafe` would only be needed to share one port between
//! threads, which none of the services does.
//!
//! # Queues and limits (fixed at start-up, identical in every process)
//!
//! | setting | value | why |
//! |---|---|---|
//! | subscriber queue | [`SUBSCRIBER_BUFFER_FRAMES`] = 16 384 frames | a receiver may stall 163 ms at 100 kHz (16 s at 1 kHz) and lose nothing |
//! | safe overflow | off | an overwritten frame would be a silent, unrecorded loss |
//! | full queue | the frame is not delivered to that subscriber; `send` returns [`FrameSendError::QueueFull`] | the sender never blocks (console timing, emulator release times stay honest) and the loss is counted |
//! | history | 0 | a restarted subscriber must never receive old commands |
//! | publishers per channel | [`MAX_PUBLISHERS_PER_CHANNEL`] = 1 | a second console (or emulator) in one run is a mistake and fails to open |
//! | subscribers per channel | [`MAX_SUBSCRIBERS_PER_CHANNEL`] = 2 | the next stage plus one observer |
//! | nodes per channel | [`MAX_NODES_PER_CHANNEL`] = 8 | the participants plus dead ones awaiting clean-up |
//! | loans | 1 per publisher, 1 borrowed sample per subscriber | every sample is written and sent, or read and released, within one call |
//!
//! The publisher's shared-memory pool holds
//! `MAX_SUBSCRIBERS_PER_CHANNEL × (SUBSCRIBER_BUFFER_FRAMES + 1) + 1` samples
//! (about 8 MiB). A frame refused by a full queue is reported to the
//! publisher; the one unreported loss is a publisher that exits before its
//! subscriber has polled once since it appeared: the frames it left unread go
//! with it. Subscribers that poll continuously never meet that case.
//!
//! # Configuration
//!
//! [`IpcConfig`] builds an `iceoryx2::config::Config` from its defaults in
//! code, never from a file (iceoryx2 would otherwise look for
//! `./config/iceoryx2.toml`, a user and a system file), with the file prefix
//! `netfi_u<uid>_<run>_` and a root directory of the user's own
//! ([`user_root_dir`]: `$XDG_RUNTIME_DIR/netfi-iceoryx2/` or
//! `/tmp/netfi-iceoryx2-<uid>/`, mode 0700, checked to be the user's and
//! closed to others before use; a replacement beside it where another
//! user took that name first; the one named by [`IPC_ROOT_ENV`] in the
//! processes a run starts), instead of iceoryx2's shared
//! `/tmp/iceoryx2/`: several users of one machine run side by side, none
//! can write into another's files, and a file another user planted under
//! this user's names is refused at once rather than waited on
//! ([`NodeOpenError::Foreign`]). The shared-memory segments in `/dev/shm`
//! are made private to the user (iceoryx2 creates its global management
//! segment world-writable), and the last node of a run to close removes
//! the run's management segment, so a run leaves nothing in `/dev/shm`.
//! The automatic dead-node clean-ups of iceoryx2 are switched off: they
//! fall back to the file-based global configuration for nodes whose
//! details are unreadable. Clean-up is explicit instead
//! ([`cleanup_dead_nodes`], [`IpcNode::reap_dead_peers`]) and reported;
//! what a run whose processes all died leaves is removed by
//! [`remove_dead_run_files`].
//!
//! # Signals
//!
//! iceoryx2 installs its own handlers for SIGINT, SIGTERM and the other
//! signals it deems non-fatal (SIGQUIT, SIGTSTP, SIGCONT, SIGTTIN, SIGTTOU,
//! SIGUSR1, SIGPROF, SIGURG, SIGVTALRM) the first time it zeroes shared
//! memory or is asked for a termination request, whatever the node's
//! `SignalHandlingMode`; from then on these signals only record themselves
//! (so Ctrl-Z and Ctrl-\ no longer stop or quit the process). Disabling its
//! signal handling would therefore make Ctrl-C silently do nothing. Nodes are created with
//! `SignalHandlingMode::HandleTerminationRequests`, the handlers are installed
//! deterministically when the [`IpcNode`] is opened, and
//! [`IpcNode::termination_requested`] latches the request so that the
//! service loop can stop cleanly (and let the ports deregister). iceoryx2
//! keeps only the last signal received, so another of the signals above
//! arriving between a Ctrl-C and the next poll hides it: poll often (every
//! loop iteration, or at least every millisecond).
//!
//! # Logging
//!
//! iceoryx2 logs to stderr. Its level defaults to warn (or `IOX2_LOG_LEVEL`
//! when set) the first time a transport object is created; [`set_log_level`]
//! overrides it.

pub mod control;
mod config;
mod liveness;
mod mgmt;
mod names;
mod node;
mod publisher;
mod root;
mod service;
mod subscriber;
mod transport;
pub mod video;

pub use config::{set_log_level, IpcConfig, IpcLogLevel};
pub use liveness::{
    cleanup_dead_nodes, cleanup_dead_runs, remove_dead_run_files, remove_run_segment_if_unused, CleanupError, CleanupReport, DeadPeer,
    FailedCleanup,
};
pub use mgmt::mgmt_segment_path;
pub use names::{Port, Role, RunId, RunIdError};
pub use transport::{Iceoryx2, Iceoryx2Args, Iceoryx2ArgsError, Iceoryx2OpenError};
pub use node::{IpcNode, NodeOpenError};
pub use publisher::{FramePublisher, FrameSendError, PublisherOpenError, PublisherStats};
pub use root::{user_root_dir, user_root_dir_resolved, IPC_ROOT_ENV};
pub use service::ServiceOpenError;
pub use subscriber::{FrameRecvError, FrameSubscriber, SubscriberOpenError, SubscriberStats};

use config::init_log_level;
use root::{ensure_user_root_dir, user_prefix, FILE_PREFIX};

/// The iceoryx2 service type of every port (see the module docs).
type Ipc = iceoryx2::service::ipc::Service;

/// A payload a port carries ([`crate::sample::Payload`]).
pub use crate::sample::Payload as IpcPayload;

/// Capacity of each subscriber's queue, in frames. A receiver can stall for
/// `SUBSCRIBER_BUFFER_FRAMES / rate` (163 ms at 100 kHz) without loss.
///
/// Kept at 16 384 for the emulator's ingress at high rates too: a console
/// that falls behind sends what it owes back to back, but its backlog is the
/// rate times the time it lost its core (a few ms: hundreds to a few
/// thousand frames), and the emulator takes faster than a console on a
/// shared core sends. The losses once seen at this ingress at 375 000
/// frames/s were frames queued while the emulator was still setting up after
/// saying it was ready (0.1–0.3 s); it now says so only once its loop runs.
/// A buffer covering that would have cost `2 × (B + 1)` samples of about
/// 200 bytes in the publisher's pool: 0.3 s at 10⁶ frames/s is 120 MB.
pub const SUBSCRIBER_BUFFER_FRAMES: usize = 16_384;
/// Publishers per channel: one producer per run.
pub const MAX_PUBLISHERS_PER_CHANNEL: usize = 1;
/// Subscribers per channel: the next stage and one observer.
pub const MAX_SUBSCRIBERS_PER_CHANNEL: usize = 2;
/// Nodes that may have a channel open at the same time, dead ones included
/// until they are cleaned up.
pub const MAX_NODES_PER_CHANNEL: usize = 8;
/// Samples a publisher may hold between loan and send.
const PUBLISHER_MAX_LOANED_SAMPLES: usize = 1;
/// Samples a subscriber may hold between receive and release.
const SUBSCRIBER_MAX_BORROWED_SAMPLES: usize = 1;
/// Frames replayed to a late subscriber: none, commands are never replayed.
const HISTORY_FRAMES: usize = 0;

#[cfg(test)]
mod tests;
