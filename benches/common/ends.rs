//! The benchmark's own ends of a chain, played in one thread: send a frame
//! on a route (through the emulator, or straight to the other end), poll a
//! route. Over iceoryx2 the ports of a run; over UDP loopback sockets.

use crate::common::args::keep_signals;
use anyhow::Result;
use netfi::clock::now_ns;
use netfi::frame::ItpFrame;
use netfi::sample::{FrameSample, ITP_FRAME_LEN};
use netfi::transport::udp::{PeerAddr, UdpOptions, UdpPort, DEFAULT_UDP_BUFFER_BYTES};
use netfi::transport::{FramePublisher, FrameSubscriber, IpcConfig, IpcNode, Port, Role, RunId};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// Options of the benchmark's own UDP sockets: 4 MiB kernel buffers, as
/// the emulator's.
pub fn udp_options() -> UdpOptions {
    UdpOptions { reuse_address: false, buffer_bytes: Some(DEFAULT_UDP_BUFFER_BYTES) }
}

/// A UDP socket on an ephemeral loopback port.
pub fn loopback_port() -> Result<UdpPort> {
    Ok(UdpPort::bind("127.0.0.1:0".parse().expect("a literal address"), &udp_options())?)
}

/// Which way a frame goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// Through the emulator.
    Chain,
    /// Straight to the receiving end, no emulator.
    Direct,
}

/// One frame that arrived.
#[derive(Debug, Clone, Copy)]
pub struct Arrival {
    pub slot: u64,
    pub recv_ns: u64,
    pub send_ns: u64,
    /// The emulator's stamps (iceoryx2 only): taken off its port, released.
    pub ingress_ns: u64,
    pub release_ns: u64,
    pub injected_delay_ns: u64,
}

pub trait Ends {
    /// Sends slot `slot`'s frame on `route`, stamping its send time as late
    /// as the transport allows. `false` if the transport refused it.
    fn send(&mut self, route: Route, slot: u64, wire: &[u8; ITP_FRAME_LEN]) -> bool;
    /// One waiting frame of `route`, stamped on arrival.
    fn poll(&mut self, route: Route) -> Option<Arrival>;
    /// Whether the emulator stamps its ingress and release times on frames.
    fn stamped(&self) -> bool;
}

/// The ITP frame of slot `slot`: a valid checksum, so the emulator's
/// validation passes it; the sequence identifies the slot (UDP carries
/// nothing else).
pub fn wire(slot: u64) -> [u8; ITP_FRAME_LEN] {
    ItpFrame { sequence: slot as u32, delx: [1, -1], surgeon_mode: 1, qw: [1.0, 1.0], ..ItpFrame::default() }.with_checksum().to_bytes()
}

pub struct IpcEnds {
    _console: IpcNode,
    _simulator: IpcNode,
    to_emulator: FramePublisher,
    direct_tx: FramePublisher,
    from_emulator: FrameSubscriber,
    direct_rx: FrameSubscriber,
}

impl IpcEnds {
    /// Opens the console's and the simulator's ports of run `run_id` and
    /// waits until the emulator is attached on both sides.
    pub fn open(run_id: &str) -> Result<IpcEnds> {
        let cfg = IpcConfig::new(RunId::new(run_id)?);
        let console = IpcNode::open(&cfg, Role::Console)?;
        let simulator = IpcNode::open(&cfg, Role::Simulator)?;
        keep_signals();
        let to_emulator = console.publisher(Port::CONSOLE)?;
        let direct_tx = console.publisher(Port::DIRECT)?;
        let from_emulator = simulator.subscriber(Port::EMULATOR)?;
        let direct_rx = simulator.subscriber(Port::DIRECT)?;
        let mut ends = IpcEnds { _console: console, _simulator: simulator, to_emulator, direct_tx, from_emulator, direct_rx };
        let t0 = Instant::now();
        while ends.to_emulator.peers_connected() == 0 || ends.from_emulator.peers_connected() == 0 || ends.direct_tx.peers_connected() == 0 {
            // Polling attaches the subscribers to the publishers.
            let _ = ends.from_emulator.try_recv();
            let _ = ends.direct_rx.try_recv();
            anyhow::ensure!(t0.elapsed() < Duration::from_secs(10), "the emulator of run {run_id} did not attach within 10 s");
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(ends)
    }

    pub fn end(&mut self, chain_sent: u64) {
        let _ = self.to_emulator.send(&FrameSample::end_marker(chain_sent));
    }
}

impl Ends for IpcEnds {
    #[inline]
    fn send(&mut self, route: Route, slot: u64, wire: &[u8; ITP_FRAME_LEN]) -> bool {
        let port = match route {
            Route::Chain => &mut self.to_emulator,
            Route::Direct => &mut self.direct_tx,
        };
        port.send_with(|s| {
            s.len = ITP_FRAME_LEN as u32;
            s.wire = *wire;
            s.console_index = slot;
            s.send_ns = now_ns();
        })
        .is_ok_and(|n| n > 0)
    }

    #[inline]
    fn poll(&mut self, route: Route) -> Option<Arrival> {
        let port = match route {
            Route::Chain => &mut self.from_emulator,
            Route::Direct => &mut self.direct_rx,
        };
        let got = port.recv_with(|s| {
            let recv_ns = now_ns();
            (!s.is_end()).then_some(Arrival {
                slot: s.console_index,
                recv_ns,
                send_ns: s.send_ns,
                ingress_ns: s.ingress_ns,
                release_ns: s.release_ns,
                injected_delay_ns: s.injected_delay_ns,
            })
        });
        got.ok().flatten().flatten()
    }

    fn stamped(&self) -> bool {
        true
    }
}

pub struct UdpEnds {
    tx: UdpPort,
    emulator_in: PeerAddr,
    direct_to: PeerAddr,
    rx_chain: UdpPort,
    rx_direct: UdpPort,
    /// Send time of each slot: UDP carries no metadata.
    sent_ns: Vec<u64>,
    buf: [u8; 256],
}

impl UdpEnds {
    pub fn new(rx_chain: UdpPort, emulator_in: SocketAddr, slots: u64) -> Result<UdpEnds> {
        let tx = loopback_port()?;
        let rx_direct = loopback_port()?;
        let direct_to = PeerAddr::new(rx_direct.local_addr());
        // Written once here (not zero-allocated), so the table's pages are
        // resident and no page fault lands between a stamp and its send.
        let sent_ns = vec![u64::MAX; slots as usize];
        Ok(UdpEnds { tx, emulator_in: PeerAddr::new(emulator_in), direct_to, rx_chain, rx_direct, sent_ns, buf: [0; 256] })
    }
}

impl Ends for UdpEnds {
    #[inline]
    fn send(&mut self, route: Route, slot: u64, wire: &[u8; ITP_FRAME_LEN]) -> bool {
        let to = match route {
            Route::Chain => &self.emulator_in,
            Route::Direct => &self.direct_to,
        };
        self.sent_ns[slot as usize] = now_ns();
        self.tx.send_to(wire, to).is_ok()
    }

    #[inline]
    fn poll(&mut self, route: Route) -> Option<Arrival> {
        let port = match route {
            Route::Chain => &self.rx_chain,
            Route::Direct => &self.rx_direct,
        };
        let d = port.recv_from(&mut self.buf).ok().flatten()?;
        let recv_ns = now_ns();
        if d.len != ITP_FRAME_LEN {
            return None;
        }
        let slot = u64::from(u32::from_le_bytes([self.buf[0], self.buf[1], self.buf[2], self.buf[3]]));
        let send_ns = *self.sent_ns.get(slot as usize).filter(|t| **t != u64::MAX)?;
        Some(Arrival { slot, recv_ns, send_ns, ingress_ns: 0, release_ns: 0, injected_delay_ns: 0 })
    }

    fn stamped(&self) -> bool {
        false
    }
}

