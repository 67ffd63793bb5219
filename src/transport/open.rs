//! A transport is a value: the emulator's ingress and egress are each one
//! enum over the transports there are, opened by one [`open`] from two
//! [`Endpoint`]s, so iceoryx2, UDP and any combination take one path
//! through the emulator.

use crate::sample::{FeedbackSample, FrameSample};
use std::collections::VecDeque;
use crate::transport::endpoint::{Endpoint, Payload};
use crate::transport::ports::{FrameSink, FrameSource, MemoryPort, PortError};
use crate::transport::udp::{Arena, ConsolePolicy, PeerAddr, UdpOptions, UdpPort, UdpSink, UdpSource};
use crate::transport::udp::UdpOpenError;
use crate::transport::{
    Channel, CleanupError, FramePublisher, FrameSubscriber, IpcConfig, IpcNode, NodeOpenError, PublisherOpenError, Role, RunId, RunIdError,
    SubscriberOpenError,
};
use std::cell::RefCell;
use std::net::SocketAddr;
use std::rc::Rc;

/// Where the emulator takes frames from.
pub enum Ingress {
    /// The console's iceoryx2 port.
    Iceoryx2(FrameSubscriber),
    /// A UDP socket.
    Udp(UdpSource),
    /// A queue in memory (tests).
    Memory(MemoryPort),
}

/// Where the emulator sends what it releases.
pub enum Egress {
    /// The simulator's iceoryx2 port.
    Iceoryx2(FramePublisher),
    /// A UDP socket, to the robot's address.
    Udp(UdpSink),
    /// A queue in memory (tests).
    Memory(MemoryPort),
}

impl FrameSource for Ingress {
    #[inline]
    fn try_recv(&mut self, out: &mut FrameSample) -> Result<bool, PortError> {
        match self {
            Ingress::Iceoryx2(p) => FrameSource::try_recv(p, out),
            Ingress::Udp(p) => p.try_recv(out),
            Ingress::Memory(p) => p.try_recv(out),
        }
    }

    fn peers(&mut self) -> Option<usize> {
        match self {
            Ingress::Iceoryx2(p) => FrameSource::peers(p),
            Ingress::Udp(p) => p.peers(),
            Ingress::Memory(p) => FrameSource::peers(p),
        }
    }

    #[inline]
    fn dropped(&mut self, sample: &FrameSample) {
        match self {
            Ingress::Iceoryx2(p) => p.dropped(sample),
            Ingress::Udp(p) => p.dropped(sample),
            Ingress::Memory(p) => p.dropped(sample),
        }
    }

    fn senders(&mut self) -> Vec<String> {
        match self {
            Ingress::Iceoryx2(p) => FrameSource::senders(p),
            Ingress::Udp(p) => p.sender().map(|a| vec![format!("udp://{}", a.addr())]).unwrap_or_default(),
            Ingress::Memory(_) => Vec::new(),
        }
    }

    #[inline]
    fn sender(&self) -> Option<&PeerAddr> {
        match self {
            Ingress::Iceoryx2(p) => p.sender(),
            Ingress::Udp(p) => p.sender(),
            Ingress::Memory(p) => p.sender(),
        }
    }
}

impl FrameSink for Egress {
    #[inline]
    fn send_with(&mut self, sample: &FrameSample, stamp: impl FnOnce(&mut FrameSample)) -> Result<Option<usize>, PortError> {
        match self {
            Egress::Iceoryx2(p) => FrameSink::send_with(p, sample, stamp),
            Egress::Udp(p) => p.send_with(sample, stamp),
            Egress::Memory(p) => p.send_with(sample, stamp),
        }
    }

    fn peers(&mut self) -> Option<usize> {
        match self {
            Egress::Iceoryx2(p) => FrameSink::peers(p),
            Egress::Udp(p) => p.peers(),
            Egress::Memory(p) => FrameSink::peers(p),
        }
    }

    fn unsubscribed(&self) -> u64 {
        match self {
            Egress::Iceoryx2(p) => FrameSink::unsubscribed(p),
            _ => 0,
        }
    }
}

/// Where the emulator takes the robot's feedback from.
pub enum FeedbackIngress {
    /// The robot's iceoryx2 port (`feedback`).
    Iceoryx2(FrameSubscriber<FeedbackSample>),
    /// A queue in memory (tests).
    Memory(VecDeque<FeedbackSample>),
}

/// Where the emulator sends the feedback it releases.
pub enum FeedbackEgress {
    /// The console's iceoryx2 port (`feedback_out`).
    Iceoryx2(FramePublisher<FeedbackSample>),
    /// A queue in memory (tests).
    Memory(VecDeque<FeedbackSample>),
}

impl FeedbackIngress {
    /// Copies the next waiting feedback into `out`; `Ok(false)` if none waits.
    #[inline]
    pub fn try_recv(&mut self, out: &mut FeedbackSample) -> Result<bool, PortError> {
        match self {
            FeedbackIngress::Iceoryx2(p) => match p.try_recv() {
                Ok(Some(s)) => {
                    *out = s;
                    Ok(true)
                }
                Ok(None) => Ok(false),
                Err(e) => Err(PortError { port: p.run_id().resource_name(p.channel()), message: e.to_string() }),
            },
            FeedbackIngress::Memory(q) => match q.pop_front() {
                Some(s) => {
                    *out = s;
                    Ok(true)
                }
                None => Ok(false),
            },
        }
    }

    /// Robots publishing feedback now (`None` in memory).
    pub fn peers(&self) -> Option<usize> {
        match self {
            FeedbackIngress::Iceoryx2(p) => Some(p.peers_connected()),
            FeedbackIngress::Memory(_) => None,
        }
    }
}

impl FeedbackEgress {
    /// Sends `sample` after `stamp` has had the last word on it; the
    /// number of receivers it reached.
    #[inline]
    pub fn send_with(&mut self, sample: &FeedbackSample, stamp: impl FnOnce(&mut FeedbackSample)) -> Result<usize, PortError> {
        match self {
            FeedbackEgress::Iceoryx2(p) => p
                .send_from(sample, stamp)
                .map_err(|e| PortError { port: p.run_id().resource_name(p.channel()), message: e.to_string() }),
            FeedbackEgress::Memory(q) => {
                let mut s = *sample;
                stamp(&mut s);
                q.push_back(s);
                Ok(1)
            }
        }
    }

    /// Feedback sent while no console was subscribed.
    pub fn unsubscribed(&self) -> u64 {
        match self {
            FeedbackEgress::Iceoryx2(p) => p.stats().unsubscribed,
            FeedbackEgress::Memory(_) => 0,
        }
    }
}

/// Opens the feedback loop's two ports on `node`: the robot's `feedback`
/// (subscriber) and the console's `feedback_out` (publisher).
pub fn open_feedback(node: &IpcNode) -> Result<(FeedbackIngress, FeedbackEgress), FeedbackOpenError> {
    let out = node.publisher_of::<FeedbackSample>(Channel::FeedbackOut).map_err(FeedbackOpenError::Egress)?;
    let inp = node.subscriber_of::<FeedbackSample>(Channel::Feedback).map_err(FeedbackOpenError::Ingress)?;
    Ok((FeedbackIngress::Iceoryx2(inp), FeedbackEgress::Iceoryx2(out)))
}

/// Why the feedback loop's ports could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum FeedbackOpenError {
    /// The emulator → console port.
    #[error("opening the emulator → console feedback port: {0}")]
    Egress(#[source] PublisherOpenError),
    /// The robot → emulator port.
    #[error("opening the robot → emulator feedback port: {0}")]
    Ingress(#[source] SubscriberOpenError),
}

/// How to open the emulator's transports, besides the endpoints.
#[derive(Debug, Clone)]
pub struct Wiring {
    /// The run, for an iceoryx2 side.
    pub run_id: Option<String>,
    /// What a UDP datagram carries.
    pub payload: Payload,
    /// Socket options of the UDP sides.
    pub udp: UdpOptions,
    /// Local address a UDP egress sends from (default: an ephemeral port).
    pub egress_bind: Option<SocketAddr>,
    /// The console a UDP ingress takes datagrams from (anything else is
    /// refused and counted): its address, or, as a
    /// [`ConsolePolicy::FirstDatagram`], the first sender. Required with a
    /// UDP ingress: without it [`open`] fails with [`ConsoleUnnamed`].
    pub console_from: Option<ConsolePolicy>,
    /// Raw payload: datagrams the release queue may hold (the arena has
    /// one slot more).
    pub queue_capacity: usize,
    /// A UDP ingress ends the stream after this long without a datagram.
    pub idle_end_ns: Option<u64>,
    /// Open the egress first and wait this long for a receiver on it
    /// before opening the ingress (`None`: do not wait).
    pub wait_for_peer_ns: Option<u64>,
}

/// A UDP ingress was to be opened without a console: nothing would tell
/// the console's frames from anyone else's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "the UDP ingress udp://{ingress} takes frames from one console, and none was named: \
     give the console's address (--console-from ADDR:PORT) or pair with the first sender (--console-from first); \
     datagrams from anyone else are refused and counted"
)]
pub struct ConsoleUnnamed {
    /// The ingress address.
    pub ingress: SocketAddr,
}

/// Why the emulator's transports could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// A UDP ingress without a console.
    #[error(transparent)]
    ConsoleUnnamed(#[from] ConsoleUnnamed),
    /// A UDP socket could not be opened.
    #[error("opening the UDP {side} socket: {source}")]
    Udp {
        /// `ingress` or `egress`.
        side: &'static str,
        /// Why.
        #[source]
        source: UdpOpenError,
    },
    /// An iceoryx2 side without a run to open it in.
    #[error("an iceoryx2 endpoint needs a run id (ingress {ingress}, egress {egress})")]
    RunIdNeeded {
        /// Where frames come from.
        ingress: Endpoint,
        /// Where they go.
        egress: Endpoint,
    },
    /// The iceoryx2 node could not be opened.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// The emulator → simulator port could not be opened.
    #[error("opening the emulator → simulator port: {0}")]
    Egress(#[source] PublisherOpenError),
    /// The console → emulator port could not be opened.
    #[error("opening the console → emulator port: {0}")]
    Ingress(#[source] SubscriberOpenError),
    /// No robot subscribed in time (`--wait-for-peer-s`).
    #[error("no robot subscribed to the emulator → simulator port within {wait_s} s")]
    NoRobot {
        /// How long it waited, s.
        wait_s: f64,
    },
    /// Told to stop while waiting for a robot.
    #[error("stopped while waiting for a robot")]
    Stopped,
}

/// Why this process's iceoryx2 node could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The run id is not one netfi accepts.
    #[error("run id `{run_id}`: {source}")]
    RunId {
        /// What was given.
        run_id: String,
        /// What is wrong with it.
        #[source]
        source: RunIdError,
    },
    /// iceoryx2 refused the node.
    #[error("opening the {role} node of run `{run_id}`: {source}")]
    Open {
        /// The process's role.
        role: Role,
        /// The run.
        run_id: String,
        /// Why.
        #[source]
        source: NodeOpenError,
    },
}

/// The emulator's transports, open.
pub struct Transports {
    /// Where frames come from.
    pub ingress: Ingress,
    /// Where released frames go.
    pub egress: Egress,
    /// The iceoryx2 node, when a side is iceoryx2.
    pub node: Option<IpcNode>,
    /// Raw payload: the slots shared by the UDP source and sink.
    pub arena: Option<Rc<RefCell<Arena>>>,
}

impl Transports {
    /// The ingress socket, when the ingress is UDP.
    pub fn udp_ingress(&self) -> Option<&UdpPort> {
        match &self.ingress {
            Ingress::Udp(s) => Some(s.port()),
            _ => None,
        }
    }

    /// The egress socket, when the egress is UDP.
    pub fn udp_egress(&self) -> Option<&UdpPort> {
        match &self.egress {
            Egress::Udp(s) => Some(s.port()),
            _ => None,
        }
    }
}

/// Opens `ingress` and `egress`: UDP sockets first, then the iceoryx2 node
/// and ports if a side needs them.
///
/// A UDP ingress takes frames from its console only (`w.console_from`,
/// required); a UDP egress socket receives from the robot's address only
/// (what the return path reads from it; a handle made with
/// [`UdpPort::try_clone`] keeps that, and [`UdpPort::accept_only`] on it
/// names another robot address). What either refuses is counted per
/// sender ([`UdpPort::refused`], [`UdpSource::foreign`]).
pub fn open(ingress: &Endpoint, egress: &Endpoint, w: &Wiring) -> Result<Transports, OpenError> {
    // `Into`: the field may hold an address or a whole policy.
    let console: Option<ConsolePolicy> = w.console_from.map(Into::into);
    let console = match (ingress.udp(), console) {
        (Some(addr), None) => return Err(ConsoleUnnamed { ingress: addr }.into()),
        (_, c) => c.unwrap_or(ConsolePolicy::FirstDatagram),
    };
    let arena = (w.payload == Payload::Raw).then(|| Rc::new(RefCell::new(Arena::new(w.queue_capacity + 1))));
    let sink = match egress.udp() {
        Some(peer) => {
            let opts = UdpOptions { reuse_address: false, ..w.udp };
            let mut port = match w.egress_bind {
                Some(local) => UdpPort::bind(local, &opts),
                None => UdpPort::bind_towards(peer, &opts),
            }
            .map_err(|source| OpenError::Udp { side: "egress", source })?;
            // Only the robot answers on the way back.
            port.accept_only(peer);
            Some(UdpSink::new(port, peer, arena.clone()))
        }
        None => None,
    };
    let source = match ingress.udp() {
        Some(addr) => {
            let port = UdpPort::bind(addr, &w.udp).map_err(|source| OpenError::Udp { side: "ingress", source })?;
            if console == ConsolePolicy::FirstDatagram {
                eprintln!(
                    "emulator: WARNING: the UDP ingress udp://{} will take the first sender as its console (--console-from first): \
                     whoever sends first is trusted",
                    port.local_addr()
                );
            }
            let s = UdpSource::new(port, arena.clone(), console);
            Some(match w.idle_end_ns {
                Some(ns) => s.with_idle_end(ns),
                None => s,
            })
        }
        None => None,
    };
    let node = match (source.is_some() && sink.is_some(), &w.run_id) {
        (true, _) => None,
        (false, Some(run_id)) => Some(open_node(run_id, Role::Emulator)?),
        (false, None) => return Err(OpenError::RunIdNeeded { ingress: *ingress, egress: *egress }),
    };
    let mut egress = match (sink, &node) {
        (Some(s), _) => Egress::Udp(s),
        (None, Some(n)) => Egress::Iceoryx2(n.publisher(Channel::Emulator).map_err(OpenError::Egress)?),
        (None, None) => unreachable!("a node is open when a side is iceoryx2"),
    };
    if let (Some(wait_ns), Egress::Iceoryx2(_)) = (w.wait_for_peer_ns, &egress) {
        // The robot first: the console's frames are taken only once there is
        // someone to release them to.
        let deadline = crate::clock::now_ns() + wait_ns;
        while egress.peers() == Some(0) {
            if crate::clock::now_ns() > deadline {
                return Err(OpenError::NoRobot { wait_s: wait_ns as f64 / 1e9 });
            }
            if node.as_ref().is_some_and(|n| n.termination_requested()) {
                return Err(OpenError::Stopped);
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }
    let ingress = match (source, &node) {
        (Some(s), _) => Ingress::Udp(s),
        (None, Some(n)) => Ingress::Iceoryx2(n.subscriber(Channel::Console).map_err(OpenError::Ingress)?),
        (None, None) => unreachable!("a node is open when a side is iceoryx2"),
    };
    Ok(Transports { ingress, egress, node, arena })
}

/// Opens this process's node in run `run_id`.
pub fn open_node(run_id: &str, role: Role) -> Result<IpcNode, NodeError> {
    let run = RunId::new(run_id).map_err(|source| NodeError::RunId { run_id: run_id.to_string(), source })?;
    IpcNode::open(&IpcConfig::new(run), role).map_err(|source| NodeError::Open { role, run_id: run_id.to_string(), source })
}

/// Removes what killed processes of earlier runs left on this host; returns
/// how many dead nodes were removed.
pub fn cleanup_stale() -> Result<usize, CleanupError> {
    let reports = crate::transport::cleanup_dead_runs(|_| true)?;
    Ok(reports.iter().map(|(_, r)| r.removed.len()).sum())
}
