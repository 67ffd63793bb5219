//! The sending end of a channel.

use iceoryx2::node::Node;
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::{BackpressureAction, BackpressureInfo, LoanError, SendError};
use iceoryx2::prelude::{BackpressureStrategy, PortFactory as _};
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use std::mem::MaybeUninit;

use super::service::{open_checked, ServiceOpenError};
use super::IpcPayload;
use super::{
    Port, Ipc, IpcConfig, RunId, MAX_PUBLISHERS_PER_CHANNEL, PUBLISHER_MAX_LOANED_SAMPLES,
    SUBSCRIBER_BUFFER_FRAMES,
};
use crate::sample::FrameSample;

/// The publishing end of a channel. Not `Send`: create it on the thread that
/// sends.
pub struct FramePublisher<T: IpcPayload = FrameSample> {
    /// The sample the next send fills: loaned right after each send, so the
    /// loan (reclaiming what subscribers returned, across cores) is not on
    /// the path of a frame due for release. Declared first: dropped (the
    /// loan returned) before the port.
    ready: Option<SampleMutUninit<Ipc, MaybeUninit<T>, ()>>,
    // Declared before `service` so that the port is dropped first.
    port: Publisher<Ipc, T, ()>,
    service: PortFactory<Ipc, T, ()>,
    run: RunId,
    channel: Port,
    stats: PublisherStats,
}

impl<T: IpcPayload> std::fmt::Debug for FramePublisher<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FramePublisher")
            .field("run", &self.run)
            .field("channel", &self.channel)
            .field("stats", &self.stats)
            .field("sample_ready", &self.ready.is_some())
            .finish_non_exhaustive()
    }
}

/// Counters of one publisher since it was opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PublisherStats {
    /// Frames handed to the channel (delivered, refused by a full queue, or
    /// sent while nobody subscribed).
    pub sent: u64,
    /// Frames that at least one registered subscriber did not receive
    /// (each also returned [`FrameSendError::QueueFull`]).
    pub queue_full: u64,
    /// Frames sent while no subscriber was connected; they went nowhere.
    pub unsubscribed: u64,
}

/// Why [`IpcNode::publisher`](super::IpcNode::publisher) failed.
#[derive(Debug, thiserror::Error)]
pub enum PublisherOpenError {
    /// The channel's service could not be opened (incompatible, or another
    /// cause).
    #[error(transparent)]
    Open(#[from] ServiceOpenError),
    /// The channel already has its one publisher: another process with the
    /// same role is running in this run, or died and was not yet cleaned up.
    #[error(
        "service `{service}` of run `{run}` already has its publisher: another {producer} of this run is running (at most {max} per run)"
    )]
    PublisherTaken {
        /// The service name.
        service: String,
        /// The run.
        run: String,
        /// The role that normally publishes on the channel.
        producer: &'static str,
        /// The limit.
        max: usize,
    },
    /// The publisher port could not be created (its shared-memory pool, for
    /// instance, when `/dev/shm` is full).
    #[error(
        "cannot create the publisher of service `{service}` of run `{run}` (iceoryx2: {source})"
    )]
    Port {
        /// The service name.
        service: String,
        /// The run.
        run: String,
        /// The iceoryx2 failure.
        #[source]
        source: PublisherCreateError,
    },
}

/// Why a frame was not sent to every subscriber.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameSendError {
    /// A registered subscriber did not receive the frame (it was delivered
    /// to the other subscribers, if any), because its queue was full: the
    /// subscriber is stalled, dead and not yet reaped, or has not polled
    /// since this publisher appeared. Also reported, less precisely, when a
    /// subscriber deregisters during the send, or when iceoryx2 could not
    /// connect to a new subscriber (it then logs a warning). Recoverable:
    /// frames are delivered again once the subscriber has caught up or has
    /// been reaped. Counted in [`PublisherStats::queue_full`].
    #[error(
        "frame not delivered on `netfi/{run}/{channel}`: a subscriber's queue of {capacity} frames is full (stalled or dead {consumer})"
    )]
    QueueFull {
        /// The run.
        run: RunId,
        /// The channel.
        channel: Port,
        /// The consumer role of the channel.
        consumer: &'static str,
        /// The queue capacity in frames.
        capacity: usize,
    },
    /// No shared-memory sample could be loaned: the publisher's pool is
    /// exhausted, which the pool sizing rules out unless a subscriber holds
    /// samples it should have released.
    #[error("cannot loan a sample on `netfi/{run}/{channel}` (iceoryx2: {source})")]
    Loan {
        /// The run.
        run: RunId,
        /// The channel.
        channel: Port,
        /// The iceoryx2 failure.
        #[source]
        source: LoanError,
    },
    /// Delivery failed for another reason: a corrupted connection, or the
    /// connections to new subscribers could not be updated.
    #[error("cannot deliver a frame on `netfi/{run}/{channel}` (iceoryx2: {source})")]
    Delivery {
        /// The run.
        run: RunId,
        /// The channel.
        channel: Port,
        /// The iceoryx2 failure.
        #[source]
        source: SendError,
    },
}

impl<T: IpcPayload> FramePublisher<T> {
    pub(super) fn open(
        node: &Node<Ipc>,
        config: &IpcConfig,
        channel: Port,
    ) -> Result<Self, PublisherOpenError> {
        let service_name = config.service_name(channel);
        let run = config.run_id();
        let service = open_checked::<T>(node, config, channel)?;
        let port = service
            .publisher_builder()
            .max_loaned_samples(PUBLISHER_MAX_LOANED_SAMPLES)
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            // Called only when a connected subscriber's queue is full: refuse
            // the frame for that subscriber and make `send` fail, so the loss
            // is reported instead of being swallowed.
            .set_backpressure_handler(|_: &BackpressureInfo| BackpressureAction::DiscardDataAndFail)
            .create()
            .map_err(|source| match source {
                PublisherCreateError::ExceedsMaxSupportedPublishers => {
                    PublisherOpenError::PublisherTaken {
                        service: service_name.clone(),
                        run: run.to_string(),
                        producer: channel.producer().as_str(),
                        max: MAX_PUBLISHERS_PER_CHANNEL,
                    }
                }
                source => PublisherOpenError::Port {
                    service: service_name.clone(),
                    run: run.to_string(),
                    source,
                },
            })?;
        let ready = port.loan_uninit().ok();
        Ok(Self {
            ready,
            port,
            service,
            run: run.clone(),
            channel,
            stats: PublisherStats::default(),
        })
    }

    /// Sends one frame: loans a sample in shared memory, initializes it to
    /// [`FrameSample::ZERO`], lets `fill` write it, and publishes it at once.
    /// `fill` runs immediately before the send, so a timestamp taken inside
    /// it is as late as the transport allows.
    ///
    /// Returns the number of subscribers that received the frame (0 when
    /// none is registered), or [`FrameSendError::QueueFull`] when a
    /// registered subscriber did not receive it.
    pub fn send_with<F: FnOnce(&mut T)>(
        &mut self,
        fill: F,
    ) -> Result<usize, FrameSendError> {
        self.send_from(&T::ZERO, fill)
    }

    /// Sends a copy of `frame` that `stamp` may still change: the sample is
    /// written once, from `frame`, and `stamp` runs immediately before the
    /// send; see [`FramePublisher::send_with`].
    pub fn send_from<F: FnOnce(&mut T)>(
        &mut self,
        frame: &T,
        stamp: F,
    ) -> Result<usize, FrameSendError> {
        let uninit = match self.ready.take() {
            Some(s) => s,
            None => self
                .port
                .loan_uninit()
                .map_err(|source| FrameSendError::Loan {
                    run: self.run.clone(),
                    channel: self.channel,
                    source,
                })?,
        };
        let mut sample = uninit.write_payload(*frame);
        // Counted before sending: a subscriber that registers during the send
        // may get the frame without being expected, never the reverse.
        let subscribers = self.peers_connected();
        stamp(sample.payload_mut());
        let result = sample.send();
        self.stats.sent += 1;
        // The next frame's sample, now, while nothing is due (a failure is
        // retried, and reported, by the next send).
        self.ready = self.port.loan_uninit().ok();
        match result {
            Ok(0) if subscribers == 0 => {
                self.stats.unsubscribed += 1;
                Ok(0)
            }
            // The backpressure handler reports a full queue of a subscriber
            // that has attached to this publisher. A subscriber that has not
            // polled since this publisher appeared has not attached yet: its
            // queue fills without it, and once full iceoryx2 drops the frame
            // for it without an error, visible only as a missing recipient.
            Ok(receivers) if receivers >= subscribers => Ok(receivers),
            Ok(_) | Err(SendError::UnableToDeliver) => {
                self.stats.queue_full += 1;
                Err(FrameSendError::QueueFull {
                    run: self.run.clone(),
                    channel: self.channel,
                    consumer: self.channel.consumer().as_str(),
                    capacity: SUBSCRIBER_BUFFER_FRAMES,
                })
            }
            Err(source) => Err(FrameSendError::Delivery {
                run: self.run.clone(),
                channel: self.channel,
                source,
            }),
        }
    }

    /// Sends a copy of `frame`; see [`FramePublisher::send_with`].
    pub fn send(&mut self, frame: &T) -> Result<usize, FrameSendError> {
        self.send_from(frame, |_| {})
    }

    /// Subscribers registered on the channel. A killed subscriber stays
    /// counted until it is reaped ([`IpcNode::reap_dead_peers`]).
    ///
    /// [`IpcNode::reap_dead_peers`]: super::IpcNode::reap_dead_peers
    pub fn peers_connected(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Counters since the publisher was opened.
    pub fn stats(&self) -> PublisherStats {
        self.stats
    }

    /// The channel this publisher sends on.
    pub fn channel(&self) -> Port {
        self.channel
    }

    /// The run this publisher belongs to.
    pub fn run_id(&self) -> &RunId {
        &self.run
    }
}
