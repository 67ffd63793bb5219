//! The two side services of a run that carry no frames: live control
//! (`netfi/<run>/control`, request-response) and telemetry
//! (`netfi/<run>/telemetry`, publish-subscribe). docs/interface.md, "Live
//! control" and "Telemetry", is their contract.
//!
//! Both are served by the emulator from a thread of its own, off the
//! loop's core; a client (`netfi ctl`) opens them only if they exist, so a
//! run id that names no running emulator is an error at once and leaves
//! nothing behind.
//!
//! Control requests and responses are UTF-8 JSON text in `[u8]` slices
//! (the service's payload type is `[u8]` both ways), which any iceoryx2
//! binding can send. A request waits for its one response.

use core::time::Duration;

use iceoryx2::port::client::Client;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{AllocationStrategy, MessagingPattern, PortFactory as _, ServiceName, ZeroCopySend};
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use iceoryx2::service::port_factory::request_response::PortFactory as ReqResFactory;
use iceoryx2::service::Service as _;

use super::node::{IpcNode, NodeOpenError};
use super::{Ipc, IpcConfig, Role};

/// The last component of the control service's name.
pub const CONTROL_SERVICE: &str = "control";
/// The last component of the telemetry service's name.
pub const TELEMETRY_SERVICE: &str = "telemetry";
/// Clients of one run's control service at a time.
pub const MAX_CONTROL_CLIENTS: usize = 4;
/// Subscribers of one run's telemetry at a time.
pub const MAX_TELEMETRY_SUBSCRIBERS: usize = 4;
/// Intervals a telemetry subscriber's queue holds; older ones are
/// overwritten (a slow watcher loses the oldest, the emulator never waits).
pub const TELEMETRY_BUFFER: usize = 64;
/// The largest request or response, bytes (a scenario's TOML text).
pub const MAX_MESSAGE_BYTES: usize = 1 << 20;

/// One interval of the emulator's telemetry (`netfi::Telemetry.v1`; the
/// layout is pinned by a size assertion, and the version in the type name
/// changes with it). Times are ns; the interval is `[start_ns, start_ns +
/// length_ns)` from the run's first frame. Percentiles are 0 when the
/// interval released no frame.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("netfi::Telemetry.v1")]
#[repr(C)]
pub struct TelemetrySample {
    /// The layout's version: 1.
    pub version: u32,
    /// Bit 0: faults were paused at the end of the interval.
    pub flags: u32,
    /// The interval's number, from 0.
    pub seq: u64,
    /// The interval's start, ns from the run's first frame.
    pub start_ns: u64,
    /// Its length, ns.
    pub length_ns: u64,
    /// Frames that entered in the interval.
    pub entered: u64,
    /// Frames released in the interval.
    pub delivered: u64,
    /// Frames dropped in the interval (any cause).
    pub dropped: u64,
    /// `dropped / entered`, NaN when none entered.
    pub loss_rate: f64,
    /// The phase of the run's timeline at the end of the interval, from 1.
    pub phase: u32,
    /// Zero (padding, kept for later versions).
    pub reserved: u32,
    /// Injected delay of the frames released in the interval: p50, p90,
    /// p99, max.
    pub injected_ns: [u64; 4],
    /// Release lateness (actual − scheduled release) of the same frames:
    /// p50, p99, p99.9, max.
    pub lateness_ns: [u64; 4],
}

// The layout docs/interface.md gives, field by field.
const _: () = {
    use core::mem::{align_of, offset_of, size_of};
    assert!(size_of::<TelemetrySample>() == 136 && align_of::<TelemetrySample>() == 8);
    assert!(offset_of!(TelemetrySample, seq) == 8 && offset_of!(TelemetrySample, start_ns) == 16);
    assert!(offset_of!(TelemetrySample, entered) == 32 && offset_of!(TelemetrySample, loss_rate) == 56);
    assert!(offset_of!(TelemetrySample, phase) == 64 && offset_of!(TelemetrySample, injected_ns) == 72);
    assert!(offset_of!(TelemetrySample, lateness_ns) == 104);
};

impl TelemetrySample {
    /// The iceoryx2 type name.
    pub const TYPE_NAME: &'static str = "netfi::Telemetry.v1";
    /// The layout's version.
    pub const VERSION: u32 = 1;
    /// `flags` bit: faults paused.
    pub const FLAG_PAUSED: u32 = 1;
}

/// Why a control or telemetry endpoint could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SideOpenError {
    /// No emulator of this run serves the service on this host (as this
    /// user): the run does not exist, has ended, or was started without it.
    #[error("no run `{run}` with a {service} service on this host (is its emulator running, as this user, with a run id, and not with --no-control{}?)", if *.service == TELEMETRY_SERVICE { " or --telemetry-ms 0" } else { "" })]
    NoSuchRun {
        /// The run.
        run: String,
        /// `control` or `telemetry`.
        service: &'static str,
    },
    /// The node could not be opened.
    #[error(transparent)]
    Node(#[from] NodeOpenError),
    /// iceoryx2 refused to open or create the service or its port (another
    /// version's service, or a limit reached: too many clients).
    #[error("cannot open `{service}` of run `{run}`: {detail}")]
    Service {
        /// The service name.
        service: String,
        /// The run.
        run: String,
        /// iceoryx2's account.
        detail: String,
    },
}

/// Why a control request got no answer.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// The request is larger than [`MAX_MESSAGE_BYTES`].
    #[error("the request is {len} bytes; at most {MAX_MESSAGE_BYTES} are accepted")]
    TooLarge {
        /// Its size.
        len: usize,
    },
    /// iceoryx2 could not send it, or the answer could not be read.
    #[error("control request to run `{run}` failed: {detail}")]
    Transport {
        /// The run.
        run: String,
        /// iceoryx2's account.
        detail: String,
    },
    /// No answer came in time: the emulator is busy ending, or gone.
    #[error("run `{run}` did not answer within {} ms (has its emulator ended?)", .waited.as_millis())]
    Timeout {
        /// The run.
        run: String,
        /// How long the client waited.
        waited: Duration,
    },
}

fn service_name(config: &IpcConfig, what: &str) -> ServiceName {
    ServiceName::new(&config.run_id().resource_name(what)).expect("a validated run id always forms a valid service name")
}

fn side_err(config: &IpcConfig, what: &str, e: impl core::fmt::Debug) -> SideOpenError {
    SideOpenError::Service { service: config.run_id().resource_name(what), run: config.run_id().to_string(), detail: format!("{e:?}") }
}

fn control_service(node: &IpcNode, create: bool) -> Result<ReqResFactory<Ipc, [u8], (), [u8], ()>, SideOpenError> {
    let config = node.config();
    let b = node
        .raw()
        .service_builder(&service_name(config, CONTROL_SERVICE))
        .request_response::<[u8], [u8]>()
        .max_servers(1)
        .max_clients(MAX_CONTROL_CLIENTS)
        .max_nodes(super::MAX_NODES_PER_CHANNEL)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1)
        .max_borrowed_responses_per_pending_response(1)
        .max_loaned_requests(1)
        .enable_fire_and_forget_requests(false);
    let r = if create { b.open_or_create().map_err(|e| side_err(config, CONTROL_SERVICE, e)) } else { b.open().map_err(|e| side_err(config, CONTROL_SERVICE, e)) };
    super::node::make_private(config.prefix());
    r
}

fn telemetry_service(node: &IpcNode, create: bool) -> Result<PubSubFactory<Ipc, TelemetrySample, ()>, SideOpenError> {
    let config = node.config();
    let b = node
        .raw()
        .service_builder(&service_name(config, TELEMETRY_SERVICE))
        .publish_subscribe::<TelemetrySample>()
        .max_publishers(1)
        .max_subscribers(MAX_TELEMETRY_SUBSCRIBERS)
        .max_nodes(super::MAX_NODES_PER_CHANNEL)
        .subscriber_max_buffer_size(TELEMETRY_BUFFER)
        .subscriber_max_borrowed_samples(1)
        .history_size(0)
        .enable_safe_overflow(true);
    let r = if create { b.open_or_create().map_err(|e| side_err(config, TELEMETRY_SERVICE, e)) } else { b.open().map_err(|e| side_err(config, TELEMETRY_SERVICE, e)) };
    super::node::make_private(config.prefix());
    r
}

/// Whether `what` of the run exists, asked without creating anything.
fn exists(config: &IpcConfig, what: &'static str, pattern: MessagingPattern) -> Result<(), SideOpenError> {
    match Ipc::does_exist(&service_name(config, what), config.iceoryx2(), pattern) {
        Ok(true) => Ok(()),
        _ => Err(SideOpenError::NoSuchRun { run: config.run_id().to_string(), service: what }),
    }
}

/// The emulator's end of the control service. Not `Send`: open it on the
/// thread that serves.
pub struct ControlServer {
    port: Server<Ipc, [u8], (), [u8], ()>,
    _service: ReqResFactory<Ipc, [u8], (), [u8], ()>,
}

impl ControlServer {
    /// Creates the run's control service (or takes over one a killed
    /// emulator left) and its server.
    pub fn open(node: &IpcNode) -> Result<ControlServer, SideOpenError> {
        let service = control_service(node, true)?;
        let port = service
            .server_builder()
            .initial_max_slice_len(4096)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| side_err(node.config(), CONTROL_SERVICE, e))?;
        Ok(ControlServer { port, _service: service })
    }

    /// Answers every request waiting, each with `answer(request)`; returns
    /// how many. A request larger than [`MAX_MESSAGE_BYTES`] (a client
    /// other than `netfi ctl` may send one) is not handed over as bytes:
    /// `answer` gets [`RequestError::TooLarge`] for it, to answer with an
    /// error. A request that cannot be answered (its client left) is
    /// skipped.
    pub fn serve(&self, mut answer: impl FnMut(Result<&[u8], RequestError>) -> Vec<u8>) -> usize {
        let mut n = 0;
        while let Ok(Some(req)) = self.port.receive() {
            n += 1;
            let payload = req.payload();
            let reply = match payload.len() {
                len if len > MAX_MESSAGE_BYTES => answer(Err(RequestError::TooLarge { len })),
                _ => answer(Ok(payload)),
            };
            let Ok(resp) = req.loan_slice_uninit(reply.len()) else { continue };
            let _ = resp.write_from_slice(&reply).send();
        }
        n
    }
}

/// A client of a run's control service (`netfi ctl`).
pub struct ControlClient {
    port: Client<Ipc, [u8], (), [u8], ()>,
    _service: ReqResFactory<Ipc, [u8], (), [u8], ()>,
    node: IpcNode,
}

impl ControlClient {
    /// Opens the control service of `config`'s run, which must exist.
    pub fn open(config: &IpcConfig) -> Result<ControlClient, SideOpenError> {
        exists(config, CONTROL_SERVICE, MessagingPattern::RequestResponse)?;
        let node = IpcNode::open(config, Role::Tool)?;
        let service = control_service(&node, false)?;
        let port = service
            .client_builder()
            .initial_max_slice_len(4096)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| side_err(config, CONTROL_SERVICE, e))?;
        Ok(ControlClient { port, _service: service, node })
    }

    /// Sends `request` and waits up to `timeout` for the answer.
    pub fn request(&self, request: &[u8], timeout: Duration) -> Result<Vec<u8>, RequestError> {
        let run = self.node.config().run_id().to_string();
        if request.len() > MAX_MESSAGE_BYTES {
            return Err(RequestError::TooLarge { len: request.len() });
        }
        let transport = |e: &dyn core::fmt::Debug| RequestError::Transport { run: run.clone(), detail: format!("{e:?}") };
        let loan = self.port.loan_slice_uninit(request.len()).map_err(|e| transport(&e))?;
        let pending = loan.write_from_slice(request).send().map_err(|e| transport(&e))?;
        let start = std::time::Instant::now();
        loop {
            if let Some(resp) = pending.receive().map_err(|e| transport(&e))? {
                return Ok(resp.payload().to_vec());
            }
            if start.elapsed() >= timeout {
                return Err(RequestError::Timeout { run, waited: timeout });
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

/// The emulator's telemetry publisher. Not `Send`.
pub struct TelemetryPublisher {
    port: Publisher<Ipc, TelemetrySample, ()>,
    _service: PubSubFactory<Ipc, TelemetrySample, ()>,
}

impl TelemetryPublisher {
    /// Creates the run's telemetry service and its publisher.
    pub fn open(node: &IpcNode) -> Result<TelemetryPublisher, SideOpenError> {
        let service = telemetry_service(node, true)?;
        let port = service.publisher_builder().create().map_err(|e| side_err(node.config(), TELEMETRY_SERVICE, e))?;
        Ok(TelemetryPublisher { port, _service: service })
    }

    /// Publishes one interval (to nobody, if nobody watches).
    pub fn send(&self, s: &TelemetrySample) {
        let _ = self.port.send_copy(*s);
    }
}

/// A watcher of a run's telemetry (`netfi ctl watch`).
pub struct TelemetrySubscriber {
    port: Subscriber<Ipc, TelemetrySample, ()>,
    _service: PubSubFactory<Ipc, TelemetrySample, ()>,
    node: IpcNode,
}

impl TelemetrySubscriber {
    /// Subscribes to the telemetry of `config`'s run, which must exist.
    pub fn open(config: &IpcConfig) -> Result<TelemetrySubscriber, SideOpenError> {
        exists(config, TELEMETRY_SERVICE, MessagingPattern::PublishSubscribe)?;
        let node = IpcNode::open(config, Role::Tool)?;
        let service = telemetry_service(&node, false)?;
        let port = service.subscriber_builder().create().map_err(|e| side_err(config, TELEMETRY_SERVICE, e))?;
        Ok(TelemetrySubscriber { port, _service: service, node })
    }

    /// The next interval received, if any.
    pub fn recv(&self) -> Option<TelemetrySample> {
        self.port.receive().ok().flatten().map(|s| *s.payload())
    }

    /// Whether SIGINT or SIGTERM came (see [`IpcNode::termination_requested`]).
    pub fn termination_requested(&self) -> bool {
        self.node.termination_requested()
    }

    /// Whether the emulator still publishes.
    pub fn publisher_alive(&self) -> bool {
        self._service.dynamic_config().number_of_publishers() > 0
    }
}
