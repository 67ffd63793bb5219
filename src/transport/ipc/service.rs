//! The definition of a channel's publish/subscribe service, shared by both
//! ends.

use iceoryx2::node::Node;
use iceoryx2::prelude::ServiceName;
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use super::{
    Port, Ipc, IpcConfig, HISTORY_FRAMES, MAX_NODES_PER_CHANNEL, MAX_PUBLISHERS_PER_CHANNEL,
    MAX_SUBSCRIBERS_PER_CHANNEL, SUBSCRIBER_BUFFER_FRAMES, SUBSCRIBER_MAX_BORROWED_SAMPLES,
};
use super::IpcPayload;

/// Opens the service of `channel`, creating it if needed, with every limit
/// stated explicitly: opening a service created with smaller limits, another
/// overflow mode or another sample type fails instead of silently adopting
/// the other's settings.
pub(super) fn open_service<T: IpcPayload>(
    node: &Node<Ipc>,
    config: &IpcConfig,
    channel: Port,
) -> Result<PortFactory<Ipc, T, ()>, PublishSubscribeOpenOrCreateError> {
    let name = ServiceName::new(&config.service_name(channel))
        .expect("a validated run id always forms a valid service name");
    node.service_builder(&name)
        .publish_subscribe::<T>()
        .max_publishers(MAX_PUBLISHERS_PER_CHANNEL)
        .max_subscribers(MAX_SUBSCRIBERS_PER_CHANNEL)
        .max_nodes(MAX_NODES_PER_CHANNEL)
        .subscriber_max_buffer_size(SUBSCRIBER_BUFFER_FRAMES)
        .subscriber_max_borrowed_samples(SUBSCRIBER_MAX_BORROWED_SAMPLES)
        .history_size(HISTORY_FRAMES)
        .enable_safe_overflow(false)
        .open_or_create()
}

/// Why a channel's service could not be opened, for either end.
#[derive(Debug, thiserror::Error)]
pub enum ServiceOpenError {
    /// The channel exists with another sample type or layout, other limits,
    /// or from another iceoryx2 version: the processes of the run were not
    /// built from the same netfi.
    #[error(
        "service `{service}` of run `{run}` exists but is incompatible: {detail} (iceoryx2: {source}); every process of a run must speak the same interface version"
    )]
    Incompatible {
        /// The service name.
        service: String,
        /// Both sides' payload types: the existing service's and this build's.
        detail: String,
        /// The run.
        run: String,
        /// The iceoryx2 failure.
        #[source]
        source: PublishSubscribeOpenOrCreateError,
    },
    /// The channel could not be opened or created for another reason
    /// (permissions, too many processes attached, a corrupted service).
    #[error("cannot open or create service `{service}` of run `{run}` (iceoryx2: {source})")]
    Service {
        /// The service name.
        service: String,
        /// The run.
        run: String,
        /// The iceoryx2 failure.
        #[source]
        source: PublishSubscribeOpenOrCreateError,
    },
}

/// [`open_service`], its failure told apart: an incompatible service (with
/// both sides' payload types) or another cause.
pub(super) fn open_checked<T: IpcPayload>(
    node: &Node<Ipc>,
    config: &IpcConfig,
    channel: Port,
) -> Result<PortFactory<Ipc, T, ()>, ServiceOpenError> {
    open_service(node, config, channel).map_err(|source| {
        let (service, run) = (config.service_name(channel), config.run_id().to_string());
        if is_incompatible(&source) {
            ServiceOpenError::Incompatible { detail: mismatch::<T>(config, channel), service, run, source }
        } else {
            ServiceOpenError::Service { service, run, source }
        }
    })
}

/// Whether an open-or-create failure means the existing service does not
/// match what this build expects.
pub(super) fn is_incompatible(e: &PublishSubscribeOpenOrCreateError) -> bool {
    use PublishSubscribeOpenError as E;
    matches!(
        e,
        PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            E::IncompatibleTypes
                | E::IncompatibleMessagingPattern
                | E::IncompatibleAttributes
                | E::IncompatibleOverflowBehavior
                | E::DoesNotSupportRequestedMinBufferSize
                | E::DoesNotSupportRequestedMinHistorySize
                | E::DoesNotSupportRequestedMinSubscriberBorrowedSamples
                | E::DoesNotSupportRequestedAmountOfPublishers
                | E::DoesNotSupportRequestedAmountOfSubscribers
                | E::DoesNotSupportRequestedAmountOfNodes
                | E::VersionMismatch
                | E::InvalidTypeDefinition
        )
    )
}

/// What the existing service of `channel` carries against what this build
/// speaks, for a refusal's message: both payload type names, sizes and
/// alignments (read from the service's static configuration).
pub(super) fn mismatch<T: IpcPayload>(config: &IpcConfig, channel: Port) -> String {
    use iceoryx2::prelude::MessagingPattern;
    use iceoryx2::service::Service as _;
    let ours = format!("{} ({} bytes, aligned to {})", T::TYPE_NAME, core::mem::size_of::<T>(), core::mem::align_of::<T>());
    let name = match ServiceName::new(&config.service_name(channel)) {
        Ok(n) => n,
        Err(_) => return format!("this build speaks {ours}"),
    };
    match Ipc::details(&name, config.iceoryx2(), MessagingPattern::PublishSubscribe) {
        Ok(Some(d)) => {
            let p = &d.static_details.publish_subscribe().message_type_details().payload;
            format!(
                "the service carries {} ({} bytes, aligned to {}), this build speaks {ours}",
                p.type_name(),
                p.size(),
                p.alignment()
            )
        }
        _ => format!("this build speaks {ours}; the existing service's payload could not be read"),
    }
}
