//! The UDP bridge: the emulator with `udp://` endpoints, so it can sit on the
//! network path between a console and a robot that speak ITP (or anything
//! else) over UDP, alone or mixed with the iceoryx2 ports.
//!
//! # Endpoints
//!
//! `--ingress` and `--egress` each take `iceoryx2` (the run's shared-memory
//! port, the default) or `udp://ADDR:PORT`, in any combination:
//!
//! | ingress | egress | what it is |
//! |---|---|---|
//! | `iceoryx2` | `iceoryx2` | the three local processes (`service::emulator`) |
//! | `udp://…` | `iceoryx2` | a network console feeding the local simulator |
//! | `iceoryx2` | `udp://…` | the local console driving a network robot |
//! | `udp://…` | `udp://…` | a UDP-to-UDP injector between two hosts or tools |
//!
//! The ingress socket binds to the given address; `udp://:PORT` (no
//! address) binds loopback, never a wildcard. The egress address is the
//! robot's; the emulator sends from an ephemeral port (on loopback when the
//! robot is on loopback) or from `--egress-bind`.
//!
//! # Payload modes
//!
//! - `itp`: a datagram is one ITP frame; it is received straight into the
//!   sample's wire bytes with its true length, so the emulator's own
//!   validation applies exactly as over iceoryx2: a wrong length is the drop
//!   `wrong_size`, a wrong checksum is counted and passed, or dropped as
//!   `bad_checksum` with `--drop-bad-checksum`.
//! - `raw`: any datagram up to 64 KiB, as opaque bytes (UDP → UDP only). It
//!   is received into a slot of the [`Arena`], which the UDP source and sink
//!   share; the sample carries the slot and the length and is flagged
//!   [`FrameSample::FLAG_RAW`]. The arena has one slot more than the release
//!   queue holds, so a slot is always free when a datagram arrives: the only
//!   way to run out of room is a full release queue, which the injector
//!   records as `queue_full`. A slot is freed when its datagram is sent or
//!   dropped.
//!
//! # The return path
//!
//! With UDP on both sides, what the robot sends back to the emulator's
//! egress socket (a status or feedback frame, a ping-pong reply) is relayed
//! from the ingress socket to the console: to the source address of the
//! latest ingress datagram, or to `--return-to`. It goes untouched, or
//! through a scenario of its own (`--return-scenario`) with its own seed,
//! queue, trace (`trace_return.csv`) and accounting. Return datagrams that
//! arrive before any console has been heard from have nowhere to go and are
//! counted as `unroutable`. The return path is polled from the same pinned
//! loop (inside the source's `try_recv`), so it costs no thread and no core.
//!
//! # Ending and reporting
//!
//! UDP has no end of stream. A run with UDP ingress ends on SIGINT/SIGTERM,
//! or with `--idle-end-ms` once no datagram has arrived for that long (the
//! source then hands the loop an end marker carrying the datagrams taken).
//! The emulator's report, trace and histograms are the same as over
//! iceoryx2; `udp.json` adds the sockets, the datagrams the kernel dropped
//! before the emulator could take them, and the return path's report.
//! `udp_endpoints.json`, written before `emulator.ready`, gives the bound
//! addresses (useful with port 0).

use crate::clock::now_ns;
use crate::injector::{Fate, Injector};
use crate::metrics::{LatencyHistogram, Summary};
use crate::sample::{FrameSample, ITP_FRAME_LEN};
use crate::scenario::Scenario;
use crate::service::args::EmulatorArgs;
use crate::service::emulator::{EmulatorConfig, EmulatorReport};
use crate::service::ports::{FrameSink, FrameSource, PortError};
use crate::stats::BatchMeans;
use crate::trace::{self, TraceEvent, TraceSink, TraceWriter};
use crate::transport::udp::{PeerAddr, UdpOptions, UdpPort, MAX_DATAGRAM_BYTES};
use anyhow::{bail, Context};
use serde::{Deserialize, Serialize};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::fmt;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::str::FromStr;

/// Default release-queue capacity in raw mode (and of a return-path
/// scenario): 4096 datagrams. Each needs an arena slot of 64 KiB of address
/// space (256 MiB in all, of which only the pages datagrams touch become
/// resident); `--queue-capacity` changes it.
pub const RAW_DEFAULT_QUEUE_CAPACITY: usize = 4096;

/// Bytes of one arena slot: any UDP payload fits.
pub const ARENA_SLOT_BYTES: usize = MAX_DATAGRAM_BYTES;

/// Default requested kernel buffer size of each UDP socket: 4 MiB, a
/// quarter of a second of 124-byte frames at 100 kHz (the kernel caps it at
/// `net.core.rmem_max`).
pub const DEFAULT_UDP_BUFFER_BYTES: usize = 4 << 20;

/// One side of the emulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// The run's iceoryx2 port.
    Iceoryx2,
    /// A UDP socket address.
    Udp(SocketAddr),
}

impl Endpoint {
    pub fn udp(&self) -> Option<SocketAddr> {
        match self {
            Endpoint::Udp(a) => Some(*a),
            Endpoint::Iceoryx2 => None,
        }
    }

    pub fn is_udp(&self) -> bool {
        matches!(self, Endpoint::Udp(_))
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::Iceoryx2 => f.write_str("iceoryx2"),
            Endpoint::Udp(a) => write!(f, "udp://{a}"),
        }
    }
}

/// Why an endpoint could not be parsed.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    /// Neither `iceoryx2` nor `udp://…`.
    #[error("`{text}`: expected `iceoryx2` or `udp://ADDR:PORT` (e.g. udp://127.0.0.1:36000, udp://:36000, udp://[::1]:36000)")]
    Scheme { text: String },
    /// `udp://` with no usable port.
    #[error("`{text}`: expected a port number 0..=65535 after the last `:`")]
    Port { text: String },
    /// The host part did not resolve.
    #[error("`{text}`: cannot resolve `{host}`: {source}")]
    Resolve {
        text: String,
        host: String,
        #[source]
        source: std::io::Error,
    },
    /// The host resolved to no address.
    #[error("`{text}`: `{host}` has no address")]
    NoAddress { text: String, host: String },
}

impl FromStr for Endpoint {
    type Err = EndpointError;

    /// `iceoryx2` (or `ipc`); `udp://ADDR:PORT` with an IPv4 address, a
    /// bracketed IPv6 address or a host name; `udp://:PORT` or `udp://PORT`
    /// for loopback (127.0.0.1).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        if text.eq_ignore_ascii_case("iceoryx2") || text.eq_ignore_ascii_case("ipc") {
            return Ok(Endpoint::Iceoryx2);
        }
        let Some(rest) = text.strip_prefix("udp://") else {
            return Err(EndpointError::Scheme { text: text.into() });
        };
        let rest = rest.strip_suffix('/').unwrap_or(rest);
        if let Ok(a) = rest.parse::<SocketAddr>() {
            return Ok(Endpoint::Udp(a));
        }
        let (host, port) = match rest.rsplit_once(':') {
            Some((h, p)) => (h, p),
            None => ("", rest),
        };
        let port: u16 = port.parse().map_err(|_| EndpointError::Port { text: text.into() })?;
        if host.is_empty() {
            return Ok(Endpoint::Udp(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port)));
        }
        let host_plain = host.trim_start_matches('[').trim_end_matches(']');
        let addrs: Vec<SocketAddr> = (host_plain, port)
            .to_socket_addrs()
            .map_err(|source| EndpointError::Resolve { text: text.into(), host: host.into(), source })?
            .collect();
        // Prefer IPv4 (as `localhost` is usually meant), else the first.
        let a = addrs.iter().find(|a| a.is_ipv4()).or(addrs.first()).copied();
        a.map(Endpoint::Udp).ok_or_else(|| EndpointError::NoAddress { text: text.into(), host: host.into() })
    }
}

/// What a UDP datagram carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Payload {
    /// One ITP frame (124 bytes, checksummed) per datagram, validated.
    #[default]
    Itp,
    /// Any datagram up to 64 KiB, forwarded as opaque bytes.
    Raw,
}

/// Fixed-size slots for datagrams in flight, allocated once at start-up.
///
/// Slots are handed out last-freed-first, so a steady stream keeps reusing
/// the same few (already resident, cache-warm) slots. The memory is zeroed
/// address space: pages become resident only when a datagram is written
/// into them.
#[derive(Debug)]
pub struct Arena {
    bytes: Vec<u8>,
    free: Vec<u32>,
    in_use: Vec<bool>,
    high_water: usize,
}

impl Arena {
    /// An arena of `slots` slots of [`ARENA_SLOT_BYTES`].
    pub fn new(slots: usize) -> Arena {
        assert!(slots >= 1 && slots <= u32::MAX as usize, "an arena needs 1..=2^32-1 slots, got {slots}");
        Arena {
            bytes: vec![0u8; slots * ARENA_SLOT_BYTES],
            free: (0..slots as u32).rev().collect(),
            in_use: vec![false; slots],
            high_water: 0,
        }
    }

    pub fn slots(&self) -> usize {
        self.in_use.len()
    }

    /// Slots in use now.
    pub fn used(&self) -> usize {
        self.slots() - self.free.len()
    }

    /// The most slots ever in use at once.
    pub fn high_water(&self) -> usize {
        self.high_water
    }

    /// A free slot, or `None` if all are in use.
    #[inline]
    pub fn alloc(&mut self) -> Option<u32> {
        let slot = self.free.pop()?;
        self.in_use[slot as usize] = true;
        self.high_water = self.high_water.max(self.used());
        Some(slot)
    }

    /// Gives `slot` back. Freeing a slot that is not in use is a broken
    /// invariant (a datagram sent or dropped twice) and panics.
    #[inline]
    pub fn free(&mut self, slot: u32) {
        let used = &mut self.in_use[slot as usize];
        assert!(*used, "arena slot {slot} freed twice");
        *used = false;
        self.free.push(slot);
    }

    #[inline]
    pub fn slot(&self, slot: u32) -> &[u8] {
        let at = slot as usize * ARENA_SLOT_BYTES;
        &self.bytes[at..at + ARENA_SLOT_BYTES]
    }

    #[inline]
    pub fn slot_mut(&mut self, slot: u32) -> &mut [u8] {
        let at = slot as usize * ARENA_SLOT_BYTES;
        &mut self.bytes[at..at + ARENA_SLOT_BYTES]
    }
}

/// The arena slot a raw sample refers to (kept in its first wire bytes).
#[inline]
fn raw_slot(s: &FrameSample) -> u32 {
    u32::from_le_bytes([s.wire[0], s.wire[1], s.wire[2], s.wire[3]])
}

fn port_error(port: &UdpPort, e: impl fmt::Display) -> PortError {
    PortError { port: format!("udp://{}", port.local_addr()), message: e.to_string() }
}

/// The emulator's source on a UDP socket (and, with UDP on both sides, the
/// return path's relay).
pub struct UdpSource {
    port: UdpPort,
    arena: Option<Rc<RefCell<Arena>>>,
    taken: u64,
    console: Option<PeerAddr>,
    ret: Option<ReturnPath>,
    idle_end_ns: Option<u64>,
    last_rx_ns: u64,
    ended: bool,
}

impl UdpSource {
    /// A source taking ITP frames (`arena: None`) or raw datagrams (into
    /// `arena`) off `port`.
    pub fn new(port: UdpPort, arena: Option<Rc<RefCell<Arena>>>) -> UdpSource {
        UdpSource { port, arena, taken: 0, console: None, ret: None, idle_end_ns: None, last_rx_ns: 0, ended: false }
    }

    /// Relay what comes back from the robot side (see the module docs).
    pub fn with_return_path(mut self, ret: ReturnPath) -> UdpSource {
        self.ret = Some(ret);
        self
    }

    /// End the stream after `idle_ns` without a datagram (once one came).
    pub fn with_idle_end(mut self, idle_ns: u64) -> UdpSource {
        self.idle_end_ns = Some(idle_ns);
        self
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.port.local_addr()
    }

    /// Datagrams taken off the socket.
    pub fn taken(&self) -> u64 {
        self.taken
    }

    /// The source address of the latest datagram.
    pub fn console(&self) -> Option<SocketAddr> {
        self.console.as_ref().map(PeerAddr::addr)
    }

    #[inline]
    fn idle(&mut self, out: &mut FrameSample) -> bool {
        if let Some(idle_ns) = self.idle_end_ns {
            if !self.ended && self.taken > 0 && now_ns().saturating_sub(self.last_rx_ns) > idle_ns {
                self.ended = true;
                *out = FrameSample::end_marker(self.taken);
                return true;
            }
        }
        false
    }
}

impl FrameSource for UdpSource {
    #[inline]
    fn try_recv(&mut self, out: &mut FrameSample) -> Result<bool, PortError> {
        if let Some(ret) = self.ret.as_mut() {
            ret.poll(&self.port, self.console.as_ref());
        }
        let (got, slot) = match &self.arena {
            None => (self.port.recv_from(&mut out.wire), None),
            Some(arena) => {
                let mut a = arena.borrow_mut();
                let slot = a.alloc().expect("the arena has one slot more than the release queue can hold");
                let got = self.port.recv_from(a.slot_mut(slot));
                if !matches!(got, Ok(Some(_))) {
                    a.free(slot);
                }
                (got, Some(slot))
            }
        };
        match got {
            Ok(Some(d)) => {
                let now = now_ns();
                self.last_rx_ns = now;
                if self.console.as_ref().map(PeerAddr::addr) != Some(d.from) {
                    self.console = Some(PeerAddr::new(d.from));
                }
                out.send_ns = now;
                out.console_index = self.taken;
                out.ingress_index = 0;
                out.ingress_ns = 0;
                out.injected_delay_ns = 0;
                out.release_sched_ns = 0;
                out.release_ns = 0;
                out.len = u32::try_from(d.len).unwrap_or(u32::MAX);
                match slot {
                    None => {
                        out.flags = 0;
                        // Bytes past a short datagram are not part of it.
                        if d.len < ITP_FRAME_LEN {
                            out.wire[d.len..].fill(0);
                        }
                    }
                    Some(slot) => {
                        out.flags = FrameSample::FLAG_RAW;
                        out.wire = [0; ITP_FRAME_LEN];
                        out.wire[..4].copy_from_slice(&slot.to_le_bytes());
                    }
                }
                self.taken += 1;
                Ok(true)
            }
            Ok(None) => Ok(self.idle(out)),
            Err(e) => Err(port_error(&self.port, e)),
        }
    }

    #[inline]
    fn dropped(&mut self, sample: &FrameSample) {
        if sample.is_raw() {
            if let Some(arena) = &self.arena {
                arena.borrow_mut().free(raw_slot(sample));
            }
        }
    }
}

/// The emulator's sink on a UDP socket: each released sample becomes one
/// datagram to the robot's address.
pub struct UdpSink {
    port: UdpPort,
    to: PeerAddr,
    arena: Option<Rc<RefCell<Arena>>>,
}

impl UdpSink {
    /// Sends from `port` to `to`; raw samples' bytes come from `arena`.
    pub fn new(port: UdpPort, to: SocketAddr, arena: Option<Rc<RefCell<Arena>>>) -> UdpSink {
        UdpSink { port, to: PeerAddr::new(to), arena }
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.port.local_addr()
    }
}

impl FrameSink for UdpSink {
    #[inline]
    fn send_with(
        &mut self,
        sample: &FrameSample,
        stamp: impl FnOnce(&mut FrameSample),
    ) -> Result<Option<usize>, PortError> {
        // UDP has no end of stream: the end marker is not a datagram.
        if sample.is_end() {
            return Ok(None);
        }
        let mut s = *sample;
        stamp(&mut s);
        let sent = if s.is_raw() {
            let arena = self.arena.as_ref().expect("a raw sample reaches only a sink that shares the source's arena");
            let mut a = arena.borrow_mut();
            let slot = raw_slot(&s);
            let len = (s.len as usize).min(ARENA_SLOT_BYTES);
            let sent = self.port.send_to(&a.slot(slot)[..len], &self.to);
            a.free(slot);
            sent
        } else {
            self.port.send_to(s.payload(), &self.to)
        };
        sent.map(|()| None).map_err(|e| port_error(&self.port, e))
    }
}

/// A return datagram held by the return path's scenario.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Held {
    slot: u32,
    len: u32,
    ingress_ns: u64,
}

/// The return path's scenario, queue, arena and measurements.
struct Shaped {
    name: String,
    seed: u64,
    inj: Injector<Held>,
    arena: Arena,
    tsink: TraceSink,
    twriter: Option<TraceWriter>,
    decision: LatencyHistogram,
    lateness: LatencyHistogram,
    injected: LatencyHistogram,
    batches: BatchMeans,
}

/// Counts of the return path.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct ReturnCounts {
    received: u64,
    unroutable: u64,
    relayed: u64,
    send_errors: u64,
    receive_errors: u64,
}

/// Relays datagrams from the robot side back to the console (see the module
/// docs). Owned by the [`UdpSource`], which polls it on every call.
pub struct ReturnPath {
    port: UdpPort,
    to: Option<PeerAddr>,
    buf: Box<[u8]>,
    shaped: Option<Box<Shaped>>,
    counts: ReturnCounts,
}

impl ReturnPath {
    /// Relays untouched what arrives at `port` (a handle on the egress
    /// socket), to `to` or else to the console's latest address.
    pub fn untouched(port: UdpPort, to: Option<SocketAddr>) -> ReturnPath {
        ReturnPath {
            port,
            to: to.map(PeerAddr::new),
            buf: vec![0u8; MAX_DATAGRAM_BYTES].into_boxed_slice(),
            shaped: None,
            counts: ReturnCounts::default(),
        }
    }

    /// Relays through `scenario` (seeded with `seed`), holding at most
    /// `queue_capacity` datagrams; `expected` sizes the trace and the loss
    /// interval's batches. Starts the return trace's writer thread (call
    /// before the loop pins its core).
    pub fn shaped(
        port: UdpPort,
        to: Option<SocketAddr>,
        scenario: Scenario,
        seed: u64,
        queue_capacity: usize,
        expected: u64,
    ) -> ReturnPath {
        let (tsink, twriter) = trace::start(expected.min(50_000_000) as usize);
        let shaped = Shaped {
            name: scenario.name().to_string(),
            seed,
            inj: Injector::new(scenario, queue_capacity),
            arena: Arena::new(queue_capacity + 1),
            tsink,
            twriter: Some(twriter),
            decision: LatencyHistogram::new(),
            lateness: LatencyHistogram::new(),
            injected: LatencyHistogram::new(),
            batches: BatchMeans::new(expected.max(1)),
        };
        ReturnPath {
            port,
            to: to.map(PeerAddr::new),
            buf: Box::default(),
            shaped: Some(Box::new(shaped)),
            counts: ReturnCounts::default(),
        }
    }

    /// Releases what is due, then takes at most one datagram from the robot
    /// side. Sends go out of `ingress`, so the console sees replies come
    /// from the address it sends to.
    #[inline]
    fn poll(&mut self, ingress: &UdpPort, console: Option<&PeerAddr>) {
        let dest = self.to.as_ref().or(console);
        let c = &mut self.counts;
        match self.shaped.as_deref_mut() {
            None => match self.port.recv_from(&mut self.buf) {
                Ok(Some(d)) => {
                    c.received += 1;
                    match dest {
                        None => c.unroutable += 1,
                        Some(to) => match ingress.send_to(&self.buf[..d.len.min(MAX_DATAGRAM_BYTES)], to) {
                            Ok(()) => c.relayed += 1,
                            Err(_) => c.send_errors += 1,
                        },
                    }
                }
                Ok(None) => {}
                Err(_) => c.receive_errors += 1,
            },
            Some(s) => {
                let now = now_ns();
                while let Some(r) = s.inj.pop_due(now) {
                    let bytes = &s.arena.slot(r.item.slot)[..r.item.len as usize];
                    let release_ns = now_ns();
                    // A datagram enters only once a console is known, and
                    // one stays known: `dest` is set here.
                    if dest.map(|to| ingress.send_to(bytes, to)).is_none_or(|sent| sent.is_err()) {
                        c.send_errors += 1;
                    }
                    s.arena.free(r.item.slot);
                    s.lateness.record(release_ns.saturating_sub(r.release_ns));
                    s.injected.record(r.release_ns - r.item.ingress_ns);
                    s.tsink.push(TraceEvent::Release { ingress_index: r.ingress_index, release_ns });
                }
                let slot = s.arena.alloc().expect("the return arena has one slot more than its queue can hold");
                match self.port.recv_from(s.arena.slot_mut(slot)) {
                    Ok(Some(d)) => {
                        c.received += 1;
                        if dest.is_none() {
                            c.unroutable += 1;
                            s.arena.free(slot);
                            return;
                        }
                        let t_take = now_ns();
                        let len = d.len.min(ARENA_SLOT_BYTES) as u32;
                        let e = s.inj.ingress(t_take, Held { slot, len, ingress_ns: t_take });
                        s.decision.record(now_ns() - t_take);
                        let (dropped, release_sched_ns) = match e.fate {
                            Fate::Scheduled { release_ns, .. } => (None, release_ns),
                            Fate::Dropped(cause) => {
                                s.arena.free(slot);
                                (Some(cause), 0)
                            }
                        };
                        s.batches.record(dropped.is_some());
                        s.tsink.push(TraceEvent::Ingress {
                            ingress_index: e.ingress_index,
                            sequence: None,
                            console_index: c.received - 1,
                            send_ns: t_take,
                            ingress_ns: t_take,
                            dropped,
                            release_sched_ns,
                        });
                    }
                    Ok(None) => s.arena.free(slot),
                    Err(_) => {
                        s.arena.free(slot);
                        c.receive_errors += 1;
                    }
                }
            }
        }
    }

    /// Stops the trace writer, writes `trace_return.csv` (when shaped) into
    /// `out_dir`, and reports.
    fn finish(&mut self, out_dir: &Path) -> anyhow::Result<ReturnReport> {
        let c = self.counts;
        let destination =
            self.to.as_ref().map_or("the console's latest address".to_string(), |t| format!("udp://{}", t.addr()));
        let kernel_drops = self.port.kernel_drops();
        let Some(s) = self.shaped.as_deref_mut() else {
            return Ok(ReturnReport {
                mode: "untouched".into(),
                scenario: None,
                seed: None,
                destination,
                received: c.received,
                unroutable: c.unroutable,
                entered: c.received - c.unroutable,
                delivered: c.relayed + c.send_errors,
                dropped: BTreeMap::new(),
                held_at_end: 0,
                send_errors: c.send_errors,
                receive_errors: c.receive_errors,
                kernel_drops,
                loss_rate: None,
                loss_rate_ci95: None,
                injected_delay_ns: None,
                decision_ns: None,
                release_lateness_ns: None,
                trace_path: None,
            });
        };
        let counts = s.inj.counts();
        assert!(counts.balanced(), "return-path accounting broken: {counts:?}");
        let rows = s.twriter.take().map(TraceWriter::finish).unwrap_or_default();
        let trace_path = out_dir.join("trace_return.csv");
        trace::write_csv(&trace_path, &rows, &[]).with_context(|| format!("writing {}", trace_path.display()))?;
        let (loss_rate, ci) = s.batches.rate_ci95();
        Ok(ReturnReport {
            mode: "scenario".into(),
            scenario: Some(s.name.clone()),
            seed: Some(s.seed),
            destination,
            received: c.received,
            unroutable: c.unroutable,
            entered: counts.entered,
            delivered: counts.released,
            dropped: s.inj.drops_by_reason().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
            held_at_end: counts.held,
            send_errors: c.send_errors,
            receive_errors: c.receive_errors,
            kernel_drops,
            loss_rate: Some(loss_rate),
            loss_rate_ci95: Some(ci),
            injected_delay_ns: Some(s.injected.summary()),
            decision_ns: Some(s.decision.summary()),
            release_lateness_ns: Some(s.lateness.summary()),
            trace_path: Some(trace_path),
        })
    }
}

/// The return path's report: `received = entered + unroutable` and
/// `entered = delivered + dropped + held_at_end`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReturnReport {
    /// `untouched` or `scenario`.
    pub mode: String,
    pub scenario: Option<String>,
    pub seed: Option<u64>,
    /// Where return datagrams go.
    pub destination: String,
    /// Datagrams taken off the egress socket.
    pub received: u64,
    /// Received before any console was known: not relayed.
    pub unroutable: u64,
    pub entered: u64,
    /// Released towards the console (including those whose send failed).
    pub delivered: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    pub send_errors: u64,
    pub receive_errors: u64,
    /// Return datagrams the kernel dropped before the emulator took them.
    pub kernel_drops: Option<u64>,
    pub loss_rate: Option<f64>,
    pub loss_rate_ci95: Option<[f64; 2]>,
    pub injected_delay_ns: Option<Summary>,
    pub decision_ns: Option<Summary>,
    pub release_lateness_ns: Option<Summary>,
    pub trace_path: Option<PathBuf>,
}

/// `udp.json`: the UDP side of an emulator run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UdpReport {
    pub ingress: String,
    pub egress: String,
    pub payload: Payload,
    /// Address the ingress socket is bound to.
    pub ingress_local: Option<SocketAddr>,
    /// Address the egress socket sends from.
    pub egress_local: Option<SocketAddr>,
    /// Datagrams taken off the ingress socket (each entered the emulator).
    pub datagrams_in: Option<u64>,
    /// Datagrams the kernel dropped at the ingress socket (receive buffer
    /// full) before the emulator could take them: they never entered.
    pub ingress_kernel_drops: Option<u64>,
    /// Receive buffer of the ingress socket as granted, bytes.
    pub ingress_buffer_bytes: Option<usize>,
    /// The console's address (source of the latest ingress datagram).
    pub console: Option<SocketAddr>,
    /// Raw mode: arena slots, and the most ever in use at once.
    pub arena_slots: Option<usize>,
    pub arena_high_water: Option<usize>,
    pub return_path: Option<ReturnReport>,
}

/// The endpoints as bound, written to `udp_endpoints.json` before
/// `emulator.ready`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoundEndpoints {
    pub ingress: Option<SocketAddr>,
    pub egress_local: Option<SocketAddr>,
    pub egress_peer: Option<SocketAddr>,
}

/// Checks that the UDP options fit the endpoints, with errors that say what
/// would be accepted.
fn validate(args: &EmulatorArgs) -> anyhow::Result<()> {
    let (i, e) = (args.ingress.is_udp(), args.egress.is_udp());
    if args.payload == Payload::Raw && !(i && e) {
        bail!("--payload raw needs UDP on both sides (--ingress udp://… --egress udp://…): an iceoryx2 port carries ITP frames only");
    }
    let return_opts = args.return_scenario.is_some() || args.return_to.is_some() || args.return_seed.is_some();
    if return_opts && !(i && e) {
        bail!(
            "--return-scenario, --return-to and --return-seed apply to the return path, which needs UDP on both sides"
        );
    }
    if args.no_return && return_opts {
        bail!("--no-return cannot be combined with --return-scenario, --return-to or --return-seed");
    }
    if args.idle_end_ms.is_some() && !i {
        bail!("--idle-end-ms applies to a UDP ingress; an iceoryx2 console ends its stream itself");
    }
    if let Some(ms) = args.idle_end_ms {
        if !(ms.is_finite() && ms > 0.0) {
            bail!("--idle-end-ms must be a positive number of milliseconds, got {ms}");
        }
    }
    if args.egress_bind.is_some() && !e {
        bail!("--egress-bind applies to a UDP egress");
    }
    if let Some(a) = args.egress.udp() {
        if a.port() == 0 || a.ip().is_unspecified() {
            bail!("--egress {}: the robot's address needs a specific address and a port other than 0", args.egress);
        }
    }
    if !(i && e) && args.run_id.is_none() {
        bail!("--run-id is needed for the iceoryx2 side (ingress {}, egress {})", args.ingress, args.egress);
    }
    Ok(())
}

/// Runs the emulator with at least one UDP endpoint (called by
/// `service::emulator::main`, which has resolved the scenario, seed, queue
/// and core into `cfg`).
pub fn main(args: &EmulatorArgs, cfg: EmulatorConfig) -> anyhow::Result<EmulatorReport> {
    use crate::service::{emulator, ipc, signals};
    use crate::transport::{Channel, Role};
    validate(args)?;
    let opts = UdpOptions { reuse_address: true, buffer_bytes: Some(args.udp_buffer_bytes) };
    let arena = (args.payload == Payload::Raw).then(|| Rc::new(RefCell::new(Arena::new(cfg.queue_capacity + 1))));

    let egress = match args.egress.udp() {
        Some(peer) => {
            let port = match args.egress_bind {
                Some(local) => UdpPort::bind(local, &UdpOptions { reuse_address: false, ..opts }),
                None => UdpPort::bind_towards(peer, &UdpOptions { reuse_address: false, ..opts }),
            }
            .context("opening the UDP egress socket")?;
            Some((port, peer))
        }
        None => None,
    };
    let source = match args.ingress.udp() {
        Some(addr) => {
            let port = UdpPort::bind(addr, &opts).context("opening the UDP ingress socket")?;
            let mut s = UdpSource::new(port, arena.clone());
            if let (Some((eport, _)), false) = (&egress, args.no_return) {
                let rport = eport.try_clone().context("opening the return path")?;
                let to = match &args.return_to {
                    Some(Endpoint::Udp(a)) => Some(*a),
                    Some(Endpoint::Iceoryx2) => bail!("--return-to takes udp://ADDR:PORT"),
                    None => None,
                };
                let ret = match &args.return_scenario {
                    None => ReturnPath::untouched(rport, to),
                    Some(name) => {
                        let spec =
                            crate::scenario::resolve(name).with_context(|| format!("--return-scenario {name}"))?;
                        let seed = args
                            .return_seed
                            .or(spec.seed)
                            .unwrap_or_else(|| crate::scenario::splitmix64(cfg.seed ^ 0x7265_7475_726e));
                        let capacity = spec.queue_capacity.unwrap_or(RAW_DEFAULT_QUEUE_CAPACITY);
                        anyhow::ensure!(capacity >= 1, "the return scenario's queue_capacity must be at least 1");
                        let scenario =
                            Scenario::new(&spec, seed).with_context(|| format!("--return-scenario {name}"))?;
                        eprintln!("emulator: return path through scenario {} seed {seed}, queue {capacity}", spec.name);
                        ReturnPath::shaped(rport, to, scenario, seed, capacity, cfg.expected_frames)
                    }
                };
                s = s.with_return_path(ret);
            }
            if let Some(ms) = args.idle_end_ms {
                s = s.with_idle_end((ms * 1e6) as u64);
            }
            Some(s)
        }
        None => None,
    };
    let mut sink = egress.map(|(port, peer)| UdpSink::new(port, peer, arena.clone()));

    let bound = BoundEndpoints {
        ingress: source.as_ref().map(UdpSource::local_addr),
        egress_local: sink.as_ref().map(UdpSink::local_addr),
        egress_peer: args.egress.udp(),
    };
    eprintln!(
        "emulator: scenario {} seed {}, queue {}, core {:?}; ingress {}{}, egress {}{}, payload {:?}",
        cfg.scenario.name,
        cfg.seed,
        cfg.queue_capacity,
        cfg.core,
        args.ingress,
        bound.ingress.map_or(String::new(), |a| format!(" (bound {a})")),
        args.egress,
        bound.egress_local.map_or(String::new(), |a| format!(" (from {a})")),
        args.payload,
    );
    std::fs::create_dir_all(&cfg.out_dir).with_context(|| format!("creating {}", cfg.out_dir.display()))?;
    let node = match args.run_id.as_deref().filter(|_| !(args.ingress.is_udp() && args.egress.is_udp())) {
        Some(run_id) => Some(ipc::open_node(run_id, Role::Emulator)?),
        None => None,
    };
    signals::install();
    let ready = |out: &Path| -> anyhow::Result<()> {
        let p = out.join("udp_endpoints.json");
        std::fs::write(&p, serde_json::to_vec_pretty(&bound)?).with_context(|| format!("writing {}", p.display()))?;
        std::fs::write(out.join("emulator.ready"), b"").context("writing emulator.ready")
    };

    // iceoryx2, once a node is open, may take SIGINT/SIGTERM for itself.
    let mut check = signals::StopCheck::new(256, || node.as_ref().is_some_and(|n| n.termination_requested()));
    let stop = move || check.requested();
    let mut source = source;
    let report = match (&mut source, &mut sink, &node) {
        (Some(src), Some(snk), _) => {
            ready(&cfg.out_dir)?;
            emulator::run(&cfg, src, snk, stop)?
        }
        (Some(src), None, Some(node)) => {
            let mut publisher = node.publisher(Channel::Emulator).context("opening the emulator → simulator port")?;
            ready(&cfg.out_dir)?;
            emulator::run(&cfg, src, &mut publisher, stop)?
        }
        (None, Some(snk), Some(node)) => {
            let mut subscriber = node.subscriber(Channel::Console).context("opening the console → emulator port")?;
            ready(&cfg.out_dir)?;
            emulator::run(&cfg, &mut subscriber, snk, stop)?
        }
        _ => bail!("the UDP bridge needs a UDP ingress or egress (ingress {}, egress {})", args.ingress, args.egress),
    };

    let return_path = match source.as_mut().and_then(|s| s.ret.as_mut()) {
        Some(r) => Some(r.finish(&cfg.out_dir)?),
        None => None,
    };
    let udp = UdpReport {
        ingress: args.ingress.to_string(),
        egress: args.egress.to_string(),
        payload: args.payload,
        ingress_local: bound.ingress,
        egress_local: bound.egress_local,
        datagrams_in: source.as_ref().map(UdpSource::taken),
        ingress_kernel_drops: source.as_ref().and_then(|s| s.port.kernel_drops()),
        ingress_buffer_bytes: source.as_ref().and_then(|s| s.port.buffer_bytes().0),
        console: source.as_ref().and_then(UdpSource::console),
        arena_slots: arena.as_ref().map(|a| a.borrow().slots()),
        arena_high_water: arena.as_ref().map(|a| a.borrow().high_water()),
        return_path,
    };
    let path = cfg.out_dir.join("udp.json");
    std::fs::write(&path, serde_json::to_vec_pretty(&udp)?).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("{}", summary_line(&report, &udp));
    Ok(report)
}

/// One line for the log: what came in, what went out, what the kernel and
/// the return path did.
fn summary_line(r: &EmulatorReport, u: &UdpReport) -> String {
    let f = &r.frames;
    let dropped: u64 = f.dropped.values().sum();
    let mut s = format!(
        "emulator: {} entered, {} delivered, {} dropped {:?}, {} held at end; ended by {}",
        f.entered, f.delivered, dropped, f.dropped, f.held_at_end, r.ended_by
    );
    if let Some(k) = u.ingress_kernel_drops.filter(|k| *k > 0) {
        s += &format!("; {k} datagrams dropped by the kernel before ingress");
    }
    if let Some(rp) = &u.return_path {
        let rd: u64 = rp.dropped.values().sum();
        s += &format!(
            "; return path ({}): {} received, {} delivered, {} dropped, {} held, {} unroutable",
            rp.mode, rp.received, rp.delivered, rd, rp.held_at_end, rp.unroutable
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_parse_with_loopback_by_default() {
        let ep = |s: &str| s.parse::<Endpoint>().unwrap();
        assert_eq!(ep("iceoryx2"), Endpoint::Iceoryx2);
        assert_eq!(ep("udp://127.0.0.1:36000"), Endpoint::Udp("127.0.0.1:36000".parse().unwrap()));
        assert_eq!(ep("udp://:36000"), Endpoint::Udp("127.0.0.1:36000".parse().unwrap()));
        assert_eq!(ep("udp://36000"), Endpoint::Udp("127.0.0.1:36000".parse().unwrap()));
        assert_eq!(ep("udp://[::1]:5"), Endpoint::Udp("[::1]:5".parse().unwrap()));
        assert_eq!(ep("udp://0.0.0.0:36000"), Endpoint::Udp("0.0.0.0:36000".parse().unwrap()));
        assert_eq!(ep("udp://localhost:7"), Endpoint::Udp("127.0.0.1:7".parse().unwrap()));
        assert_eq!(ep("udp://127.0.0.1:36000").to_string(), "udp://127.0.0.1:36000");
    }

    #[test]
    fn bad_endpoints_say_what_is_accepted() {
        let e = "tcp://1.2.3.4:5".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Scheme { .. }) && e.to_string().contains("udp://ADDR:PORT"), "{e}");
        let e = "udp://127.0.0.1:http".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Port { .. }), "{e}");
        let e = "udp://127.0.0.1:70000".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Port { .. }), "{e}");
    }

    #[test]
    fn the_arena_reuses_the_last_freed_slot_and_tracks_its_high_water() {
        let mut a = Arena::new(3);
        let s0 = a.alloc().unwrap();
        let s1 = a.alloc().unwrap();
        assert_eq!((s0, s1), (0, 1));
        a.slot_mut(s1)[..3].copy_from_slice(b"abc");
        a.free(s1);
        assert_eq!(a.alloc(), Some(s1));
        assert_eq!(&a.slot(s1)[..3], b"abc");
        assert!(a.alloc().is_some());
        assert_eq!(a.alloc(), None, "three slots");
        assert_eq!((a.used(), a.high_water()), (3, 3));
    }

    #[test]
    #[should_panic(expected = "freed twice")]
    fn freeing_a_slot_twice_is_a_broken_invariant() {
        let mut a = Arena::new(2);
        let s = a.alloc().unwrap();
        a.free(s);
        a.free(s);
    }

    fn loopback() -> UdpPort {
        UdpPort::bind("127.0.0.1:0".parse().unwrap(), &UdpOptions::default()).unwrap()
    }

    fn recv_one(src: &mut UdpSource) -> FrameSample {
        let mut s = FrameSample::ZERO;
        let t0 = std::time::Instant::now();
        while !src.try_recv(&mut s).unwrap() {
            assert!(t0.elapsed().as_secs() < 5, "loopback datagram never arrived");
        }
        s
    }

    #[test]
    fn an_itp_source_keeps_the_true_length_and_a_raw_one_the_slot() {
        let console = loopback();
        let mut itp = UdpSource::new(loopback(), None);
        let to = PeerAddr::new(itp.local_addr());
        console.send_to(&[1u8; 300], &to).unwrap();
        let s = recv_one(&mut itp);
        assert_eq!((s.len, s.flags, s.console_index), (300, 0, 0));
        assert_eq!(itp.console(), Some(console.local_addr()));
        console.send_to(&[2u8; 10], &to).unwrap();
        let s = recv_one(&mut itp);
        assert_eq!((s.len, s.console_index), (10, 1));
        assert_eq!(&s.wire[..12], &[2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 0, 0], "bytes past the datagram are zero");

        let arena = Rc::new(RefCell::new(Arena::new(2)));
        let mut raw = UdpSource::new(loopback(), Some(arena.clone()));
        console.send_to(&[3u8; 2000], &PeerAddr::new(raw.local_addr())).unwrap();
        let s = recv_one(&mut raw);
        assert!(s.is_raw());
        assert_eq!(s.len, 2000);
        assert_eq!(arena.borrow().used(), 1);
        assert_eq!(&arena.borrow().slot(raw_slot(&s))[..2000], &[3u8; 2000][..]);
        raw.dropped(&s);
        assert_eq!(arena.borrow().used(), 0, "a dropped datagram frees its slot");
    }

    #[test]
    fn a_sink_sends_raw_bytes_from_the_arena_and_never_the_end_marker() {
        let robot = loopback();
        let arena = Rc::new(RefCell::new(Arena::new(2)));
        let mut sink = UdpSink::new(loopback(), robot.local_addr(), Some(arena.clone()));
        let slot = arena.borrow_mut().alloc().unwrap();
        arena.borrow_mut().slot_mut(slot)[..5].copy_from_slice(b"hello");
        let mut s = FrameSample { len: 5, flags: FrameSample::FLAG_RAW, ..FrameSample::ZERO };
        s.wire[..4].copy_from_slice(&slot.to_le_bytes());
        let mut stamped = false;
        sink.send_with(&s, |_| stamped = true).unwrap();
        assert!(stamped);
        assert_eq!(arena.borrow().used(), 0, "a sent datagram frees its slot");
        sink.send_with(&FrameSample::end_marker(1), |_| {}).unwrap();
        let mut buf = [0u8; 64];
        let t0 = std::time::Instant::now();
        let d = loop {
            if let Some(d) = robot.recv_from(&mut buf).unwrap() {
                break d;
            }
            assert!(t0.elapsed().as_secs() < 5);
        };
        assert_eq!(&buf[..d.len], b"hello");
        std::thread::sleep(std::time::Duration::from_millis(20));
        assert!(robot.recv_from(&mut buf).unwrap().is_none(), "the end marker is not a datagram");
    }

    #[test]
    fn an_idle_source_ends_the_stream_once() {
        let console = loopback();
        let mut src = UdpSource::new(loopback(), None).with_idle_end(1_000_000);
        let mut s = FrameSample::ZERO;
        std::thread::sleep(std::time::Duration::from_millis(3));
        assert!(!src.try_recv(&mut s).unwrap(), "no end before the first datagram");
        console.send_to(&[0u8; 124], &PeerAddr::new(src.local_addr())).unwrap();
        recv_one(&mut src);
        std::thread::sleep(std::time::Duration::from_millis(3));
        assert!(src.try_recv(&mut s).unwrap() && s.is_end() && s.console_index == 1);
        assert!(!src.try_recv(&mut s).unwrap(), "the end comes once");
    }
}
