//! The receiving end of a channel.

use iceoryx2::node::Node;
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::update_connections::{ConnectionFailure, UpdateConnections as _};
use iceoryx2::port::ReceiveError;
use iceoryx2::prelude::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use super::service::{open_checked, ServiceOpenError};
use super::IpcPayload;
use super::{
    Port, Ipc, IpcConfig, RunId, MAX_SUBSCRIBERS_PER_CHANNEL, SUBSCRIBER_BUFFER_FRAMES,
};
use crate::sample::FrameSample;

/// The subscribing end of a channel. Not `Send`: create it on the thread
/// that receives.
#[derive(Debug)]
pub struct FrameSubscriber<T: IpcPayload = FrameSample> {
    // Declared before `service` so that the port is dropped first.
    port: Subscriber<Ipc, T, ()>,
    service: PortFactory<Ipc, T, ()>,
    run: RunId,
    channel: Port,
    stats: SubscriberStats,
    config: IpcConfig,
}

/// Counters of one subscriber since it was opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SubscriberStats {
    /// Frames received.
    pub received: u64,
}

/// Why [`IpcNode::subscriber`](super::IpcNode::subscriber) failed.
#[derive(Debug, thiserror::Error)]
pub enum SubscriberOpenError {
    /// The channel's service could not be opened (incompatible, or another
    /// cause).
    #[error(transparent)]
    Open(#[from] ServiceOpenError),
    /// The channel already has its maximum number of subscribers.
    #[error(
        "service `{service}` of run `{run}` already has {max} subscribers: is another {consumer} of this run running?"
    )]
    SubscribersTaken {
        /// The service name.
        service: String,
        /// The run.
        run: String,
        /// The role that normally subscribes to the channel.
        consumer: &'static str,
        /// The limit.
        max: usize,
    },
    /// The publisher already on the channel could not be attached (its
    /// shared memory could not be mapped).
    #[error(
        "cannot attach to the publisher of service `{service}` of run `{run}` (iceoryx2: {source})"
    )]
    Connect {
        /// The service name.
        service: String,
        /// The run.
        run: String,
        /// The iceoryx2 failure.
        #[source]
        source: ConnectionFailure,
    },
    /// The subscriber port could not be created.
    #[error(
        "cannot create a subscriber of service `{service}` of run `{run}` (iceoryx2: {source})"
    )]
    Port {
        /// The service name.
        service: String,
        /// The run.
        run: String,
        /// The iceoryx2 failure.
        #[source]
        source: SubscriberCreateError,
    },
}

/// Why a frame could not be received.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameRecvError {
    /// A new publisher appeared but could not be connected (its shared
    /// memory could not be mapped); frames from it are not received until a
    /// later call succeeds.
    #[error("cannot receive on `netfi/{run}/{channel}` (iceoryx2: {source})")]
    Receive {
        /// The run.
        run: RunId,
        /// The channel.
        channel: Port,
        /// The iceoryx2 failure.
        #[source]
        source: ReceiveError,
    },
}

impl<T: IpcPayload> FrameSubscriber<T> {
    pub(super) fn open(
        node: &Node<Ipc>,
        config: &IpcConfig,
        channel: Port,
    ) -> Result<Self, SubscriberOpenError> {
        let service_name = config.service_name(channel);
        let run = config.run_id();
        let service = open_checked::<T>(node, config, channel)?;
        let port = service
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER_FRAMES)
            .create()
            .map_err(|source| match source {
                SubscriberCreateError::ExceedsMaxSupportedSubscribers => {
                    SubscriberOpenError::SubscribersTaken {
                        service: service_name.clone(),
                        run: run.to_string(),
                        consumer: channel.consumer().as_str(),
                        max: MAX_SUBSCRIBERS_PER_CHANNEL,
                    }
                }
                source => SubscriberOpenError::Port {
                    service: service_name.clone(),
                    run: run.to_string(),
                    source,
                },
            })?;
        // Attach to the publisher already present now rather than at the
        // first receive: until then its frames queue up unseen and, once the
        // queue is full, are dropped without the publisher being told.
        port.update_connections()
            .map_err(|source| SubscriberOpenError::Connect {
                service: service_name.clone(),
                run: run.to_string(),
                source,
            })?;
        Ok(Self {
            port,
            service,
            run: run.clone(),
            channel,
            stats: SubscriberStats::default(),
            config: config.clone(),
        })
    }

    /// Takes the oldest queued frame, copied out of shared memory, or `None`
    /// when the queue is empty. Never blocks. Each call also attaches to a
    /// publisher that appeared since the last one: poll continuously, or
    /// frames of a publisher that exits before the next poll are lost with
    /// it.
    pub fn try_recv(&mut self) -> Result<Option<T>, FrameRecvError> {
        self.recv_with(|frame| *frame)
    }

    /// Takes the oldest queued frame and lends it to `read` in place, without
    /// copying; the sample is released when `read` returns. `None` when the
    /// queue is empty. Never blocks.
    pub fn recv_with<R, F: FnOnce(&T) -> R>(
        &mut self,
        read: F,
    ) -> Result<Option<R>, FrameRecvError> {
        match self.port.receive() {
            Ok(Some(sample)) => {
                self.stats.received += 1;
                Ok(Some(read(sample.payload())))
            }
            Ok(None) => Ok(None),
            Err(source) => Err(FrameRecvError::Receive {
                run: self.run.clone(),
                channel: self.channel,
                source,
            }),
        }
    }

    /// Publishers registered on the channel (0 or 1). A killed publisher
    /// stays counted until it is reaped ([`IpcNode::reap_dead_peers`]);
    /// frames it sent before dying remain receivable.
    ///
    /// [`IpcNode::reap_dead_peers`]: super::IpcNode::reap_dead_peers
    pub fn peers_connected(&self) -> usize {
        self.service.dynamic_config().number_of_publishers()
    }

    /// Who publishes on the channel now: each publisher's node as
    /// `role (executable, pid N)` or `node \`name\` (…)`. Lists the run's
    /// nodes: for reports, never per frame.
    pub fn publishers(&self) -> Vec<String> {
        use iceoryx2::node::{NodeState, NodeView};
        use iceoryx2::prelude::CallbackProgression;
        let mut ids = Vec::new();
        self.service.dynamic_config().list_publishers(|d| {
            ids.push(d.node_id);
            CallbackProgression::Continue
        });
        let mut out = Vec::new();
        let _ = iceoryx2::node::Node::<Ipc>::list(self.config.iceoryx2(), |state| {
            if let NodeState::Alive(v) = &state {
                if ids.contains(v.id()) {
                    out.push(super::liveness::describe(&self.config, v.details()).to_string());
                }
            }
            CallbackProgression::Continue
        });
        out
    }

    /// Counters since the subscriber was opened.
    pub fn stats(&self) -> SubscriberStats {
        self.stats
    }

    /// The queue capacity in frames.
    pub fn capacity(&self) -> usize {
        self.port.buffer_size()
    }

    /// The channel this subscriber receives from.
    pub fn channel(&self) -> Port {
        self.channel
    }

    /// The run this subscriber belongs to.
    pub fn run_id(&self) -> &RunId {
        &self.run
    }
}
