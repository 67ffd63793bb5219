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
//! | `iceoryx2` | `iceoryx2` | the three local processes |
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
//!   is received into a slot of the [`Arena`], which the UDP source and
//!   sink share; the sample carries the slot and the length and is flagged
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
//! from the ingress socket to the console: to its address (`--console-from`,
//! or the first sender's, locked; see [`crate::transport::udp::UdpSource`]), or to `--return-to`. It goes untouched, or
//! through a scenario of its own (`--return-scenario`) with its own seed,
//! queue, trace (`trace_return.csv`) and accounting. Return datagrams that
//! arrive before any console has been heard from have nowhere to go and are
//! counted as `unroutable`. The return path is polled by the same pinned
//! loop, once per turn, so it costs no thread and no core; when shaped it is
//! a [`Link`] of its own.
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
use crate::injector::Fate;
use crate::metrics::Summary;
use crate::scenario::Scenario;
use crate::service::args::EmulatorArgs;
use crate::service::link::{Arrival, Carried, Link, Release};
use crate::transport::udp::{Arena, PeerAddr, UdpPort, ARENA_SLOT_BYTES, MAX_DATAGRAM_BYTES};
use crate::transport::{Endpoint, Payload, PortError, Transports};
use anyhow::{bail, Context};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

/// Default release-queue capacity in raw mode (and of a return-path
/// scenario): 4096 datagrams. Each needs an arena slot of 64 KiB of address
/// space (256 MiB in all, of which only the pages datagrams touch become
/// resident); `--queue-capacity` changes it.
pub const RAW_DEFAULT_QUEUE_CAPACITY: usize = 4096;

/// A return datagram held by the return path's scenario.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Held {
    slot: u32,
    len: u32,
    ingress_ns: u64,
}

impl Carried for Held {
    #[inline]
    fn ingress_ns(&self) -> u64 {
        self.ingress_ns
    }
}

/// Where the return link releases: out of the ingress socket to the
/// console, the bytes from the return arena (whose slot is then freed).
struct Relay<'a> {
    port: &'a UdpPort,
    dest: Option<&'a PeerAddr>,
    arena: &'a mut Arena,
}

impl Release<Held> for Relay<'_> {
    #[inline]
    fn release(&mut self, item: &Held, _scheduled_ns: u64) -> Result<u64, (u64, PortError)> {
        let bytes = &self.arena.slot(item.slot)[..item.len as usize];
        let release_ns = now_ns();
        // A datagram enters only once a console is known, and one stays
        // known: `dest` is set here.
        let sent = match self.dest {
            Some(to) => self.port.send_to(bytes, to).map_err(|e| e.to_string()),
            None => Err("no console to return to".to_string()),
        };
        self.arena.free(item.slot);
        sent.map(|()| release_ns)
            .map_err(|message| (release_ns, PortError { port: format!("udp://{}", self.port.local_addr()), message }))
    }
}

/// The return path's scenario and arena.
struct Shaped {
    seed: u64,
    link: Link<Held>,
    arena: Arena,
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
/// docs). The emulator's loop polls it once per turn.
pub struct ReturnPath {
    /// A handle on the egress socket: what the robot sends back.
    from_robot: UdpPort,
    /// A handle on the ingress socket: the console sees replies come from
    /// the address it sends to.
    to_console: UdpPort,
    to: Option<PeerAddr>,
    buf: Box<[u8]>,
    shaped: Option<Box<Shaped>>,
    counts: ReturnCounts,
}

impl ReturnPath {
    /// Relays untouched what arrives at `from_robot`, out of `to_console`,
    /// to `to` or else to the console's address.
    pub fn untouched(from_robot: UdpPort, to_console: UdpPort, to: Option<SocketAddr>) -> ReturnPath {
        ReturnPath {
            from_robot,
            to_console,
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
        from_robot: UdpPort,
        to_console: UdpPort,
        to: Option<SocketAddr>,
        scenario: Scenario,
        seed: u64,
        queue_capacity: usize,
        expected: u64,
    ) -> anyhow::Result<ReturnPath> {
        let shaped =
            Shaped { seed, link: Link::new(scenario, queue_capacity, expected)?, arena: Arena::new(queue_capacity + 1) };
        Ok(ReturnPath {
            from_robot,
            to_console,
            to: to.map(PeerAddr::new),
            buf: Box::default(),
            shaped: Some(Box::new(shaped)),
            counts: ReturnCounts::default(),
        })
    }

    /// Keeps a shaped path's trace writer off `core` (the loop's); `false`
    /// where it may use no other core.
    pub fn keep_trace_off_core(&self, core: usize) -> bool {
        self.shaped.as_ref().is_none_or(|s| s.link.keep_trace_off_core(core))
    }

    /// Releases what is due, then takes at most one datagram from the robot
    /// side. `console` is the ingress's console.
    #[inline]
    pub fn poll(&mut self, console: Option<&PeerAddr>) {
        let Some(s) = self.shaped.as_deref_mut() else { return self.relay_one(console) };
        let dest = self.to.as_ref().or(console);
        let c = &mut self.counts;
        s.link.release_due(now_ns(), &mut Relay { port: &self.to_console, dest, arena: &mut s.arena });
        let slot = s.arena.alloc().expect("the return arena has one slot more than its queue can hold");
        match self.from_robot.recv_from(s.arena.slot_mut(slot)) {
            Ok(Some(d)) => {
                c.received += 1;
                if dest.is_none() {
                    c.unroutable += 1;
                    s.arena.free(slot);
                    return;
                }
                let t_take = now_ns();
                let len = d.len.min(ARENA_SLOT_BYTES) as u32;
                let arrival = Arrival { sequence: None, console_index: c.received - 1, send_ns: t_take };
                let e = s.link.ingress(t_take, Held { slot, len, ingress_ns: t_take }, arrival);
                if let Fate::Dropped(_) = e.fate {
                    s.arena.free(slot);
                }
            }
            Ok(None) => s.arena.free(slot),
            Err(_) => {
                s.arena.free(slot);
                c.receive_errors += 1;
            }
        }
    }

    /// Untouched: at most one datagram from the robot side, straight on.
    #[inline]
    fn relay_one(&mut self, console: Option<&PeerAddr>) {
        let dest = self.to.as_ref().or(console);
        let c = &mut self.counts;
        match self.from_robot.recv_from(&mut self.buf) {
            Ok(Some(d)) => {
                c.received += 1;
                match dest {
                    None => c.unroutable += 1,
                    Some(to) => match self.to_console.send_to(&self.buf[..d.len.min(MAX_DATAGRAM_BYTES)], to) {
                        Ok(()) => c.relayed += 1,
                        Err(_) => c.send_errors += 1,
                    },
                }
            }
            Ok(None) => {}
            Err(_) => c.receive_errors += 1,
        }
    }

    /// Stops the trace writer, writes `trace_return.csv` (when shaped) into
    /// `out_dir`, and reports.
    pub fn finish(self, out_dir: &Path) -> anyhow::Result<ReturnReport> {
        let c = self.counts;
        let destination =
            self.to.as_ref().map_or("the console's address".to_string(), |t| format!("udp://{}", t.addr()));
        let untouched = ReturnReport {
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
            kernel_drops: self.from_robot.kernel_drops(),
            loss_rate: None,
            loss_rate_ci95: None,
            injected_delay_ns: None,
            decision_ns: None,
            release_lateness_ns: None,
            trace_path: None,
        };
        let Some(s) = self.shaped else { return Ok(untouched) };
        let l = s.link.finish(&out_dir.join("trace_return.csv"), 0)?;
        Ok(ReturnReport {
            mode: "scenario".into(),
            scenario: Some(l.scenario),
            seed: Some(s.seed),
            entered: l.entered,
            delivered: l.delivered,
            dropped: l.dropped,
            held_at_end: l.held_at_end,
            send_errors: l.send_errors,
            loss_rate: Some(l.measures.loss_rate),
            loss_rate_ci95: Some(l.measures.loss_rate_ci95),
            injected_delay_ns: Some(l.measures.injected_delay_ns),
            decision_ns: Some(l.measures.decision_ns),
            release_lateness_ns: Some(l.measures.release_lateness_ns),
            trace_path: Some(l.trace_path),
            ..untouched
        })
    }
}

/// The return path the arguments ask for, on the transports opened for
/// them: with UDP on both sides and unless `--no-return`.
pub fn return_path(args: &EmulatorArgs, t: &Transports, seed: u64, expected: u64) -> anyhow::Result<Option<ReturnPath>> {
    let (Some(ingress), Some(egress)) = (t.udp_ingress(), t.udp_egress()) else { return Ok(None) };
    if args.no_return {
        return Ok(None);
    }
    let from_robot = egress.try_clone().context("opening the return path")?;
    let to_console = ingress.try_clone().context("opening the return path")?;
    let to = match &args.return_to {
        Some(Endpoint::Udp(a)) => Some(*a),
        Some(Endpoint::Iceoryx2) => bail!("--return-to takes udp://ADDR:PORT"),
        None => None,
    };
    let Some(name) = &args.return_scenario else { return Ok(Some(ReturnPath::untouched(from_robot, to_console, to))) };
    let spec = crate::load::resolve(name).with_context(|| format!("--return-scenario {name}"))?;
    let seed = args.return_seed.or(spec.seed).unwrap_or_else(|| crate::scenario::splitmix64(seed ^ 0x7265_7475_726e));
    let capacity = spec.queue_capacity.unwrap_or(RAW_DEFAULT_QUEUE_CAPACITY);
    anyhow::ensure!(capacity >= 1, "the return scenario's queue_capacity must be at least 1");
    let scenario = Scenario::new(&spec, seed).with_context(|| format!("--return-scenario {name}"))?;
    eprintln!("emulator: return path through scenario {} seed {seed}, queue {capacity}", spec.name);
    let mut ret = ReturnPath::shaped(from_robot, to_console, to, scenario, seed, capacity, expected).context("--queue-capacity")?;
    if let Some(s) = ret.shaped.as_deref_mut() {
        s.link.stream_to(&args.out.join("trace_return.csv"), None)?;
    }
    Ok(Some(ret))
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
    /// The console's address: `--console-from`, or the first sender's.
    pub console: Option<SocketAddr>,
    /// Ingress datagrams from other senders, dropped before they entered
    /// the link (so not in its accounting).
    #[serde(default)]
    pub foreign_sender: u64,
    /// Who they were: the first distinct senders, with their counts.
    #[serde(default)]
    pub foreign_senders: Vec<ForeignSender>,
    /// Foreign datagrams from senders beyond those named.
    #[serde(default)]
    pub foreign_unnamed: u64,
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

impl BoundEndpoints {
    /// The endpoints of `t` as bound.
    pub fn of(t: &Transports, args: &EmulatorArgs) -> BoundEndpoints {
        BoundEndpoints {
            ingress: t.udp_ingress().map(UdpPort::local_addr),
            egress_local: t.udp_egress().map(UdpPort::local_addr),
            egress_peer: args.egress.udp(),
        }
    }
}

/// A sender other than the console, and how many datagrams it sent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForeignSender {
    pub addr: SocketAddr,
    pub datagrams: u64,
}

impl UdpReport {
    /// The UDP side of a run that has ended.
    pub fn new(args: &EmulatorArgs, t: &Transports, bound: &BoundEndpoints, return_path: Option<ReturnReport>) -> UdpReport {
        let source = match &t.ingress {
            crate::transport::Ingress::Udp(s) => Some(s),
            _ => None,
        };
        UdpReport {
            ingress: args.ingress.to_string(),
            egress: args.egress.to_string(),
            payload: args.payload,
            ingress_local: bound.ingress,
            egress_local: bound.egress_local,
            datagrams_in: source.map(|s| s.taken()),
            ingress_kernel_drops: source.and_then(|s| s.port().kernel_drops()),
            ingress_buffer_bytes: source.and_then(|s| s.port().buffer_bytes().0),
            console: source.and_then(|s| s.console()),
            foreign_sender: source.map_or(0, |s| s.foreign().total),
            foreign_senders: source
                .map(|s| s.foreign().named().map(|(addr, datagrams)| ForeignSender { addr, datagrams }).collect())
                .unwrap_or_default(),
            foreign_unnamed: source.map_or(0, |s| s.foreign().unnamed),
            arena_slots: t.arena.as_ref().map(|a| a.borrow().slots()),
            arena_high_water: t.arena.as_ref().map(|a| a.borrow().high_water()),
            return_path,
        }
    }
}
