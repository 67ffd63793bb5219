//! UDP as a transport of the emulator (`udp://ADDR:PORT`): a socket bound
//! at the ingress that takes datagrams from its console only, a socket at
//! the egress that sends to the robot and hears only it, and, with raw
//! payloads, the store of datagrams both share; at the end, `udp.json`.

use super::args::{Payload, UdpArgs, UdpArgsError};
use super::report::{BoundEndpoints, ForeignSender, OwnPercentiles, OwnTime, UdpReport};
use super::{Arena, ConsolePolicy, UdpOpenError, UdpOptions, UdpPort, UdpSink, UdpSource};
use crate::model::ModelKind;
use crate::transport::declare::{Lane, Sides, Transport, Wiring};
use crate::transport::EndpointError;
use std::cell::{Cell, RefCell};
use std::collections::BTreeMap;
use std::fmt;
use std::net::SocketAddr;
use std::rc::Rc;

/// Default release-queue capacity with raw payloads (and of the return
/// path): 4096 datagrams. Each needs an arena slot of 64 KiB of address
/// space (256 MiB in all, of which only the pages datagrams touch become
/// resident).
pub const RAW_DEFAULT_QUEUE_CAPACITY: usize = 4096;

/// The UDP transport.
pub struct Udp;

/// Where a UDP console's address is shared with the return path, once
/// known: named by `--console-from`, or the first sender's.
pub type ConsoleAddr = Rc<Cell<Option<SocketAddr>>>;

/// What a lane keeps of its UDP sides.
pub struct UdpSession {
    /// Raw payloads: the slots shared by the source and the sink.
    pub arena: Option<Rc<RefCell<Arena>>>,
    /// The console's address, once known.
    pub console: ConsoleAddr,
    /// A handle on each socket, for the return path.
    ingress: Option<UdpPort>,
    egress: Option<UdpPort>,
    /// The sockets as bound.
    pub bound: BoundEndpoints,
    /// End the stream after this long without a datagram.
    idle_end_ns: Option<u64>,
}

impl UdpSession {
    /// Handles on the egress socket (what the robot sends back) and the
    /// ingress socket (towards the console), when both sides are UDP.
    pub fn return_ports(&self) -> Result<Option<(UdpPort, UdpPort)>, UdpOpenError> {
        let (Some(i), Some(e)) = (&self.ingress, &self.egress) else { return Ok(None) };
        Ok(Some((e.try_clone()?, i.try_clone()?)))
    }
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

/// Why a lane's UDP sides could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum UdpSideError {
    /// A UDP ingress without a console.
    #[error(transparent)]
    ConsoleUnnamed(#[from] ConsoleUnnamed),
    /// A socket could not be opened.
    #[error("opening the UDP {side} socket: {source}")]
    Socket {
        /// `ingress` or `egress`.
        side: &'static str,
        /// Why.
        #[source]
        source: UdpOpenError,
    },
}

impl Transport for Udp {
    const SCHEME: &'static str = "udp";
    const SYNTAX: &'static str = "`udp://ADDR:PORT` (e.g. udp://127.0.0.1:36000, udp://:36000, udp://[::1]:36000)";
    type Addr = SocketAddr;

    fn parse(text: &str) -> Option<Result<SocketAddr, EndpointError>> {
        super::addr::parse(text)
    }

    fn show(addr: &SocketAddr, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "udp://{addr}")
    }

    fn socket_addr(addr: &SocketAddr) -> Option<SocketAddr> {
        Some(*addr)
    }

    type Args = UdpArgs;
    type ArgsError = UdpArgsError;

    fn check(args: &UdpArgs, lane: Lane<'_, SocketAddr>) -> Result<(), UdpArgsError> {
        args.check(lane)
    }

    fn opaque(args: &UdpArgs) -> bool {
        args.payload == Payload::Raw
    }

    /// A raw sample's bytes live in the arena, freed at its release, so a
    /// copy would be sent from a freed slot, and a flip would miss.
    fn unsupported(args: &UdpArgs) -> &'static [ModelKind] {
        match args.payload {
            Payload::Raw => &[ModelKind::Duplicate, ModelKind::Corrupt],
            Payload::Itp => &[],
        }
    }

    fn default_queue_capacity(args: &UdpArgs) -> Option<usize> {
        (args.payload == Payload::Raw).then_some(RAW_DEFAULT_QUEUE_CAPACITY)
    }

    type Session = UdpSession;
    type OpenError = UdpSideError;

    fn session(args: &UdpArgs, sides: Sides<&SocketAddr>, w: &Wiring) -> Result<UdpSession, UdpSideError> {
        if let (Some(addr), None) = (sides.ingress, args.console_from) {
            return Err(ConsoleUnnamed { ingress: *addr }.into());
        }
        Ok(UdpSession {
            arena: (args.payload == Payload::Raw).then(|| Rc::new(RefCell::new(Arena::new(w.queue_capacity + 1)))),
            console: ConsoleAddr::default(),
            ingress: None,
            egress: None,
            bound: BoundEndpoints { ingress: None, egress_local: None, egress_peer: sides.egress.copied() },
            idle_end_ns: w.idle_end_ns,
        })
    }

    type Source = UdpSource;
    type Sink = UdpSink;

    /// A socket towards the robot, hearing only the robot (what the return
    /// path reads from a handle on it).
    fn sink(s: &mut UdpSession, peer: &SocketAddr, args: &UdpArgs, _w: &Wiring) -> Result<UdpSink, UdpSideError> {
        let opts = UdpOptions { reuse_address: false, buffer_bytes: Some(args.udp_buffer_bytes) };
        let port = match args.egress_bind {
            Some(local) => UdpPort::bind(local, &opts),
            None => UdpPort::bind_towards(*peer, &opts),
        };
        let mut port = port.map_err(|source| UdpSideError::Socket { side: "egress", source })?;
        // Only the robot answers on the way back.
        port.accept_only(*peer);
        s.bound.egress_local = Some(port.local_addr());
        s.egress = Some(port.try_clone().map_err(|source| UdpSideError::Socket { side: "egress", source })?);
        Ok(UdpSink::new(port, *peer, s.arena.clone()))
    }

    /// A socket at `addr` taking datagrams from its console only.
    fn source(s: &mut UdpSession, addr: &SocketAddr, args: &UdpArgs, _w: &Wiring) -> Result<UdpSource, UdpSideError> {
        let opts = UdpOptions { reuse_address: true, buffer_bytes: Some(args.udp_buffer_bytes) };
        let port = UdpPort::bind(*addr, &opts).map_err(|source| UdpSideError::Socket { side: "ingress", source })?;
        let console = args.console_from.unwrap_or(ConsolePolicy::FirstDatagram);
        if console == ConsolePolicy::FirstDatagram {
            eprintln!(
                "emulator: WARNING: the UDP ingress udp://{} will take the first sender as its console (--console-from first): \
                 whoever sends first is trusted",
                port.local_addr()
            );
        }
        s.bound.ingress = Some(port.local_addr());
        s.ingress = Some(port.try_clone().map_err(|source| UdpSideError::Socket { side: "ingress", source })?);
        let source = UdpSource::new(port, s.arena.clone(), console, s.console.clone());
        Ok(match s.idle_end_ns {
            Some(ns) => source.with_idle_end(ns),
            None => source,
        })
    }

    fn describe(s: &UdpSession, args: &UdpArgs, ends: (&dyn fmt::Display, &dyn fmt::Display)) -> Option<String> {
        Some(format!(
            "ingress {}{}, egress {}{}, payload {:?}",
            ends.0,
            s.bound.ingress.map_or(String::new(), |x| format!(" (bound {x})")),
            ends.1,
            s.bound.egress_local.map_or(String::new(), |x| format!(" (from {x})")),
            args.payload,
        ))
    }

    type Report = UdpReport;
    const REPORT_FILE: &'static str = "udp.json";
    const START_FILE: Option<&'static str> = Some("udp_endpoints.json");

    fn at_start(s: &UdpSession) -> Option<serde_json::Value> {
        serde_json::to_value(&s.bound).ok()
    }

    /// The sockets, what the ingress took and refused, and the raw arena.
    fn report(s: &UdpSession, args: &UdpArgs, ends: (&dyn fmt::Display, &dyn fmt::Display), source: Option<&UdpSource>, _sink: Option<&UdpSink>) -> Option<UdpReport> {
        let arena = s.arena.as_ref().map(|a| a.borrow());
        Some(UdpReport {
            ingress: ends.0.to_string(),
            egress: ends.1.to_string(),
            payload: args.payload,
            ingress_local: s.bound.ingress,
            egress_local: s.bound.egress_local,
            datagrams_in: source.map(|s| s.taken()),
            ingress_kernel_drops: source.and_then(|s| s.port().kernel_drops()),
            ingress_buffer_bytes: source.and_then(|s| s.port().buffer_bytes().0),
            console: source.and_then(|s| s.console()),
            foreign_sender: source.map_or(0, |s| s.foreign().total),
            foreign_senders: source.map(|s| s.foreign().named().map(|(addr, datagrams)| ForeignSender { addr, datagrams }).collect()).unwrap_or_default(),
            foreign_unnamed: source.map_or(0, |s| s.foreign().unnamed),
            arena_slots: arena.as_ref().map(|a| a.slots()),
            arena_high_water: arena.as_ref().map(|a| a.high_water()),
            return_path: None,
            own_time_ns: None,
        })
    }

    /// The return path's report (the path `return`), and netfi's own time
    /// per datagram each way (each path's release lateness).
    fn attach(r: &mut UdpReport, paths: &BTreeMap<String, serde_json::Value>, forward_lateness: &crate::metrics::Summary) {
        r.return_path = paths.get(super::RETURN_PATH).cloned();
        let back = r.return_path.as_ref().and_then(|p| serde_json::from_value::<crate::metrics::Summary>(p["release_lateness_ns"].clone()).ok());
        r.own_time_ns = Some(OwnTime { forward: OwnPercentiles::of(forward_lateness), return_path: back.as_ref().map(OwnPercentiles::of) });
    }

    fn summary(r: &UdpReport) -> String {
        r.summary()
    }

    fn line(r: &UdpReport) -> Option<String> {
        Some(r.line())
    }

    fn faults(r: &UdpReport) -> Vec<String> {
        r.fault().into_iter().collect()
    }
}
