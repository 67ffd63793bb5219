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
mod liveness;
mod node;
mod publisher;
mod service;
mod subscriber;
pub mod video;

use core::fmt;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use std::path::{Path, PathBuf};

use crate::host::private_dir::{self, PrivateDir, PrivateDirError};
use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, LogLevel, SemanticString};

pub use liveness::{
    cleanup_dead_nodes, cleanup_dead_runs, remove_dead_run_files, remove_run_segment_if_unused, CleanupError, CleanupReport, DeadPeer,
    FailedCleanup,
};
pub use node::{IpcNode, NodeOpenError};
pub use publisher::{FramePublisher, FrameSendError, PublisherOpenError, PublisherStats};
pub use subscriber::{FrameRecvError, FrameSubscriber, SubscriberOpenError, SubscriberStats};

/// The iceoryx2 service type of every port (see the module docs).
type Ipc = iceoryx2::service::ipc::Service;

/// A payload a channel carries: a fixed-size `#[repr(C)]` sample with a
/// stable type name and an all-zero value to loan with.
pub trait IpcPayload: iceoryx2::prelude::ZeroCopySend + Copy + core::fmt::Debug + 'static {
    /// An all-zero sample.
    const ZERO: Self;
    /// The iceoryx2 type name.
    const TYPE_NAME: &'static str;
}

impl IpcPayload for crate::sample::FrameSample {
    const ZERO: Self = crate::sample::FrameSample::ZERO;
    const TYPE_NAME: &'static str = crate::sample::FrameSample::TYPE_NAME;
}

impl IpcPayload for crate::sample::FeedbackSample {
    const ZERO: Self = crate::sample::FeedbackSample::ZERO;
    const TYPE_NAME: &'static str = crate::sample::FeedbackSample::TYPE_NAME;
}

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

/// Prefix of every iceoryx2 file of netfi; `u<uid>_`, the run id and `_`
/// follow.
const FILE_PREFIX: &str = "netfi_";

/// This user's file prefix: `netfi_u<uid>_`.
fn user_prefix() -> String {
    // SAFETY: geteuid has no preconditions.
    format!("{FILE_PREFIX}u{}_", unsafe { libc::geteuid() })
}

/// The environment variable through which a process tells the processes
/// it starts which iceoryx2 root directory the run uses, so that all of a
/// run's processes agree on it even where the usual one was taken.
pub const IPC_ROOT_ENV: &str = "NETFI_IPC_ROOT";

/// The longest root directory accepted, in bytes: iceoryx2's paths (root,
/// sub-directory, prefix, run id and its own names) must stay within its
/// path limit.
const ROOT_MAX_LEN: usize = 96;

/// This user's iceoryx2 root directory, with a trailing `/` (see
/// [`user_root_dir_resolved`]); where none can be had, the usual name,
/// which opening a node then reports.
pub fn user_root_dir() -> PathBuf {
    let dir = ensure_user_root_dir().unwrap_or_else(|_| usual_root_dirs().pop().unwrap_or_default());
    let mut text = dir.into_os_string();
    text.push("/");
    text.into()
}

/// This user's iceoryx2 root directory, private (0700, this user's, closed
/// to others), created if missing, chosen in this order:
///
/// 1. [`IPC_ROOT_ENV`], as set by the process that started this one;
/// 2. `$XDG_RUNTIME_DIR/netfi-iceoryx2`, where `$XDG_RUNTIME_DIR` is a
///    private directory of this user;
/// 3. `/tmp/netfi-iceoryx2-<uid>`;
/// 4. where those are taken by someone else (another owner, or open to
///    others): the first `/tmp/netfi-iceoryx2-<uid>-XXXXXX` of this user,
///    made if none exists, with a warning naming the owner of the taken
///    one.
pub fn user_root_dir_resolved() -> Result<PrivateDir, PrivateDirError> {
    let named = std::env::var_os(IPC_ROOT_ENV).filter(|e| !e.is_empty()).map(PathBuf::from).filter(|p| usable_root(p));
    private_dir::resolve_named(named, &usual_root_dirs(), Path::new("/tmp"), &format!("netfi-iceoryx2-{}", private_dir::uid()))
}

/// The usual places of the root that iceoryx2 can use, in order of
/// preference.
fn usual_root_dirs() -> Vec<PathBuf> {
    let tmp = PathBuf::from(format!("/tmp/netfi-iceoryx2-{}", private_dir::uid()));
    private_dir::xdg_runtime_dir().map(|d| d.join("netfi-iceoryx2")).into_iter().chain([tmp]).filter(|p| usable_root(p)).collect()
}

/// Whether iceoryx2 can have its files under `dir`.
fn usable_root(dir: &Path) -> bool {
    dir.is_absolute() && dir.as_os_str().len() <= ROOT_MAX_LEN && iceoryx2::prelude::Path::new(dir.as_os_str().as_encoded_bytes()).is_ok()
}

/// The root this process resolved, while it stays private.
static ROOT: std::sync::Mutex<Option<PathBuf>> = std::sync::Mutex::new(None);

/// This user's root directory, resolved once per process (again only if it
/// was removed meanwhile); a taken usual name is warned of once.
fn ensure_user_root_dir() -> Result<PathBuf, PrivateDirError> {
    let mut root = ROOT.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(dir) = root.as_ref().filter(|d| private_dir::is_private(d)) {
        return Ok(dir.clone());
    }
    let dir = user_root_dir_resolved()?;
    if let Some(w) = dir.warning() {
        eprintln!("WARNING: iceoryx2's directory: {w}");
    }
    *root = Some(dir.path.clone());
    Ok(dir.path)
}

/// Identifier of one run: 1 to [`RunId::MAX_LEN`] ASCII letters, digits,
/// `_` or `-`. It names every iceoryx2 resource of the run, so runs with
/// different ids never interfere. Cloning is cheap (shared string), so
/// errors on the hot path can carry it without allocating.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunId(Arc<str>);

impl RunId {
    /// Longest accepted run id, in bytes.
    pub const MAX_LEN: usize = 48;

    /// Validates `value` as a run id.
    pub fn new(value: &str) -> Result<Self, RunIdError> {
        if value.is_empty() {
            return Err(RunIdError::Empty);
        }
        if value.len() > Self::MAX_LEN {
            return Err(RunIdError::TooLong {
                run: value.to_owned(),
                len: value.len(),
            });
        }
        if let Some((index, ch)) = value
            .char_indices()
            .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_' || c == '-'))
        {
            return Err(RunIdError::InvalidCharacter {
                run: value.to_owned(),
                ch,
                index,
            });
        }
        Ok(Self(Arc::from(value)))
    }

    /// The run id as written.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for RunId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl FromStr for RunId {
    type Err = RunIdError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

/// Why a string is not a valid [`RunId`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RunIdError {
    /// The run id is the empty string.
    #[error("run id is empty; use 1 to 48 ASCII letters, digits, `_` or `-`")]
    Empty,
    /// The run id is longer than [`RunId::MAX_LEN`] bytes.
    #[error("run id `{run}` is {len} bytes long; at most 48 are accepted")]
    TooLong {
        /// The rejected run id.
        run: String,
        /// Its length in bytes.
        len: usize,
    },
    /// The run id contains a character other than an ASCII letter, digit,
    /// `_` or `-`.
    #[error(
        "run id `{run}` contains {ch:?} at byte {index}; only ASCII letters, digits, `_` and `-` are accepted"
    )]
    InvalidCharacter {
        /// The rejected run id.
        run: String,
        /// The first offending character.
        ch: char,
        /// Its byte offset in `run`.
        index: usize,
    },
}

/// One hop of the pipeline, carried by one publish/subscribe service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    /// Console → emulator: the frames as the console sent them.
    Console,
    /// Emulator → simulator: the frames that survived the scenario.
    Emulator,
    /// Console → simulator directly: the same frames without the emulator,
    /// the baseline hop measured in the same run.
    Direct,
    /// Robot → emulator: the robot's feedback
    /// ([`FeedbackSample`](crate::sample::FeedbackSample)), one per command
    /// it received.
    Feedback,
    /// Emulator → console: the feedback that survived the return scenario.
    FeedbackOut,
    /// Robot → emulator: video frames, `[u8]` with a
    /// [`VideoHeader`](crate::sample::VideoHeader) ([`video`]).
    Video,
    /// Emulator → console: the video frames that survived the video scenario.
    VideoOut,
}

impl Channel {
    /// Every channel: the pipeline in order, the direct baseline, then the
    /// feedback loop.
    pub const ALL: [Channel; 7] =
        [Channel::Console, Channel::Emulator, Channel::Direct, Channel::Feedback, Channel::FeedbackOut, Channel::Video, Channel::VideoOut];

    /// The last component of the service name.
    pub fn as_str(self) -> &'static str {
        match self {
            Channel::Console => "console",
            Channel::Emulator => "emulator",
            Channel::Direct => "direct",
            Channel::Feedback => "feedback",
            Channel::FeedbackOut => "feedback_out",
            Channel::Video => "video",
            Channel::VideoOut => "video_out",
        }
    }

    /// The role that publishes on this channel.
    pub fn producer(self) -> Role {
        match self {
            Channel::Console | Channel::Direct => Role::Console,
            Channel::Emulator | Channel::FeedbackOut | Channel::VideoOut => Role::Emulator,
            Channel::Feedback | Channel::Video => Role::Simulator,
        }
    }

    /// The role that subscribes to this channel.
    pub fn consumer(self) -> Role {
        match self {
            Channel::Console | Channel::Feedback | Channel::Video => Role::Emulator,
            Channel::Emulator | Channel::Direct => Role::Simulator,
            Channel::FeedbackOut | Channel::VideoOut => Role::Console,
        }
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What a process is in the run; names its iceoryx2 node, so that a dead
/// peer can be reported by role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// The surgeon-side command source.
    Console,
    /// The fault injector.
    Emulator,
    /// The patient-side receiver.
    Simulator,
    /// Anything else attached to the run: a recorder, an inspector, a test.
    Tool,
}

impl Role {
    /// All roles.
    pub const ALL: [Role; 4] = [Role::Console, Role::Emulator, Role::Simulator, Role::Tool];

    /// The lowercase name used in node names and messages.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Console => "console",
            Role::Emulator => "emulator",
            Role::Simulator => "simulator",
            Role::Tool => "tool",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The explicit iceoryx2 configuration of one run.
#[derive(Debug, Clone)]
pub struct IpcConfig {
    run: RunId,
    iceoryx2: Config,
}

impl IpcConfig {
    /// Builds the configuration of run `run` from iceoryx2's compiled-in
    /// defaults; no configuration file is read.
    pub fn new(run: RunId) -> Self {
        let mut config = Config::default();
        let prefix = format!("{}{run}_", user_prefix());
        // A validated run id is at most 48 bytes of [A-Za-z0-9_-], which is
        // always a valid file name.
        config.global.prefix = FileName::new(prefix.as_bytes())
            .expect("a validated run id always forms a valid iceoryx2 file prefix");
        let root = user_root_dir();
        config.global.set_root_path(
            &iceoryx2::prelude::Path::new(root.as_os_str().as_encoded_bytes())
                .expect("the root directory is checked to be a valid iceoryx2 path when chosen"),
        );
        config.global.node.cleanup_dead_nodes_on_creation = false;
        config.global.node.cleanup_dead_nodes_on_destruction = false;
        config.global.service.cleanup_dead_nodes_on_open = false;

        // The service builders set every limit explicitly as well; setting the
        // defaults too keeps any service opened through this configuration
        // within the same limits.
        let pubsub = &mut config.defaults.publish_subscribe;
        pubsub.max_publishers = MAX_PUBLISHERS_PER_CHANNEL;
        pubsub.max_subscribers = MAX_SUBSCRIBERS_PER_CHANNEL;
        pubsub.max_nodes = MAX_NODES_PER_CHANNEL;
        pubsub.subscriber_max_buffer_size = SUBSCRIBER_BUFFER_FRAMES;
        pubsub.subscriber_max_borrowed_samples = SUBSCRIBER_MAX_BORROWED_SAMPLES;
        pubsub.publisher_max_loaned_samples = PUBLISHER_MAX_LOANED_SAMPLES;
        pubsub.publisher_history_size = HISTORY_FRAMES;
        pubsub.enable_safe_overflow = false;
        pubsub.backpressure_strategy = iceoryx2::prelude::BackpressureStrategy::DiscardData;

        Self {
            run,
            iceoryx2: config,
        }
    }

    /// The run this configuration belongs to.
    pub fn run_id(&self) -> &RunId {
        &self.run
    }

    /// The file prefix of every iceoryx2 resource of the run
    /// (`netfi_u<uid>_<run>_`).
    pub fn prefix(&self) -> &str {
        self.iceoryx2.global.prefix.as_str()
    }

    /// The service name of `channel`: `netfi/<run>/<channel>`.
    pub fn service_name(&self, channel: Channel) -> String {
        format!("netfi/{}/{}", self.run, channel)
    }

    /// The node name of a process with `role`: `netfi/<run>/<role>`.
    pub fn node_name(&self, role: Role) -> String {
        format!("netfi/{}/{}", self.run, role)
    }

    /// The role encoded in a node name of this run, if it is one.
    pub(crate) fn role_of_node_name(&self, node_name: &str) -> Option<Role> {
        Role::ALL
            .into_iter()
            .find(|role| node_name == self.node_name(*role))
    }

    /// The iceoryx2 configuration itself, for diagnostics.
    pub fn iceoryx2(&self) -> &Config {
        &self.iceoryx2
    }
}

/// Verbosity of iceoryx2's own log on stderr.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IpcLogLevel {
    /// Every resource created or destroyed.
    Trace,
    /// Every error result, including expected ones.
    Debug,
    /// Informational messages.
    Info,
    /// Recoverable misbehaviour; the default.
    Warn,
    /// Severe but handled failures.
    Error,
    /// Only messages that precede a panic.
    Fatal,
}

impl FromStr for IpcLogLevel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "trace" => Ok(Self::Trace),
            "debug" => Ok(Self::Debug),
            "info" => Ok(Self::Info),
            "warn" | "warning" => Ok(Self::Warn),
            "error" => Ok(Self::Error),
            "fatal" => Ok(Self::Fatal),
            other => Err(format!(
                "unknown iceoryx2 log level `{other}`; expected trace, debug, info, warn, error or fatal"
            )),
        }
    }
}

impl From<IpcLogLevel> for LogLevel {
    fn from(level: IpcLogLevel) -> Self {
        match level {
            IpcLogLevel::Trace => LogLevel::Trace,
            IpcLogLevel::Debug => LogLevel::Debug,
            IpcLogLevel::Info => LogLevel::Info,
            IpcLogLevel::Warn => LogLevel::Warn,
            IpcLogLevel::Error => LogLevel::Error,
            IpcLogLevel::Fatal => LogLevel::Fatal,
        }
    }
}

/// Set once a level has been chosen, explicitly or by default.
static LOG_LEVEL_CHOSEN: AtomicBool = AtomicBool::new(false);

/// Sets iceoryx2's log level for the whole process.
pub fn set_log_level(level: IpcLogLevel) {
    LOG_LEVEL_CHOSEN.store(true, Ordering::Relaxed);
    iceoryx2::prelude::set_log_level(level.into());
}

/// Applies the default log level (warn, or `IOX2_LOG_LEVEL`) unless a level
/// was already chosen; iceoryx2's own default would be info.
fn init_log_level() {
    if !LOG_LEVEL_CHOSEN.swap(true, Ordering::Relaxed) {
        iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Warn);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_id_accepts_the_documented_alphabet() {
        for ok in ["a", "run-1", "R_2024-05-01", &"x".repeat(RunId::MAX_LEN)] {
            assert_eq!(RunId::new(ok).unwrap().as_str(), ok);
        }
    }

    #[test]
    fn run_id_rejects_the_rest() {
        assert_eq!(RunId::new(""), Err(RunIdError::Empty));
        assert!(matches!(
            RunId::new(&"x".repeat(RunId::MAX_LEN + 1)),
            Err(RunIdError::TooLong { len: 49, .. })
        ));
        for (bad, ch, index) in [
            ("a/b", '/', 1),
            ("a b", ' ', 1),
            (".", '.', 0),
            ("é", 'é', 0),
        ] {
            assert_eq!(
                RunId::new(bad),
                Err(RunIdError::InvalidCharacter {
                    run: bad.to_owned(),
                    ch,
                    index
                })
            );
        }
    }

    #[test]
    fn config_is_explicit_and_prefixed_per_run() {
        let config = IpcConfig::new(RunId::new("r1").unwrap());
        let uid = unsafe { libc::geteuid() };
        assert_eq!(config.prefix(), format!("netfi_u{uid}_r1_"));
        let root = user_root_dir();
        assert_eq!(config.iceoryx2().global.root_path().to_string(), root.to_string_lossy());
        assert!(private_dir::is_private(&root));
        assert_eq!(config.service_name(Channel::Console), "netfi/r1/console");
        assert_eq!(config.node_name(Role::Simulator), "netfi/r1/simulator");
        assert_eq!(
            config.role_of_node_name("netfi/r1/emulator"),
            Some(Role::Emulator)
        );
        assert_eq!(config.role_of_node_name("netfi/r2/emulator"), None);
        let iox = config.iceoryx2();
        assert!(!iox.defaults.publish_subscribe.enable_safe_overflow);
        assert_eq!(
            iox.defaults.publish_subscribe.subscriber_max_buffer_size,
            SUBSCRIBER_BUFFER_FRAMES
        );
        assert!(!iox.global.node.cleanup_dead_nodes_on_creation);
    }

    #[test]
    fn log_level_parses() {
        assert_eq!("WARN".parse::<IpcLogLevel>(), Ok(IpcLogLevel::Warn));
        assert!("loud".parse::<IpcLogLevel>().is_err());
    }
}
