//! One process's membership in a run: its iceoryx2 node, the factory of its
//! endpoints, and its view of signals.

use core::time::Duration;
use std::mem::ManuallyDrop;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use iceoryx2::node::{Node, NodeCreationFailure, NodeWaitFailure};
use iceoryx2::prelude::{NodeBuilder, NodeName, SignalHandlingMode};

use super::liveness::{cleanup_dead_nodes, CleanupError, CleanupReport};
use super::publisher::{FramePublisher, PublisherOpenError};
use super::subscriber::{FrameSubscriber, SubscriberOpenError};
use super::{init_log_level, Port, Ipc, IpcConfig, IpcPayload, Role};

/// Latched once SIGINT or SIGTERM has been seen: iceoryx2 reports a signal
/// only once, and every node of the process must keep seeing the request.
static TERMINATION_REQUESTED: AtomicBool = AtomicBool::new(false);

/// A process's node in a run. Open one per process, then open its
/// endpoints from it.
#[derive(Debug)]
pub struct IpcNode {
    /// Dropped by hand first in `Drop`, so the run's last node can then
    /// remove the run's management segment.
    pub(super) node: ManuallyDrop<Node<Ipc>>,
    pub(super) config: IpcConfig,
    role: Role,
    startup_cleanup: CleanupReport,
}

/// Why [`IpcNode::open`] failed.
#[derive(Debug, thiserror::Error)]
pub enum NodeOpenError {
    /// Scanning the run for nodes left by killed processes failed.
    #[error("cannot open the {role} node of run `{run}`: {source}")]
    Cleanup {
        /// The role of the node being opened.
        role: Role,
        /// The run.
        run: String,
        /// What went wrong while scanning.
        #[source]
        source: CleanupError,
    },
    /// No private iceoryx2 root directory of this user could be had
    /// ([`user_root_dir`](super::user_root_dir)): creating one failed.
    #[error("cannot open the {role} node of run `{run}`: iceoryx2's directory: {source}")]
    RootDir {
        /// The role of the node being opened.
        role: Role,
        /// The run.
        run: String,
        /// Why the directory could not be had.
        #[source]
        source: crate::host::private_dir::PrivateDirError,
    },
    /// A shared-memory file with this run's names belongs to another user
    /// (planted, or left by a version that did not name files per user):
    /// iceoryx2 would wait on it, or share it; refused at once.
    #[error("cannot open the {role} node of run `{run}`: {} belongs to uid {uid}, not to this user; remove it or use another run id", path.display())]
    Foreign {
        /// The role of the node being opened.
        role: Role,
        /// The run.
        run: String,
        /// The file.
        path: PathBuf,
        /// Its owner.
        uid: u32,
    },
    /// iceoryx2 could not create the node (permissions on its directories
    /// under the root directory, or a corrupted system).
    #[error("cannot create the {role} node of run `{run}` (iceoryx2: {source})")]
    Create {
        /// The role of the node being opened.
        role: Role,
        /// The run.
        run: String,
        /// The iceoryx2 failure.
        #[source]
        source: NodeCreationFailure,
    },
}

impl IpcNode {
    /// Joins the run of `config` as `role`.
    ///
    /// First removes what processes of this run killed earlier left behind
    /// (see [`IpcNode::startup_cleanup`]), so that a restarted process finds
    /// its channel free; then creates the node and installs iceoryx2's
    /// signal capture (see the module docs).
    pub fn open(config: &IpcConfig, role: Role) -> Result<Self, NodeOpenError> {
        init_log_level();
        let run = config.run_id().to_string();
        super::ensure_user_root_dir().map_err(|source| NodeOpenError::RootDir { role, run: run.clone(), source })?;
        if let Some((path, uid)) = foreign_shm(config.prefix()) {
            return Err(NodeOpenError::Foreign { role, run, path, uid });
        }
        let startup_cleanup =
            cleanup_dead_nodes(config).map_err(|source| NodeOpenError::Cleanup {
                role,
                run: run.clone(),
                source,
            })?;

        // The run's management segment, made private before iceoryx2
        // would make it open to all (see `mgmt`).
        super::mgmt::create_private(config.prefix());
        // At most 6 + 48 + 1 + 9 bytes of [A-Za-z0-9_/-]: always a valid
        // node name.
        let node_name = NodeName::new(&config.node_name(role))
            .expect("a validated run id always forms a valid node name");
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(config.iceoryx2())
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Ipc>()
            .map_err(|source| NodeOpenError::Create { role, run, source })?;

        let this = Self {
            node: ManuallyDrop::new(node),
            config: config.clone(),
            role,
            startup_cleanup,
        };
        // Asking once installs iceoryx2's handlers now rather than at the
        // first shared-memory allocation, so that Ctrl-C behaves the same
        // in every process from here on.
        this.termination_requested();
        make_private(config.prefix());
        Ok(this)
    }

    /// The iceoryx2 node, for the services opened beside the channels.
    pub(super) fn raw(&self) -> &Node<Ipc> {
        &self.node
    }

    /// The run configuration.
    pub fn config(&self) -> &IpcConfig {
        &self.config
    }

    /// The role this node was opened with.
    pub fn role(&self) -> Role {
        self.role
    }

    /// The dead nodes of this run that [`IpcNode::open`] found and removed.
    pub fn startup_cleanup(&self) -> &CleanupReport {
        &self.startup_cleanup
    }

    /// Opens the publishing end of `channel`, creating the channel if this
    /// process is the first to use it.
    pub fn publisher(&self, channel: Port) -> Result<FramePublisher, PublisherOpenError> {
        self.publisher_of::<crate::sample::FrameSample>(channel)
    }

    /// Opens the publishing end of `channel` carrying payload `T` (the
    /// feedback channels carry [`FeedbackSample`](crate::sample::FeedbackSample)).
    pub fn publisher_of<T: IpcPayload>(&self, channel: Port) -> Result<FramePublisher<T>, PublisherOpenError> {
        let p = FramePublisher::open(&self.node, &self.config, channel);
        make_private(self.config.prefix());
        p
    }

    /// Opens a subscribing end of `channel`, creating the channel if this
    /// process is the first to use it.
    pub fn subscriber(&self, channel: Port) -> Result<FrameSubscriber, SubscriberOpenError> {
        self.subscriber_of::<crate::sample::FrameSample>(channel)
    }

    /// Opens a subscribing end of `channel` carrying payload `T`.
    pub fn subscriber_of<T: IpcPayload>(&self, channel: Port) -> Result<FrameSubscriber<T>, SubscriberOpenError> {
        let s = FrameSubscriber::open(&self.node, &self.config, channel);
        make_private(self.config.prefix());
        s
    }

    /// Finds the nodes of this run whose process died without cleaning up
    /// (kill -9, crash, power loss of a container), removes their resources
    /// and reports them.
    ///
    /// Until this runs, a killed peer's port stays registered: the
    /// endpoints' `peers_connected` still count it, and a publisher keeps
    /// filling a killed subscriber's queue until [`FrameSendError::QueueFull`].
    /// It lists the run's node directory and checks one lock per node:
    /// call it a few times per second from the service loop, never per frame.
    /// Any process of the run may reap; each of several concurrent reapers
    /// reports the dead peer, and one may wait up to 100 ms for another.
    ///
    /// [`FrameSendError::QueueFull`]: super::FrameSendError::QueueFull
    pub fn reap_dead_peers(&self) -> Result<CleanupReport, CleanupError> {
        cleanup_dead_nodes(&self.config)
    }

    /// Whether SIGINT or SIGTERM has been received by this process. Latched:
    /// once true it stays true. Costs an uncontended mutex and an atomic, no
    /// system call; cheap enough for every loop iteration, though once per
    /// millisecond is plenty.
    pub fn termination_requested(&self) -> bool {
        if TERMINATION_REQUESTED.load(Ordering::Relaxed) {
            return true;
        }
        // A zero wait does not sleep; it only asks iceoryx2's signal handler
        // whether SIGINT or SIGTERM was the last signal received.
        match self.node.wait(Duration::ZERO) {
            Err(NodeWaitFailure::TerminationRequest) => {
                TERMINATION_REQUESTED.store(true, Ordering::Relaxed);
                true
            }
            Ok(()) | Err(NodeWaitFailure::Interrupt) => false,
        }
    }
}

impl Drop for IpcNode {
    fn drop(&mut self) {
        // SAFETY: the node is dropped exactly once, here, and not used after.
        unsafe { ManuallyDrop::drop(&mut self.node) };
        // The last node of the run removes the run's management segment,
        // which iceoryx2 keeps for good (one file per run otherwise).
        super::liveness::remove_mgmt_segment_if_unused(&self.config);
    }
}

/// A file in `/dev/shm` with `prefix` that another user owns.
fn foreign_shm(prefix: &str) -> Option<(PathBuf, u32)> {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    std::fs::read_dir(super::liveness::SHM_DIR).ok()?.filter_map(|e| e.ok()).find_map(|e| {
        let name = e.file_name();
        if !name.to_str().is_some_and(|n| n.starts_with(prefix)) {
            return None;
        }
        let meta = std::fs::symlink_metadata(e.path()).ok()?;
        (meta.uid() != uid).then(|| (e.path(), meta.uid()))
    })
}

/// Takes group and other permissions off this user's shared-memory files
/// with `prefix` (iceoryx2 creates the management segment 0666): the
/// processes of a run are all this user's.
pub(super) fn make_private(prefix: &str) {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    let Ok(rd) = std::fs::read_dir(super::liveness::SHM_DIR) else { return };
    for e in rd.filter_map(|e| e.ok()) {
        if !e.file_name().to_str().is_some_and(|n| n.starts_with(prefix)) {
            continue;
        }
        let Ok(meta) = std::fs::symlink_metadata(e.path()) else { continue };
        if meta.is_file() && meta.uid() == uid && meta.mode() & 0o077 != 0 {
            let _ = std::fs::set_permissions(e.path(), std::fs::Permissions::from_mode(meta.mode() & 0o700));
        }
    }
}
