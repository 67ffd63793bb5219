//! The explicit iceoryx2 configuration of one run, and iceoryx2's log level.

use super::names::{Port, Role, RunId};
use super::root::{user_prefix, user_root_dir};
use super::{
    HISTORY_FRAMES, MAX_NODES_PER_CHANNEL, MAX_PUBLISHERS_PER_CHANNEL, MAX_SUBSCRIBERS_PER_CHANNEL, PUBLISHER_MAX_LOANED_SAMPLES, SUBSCRIBER_BUFFER_FRAMES,
    SUBSCRIBER_MAX_BORROWED_SAMPLES,
};
use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, LogLevel, SemanticString};
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};

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

    /// The directory of the run's iceoryx2 files (this user's private root):
    /// a client must use the same root and prefix to join the run.
    pub fn root(&self) -> std::path::PathBuf {
        use iceoryx2::prelude::SemanticString;
        std::path::PathBuf::from(String::from_utf8_lossy(self.iceoryx2.global.root_path().as_bytes()).into_owned())
    }

    /// The service name of `channel`: `netfi/<run>/<channel>`.
    pub fn service_name(&self, channel: Port) -> String {
        self.run.resource_name(channel)
    }

    /// The node name of a process with `role`: `netfi/<run>/<role>`.
    pub fn node_name(&self, role: Role) -> String {
        self.run.resource_name(role)
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
pub(super) fn init_log_level() {
    if !LOG_LEVEL_CHOSEN.swap(true, Ordering::Relaxed) {
        iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Warn);
    }
}
