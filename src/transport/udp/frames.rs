//! Frames over UDP sockets: the emulator's [`FrameSource`] and
//! [`FrameSink`] on a [`UdpPort`].
//!
//! - `itp` payload: a datagram is one ITP frame, received straight into the
//!   sample's wire bytes with its true length, so the emulator's own
//!   validation applies exactly as over iceoryx2.
//! - `raw` payload: any datagram up to 64 KiB, as opaque bytes, received into
//!   a slot of the [`Arena`], which the source and the sink share; the
//!   sample carries the slot and the length and is flagged
//!   [`FrameSample::FLAG_RAW`]. A slot is freed when its datagram is sent or
//!   dropped.
//!
//! UDP has no end of stream: with an idle timeout the source hands the loop
//! an end marker once no datagram has arrived for that long, and the sink
//! never sends one.

use super::{ConsolePolicy, ForeignSenders, PeerAddr, UdpPort, MAX_DATAGRAM_BYTES};
use crate::clock::now_ns;
use crate::sample::{FrameSample, ITP_FRAME_LEN};
use crate::transport::ports::{FrameSink, FrameSource, PortError};
use std::cell::RefCell;
use std::fmt;
use std::net::SocketAddr;
use std::rc::Rc;

/// Bytes of one arena slot: any UDP payload fits.
pub const ARENA_SLOT_BYTES: usize = MAX_DATAGRAM_BYTES;

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

    /// Slots in all.
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

    /// The bytes of `slot`.
    #[inline]
    pub fn slot(&self, slot: u32) -> &[u8] {
        let at = slot as usize * ARENA_SLOT_BYTES;
        &self.bytes[at..at + ARENA_SLOT_BYTES]
    }

    /// The bytes of `slot`, to write.
    #[inline]
    pub fn slot_mut(&mut self, slot: u32) -> &mut [u8] {
        let at = slot as usize * ARENA_SLOT_BYTES;
        &mut self.bytes[at..at + ARENA_SLOT_BYTES]
    }
}

/// The arena slot a raw sample refers to (kept in its first wire bytes).
#[inline]
pub fn raw_slot(s: &FrameSample) -> u32 {
    u32::from_le_bytes([s.wire[0], s.wire[1], s.wire[2], s.wire[3]])
}

fn port_error(port: &UdpPort, e: impl fmt::Display) -> PortError {
    PortError { port: format!("udp://{}", port.local_addr()), message: e.to_string() }
}

/// The emulator's source on a UDP socket.
///
/// It takes datagrams from one sender only, the console, as its
/// [`ConsolePolicy`] says: the address named, or the first sender's,
/// locked from then on (and said on stderr). Datagrams from anyone else
/// are refused by the port ([`UdpPort::accept_only`]) before they enter
/// the link (they are not frames of the stream, so the link's accounting
/// `entered = delivered + dropped + held` is about the console's frames
/// only) and counted per sender in [`UdpSource::foreign`]. So no other
/// socket can feed the robot or take over the return path.
pub struct UdpSource {
    port: UdpPort,
    arena: Option<Rc<RefCell<Arena>>>,
    /// The console's address, shared with the return path once known.
    console: super::ConsoleAddr,
    taken: u64,
    idle_end_ns: Option<u64>,
    last_rx_ns: u64,
    ended: bool,
}

impl UdpSource {
    /// A source taking ITP frames (`arena: None`) or raw datagrams (into
    /// `arena`) off `port`, from the console `policy` names; the console's
    /// address goes into `console` once known.
    pub fn new(mut port: UdpPort, arena: Option<Rc<RefCell<Arena>>>, policy: ConsolePolicy, console: super::ConsoleAddr) -> UdpSource {
        match policy {
            ConsolePolicy::Named(addr) => {
                port.accept_only(addr);
                console.set(Some(addr));
            }
            ConsolePolicy::FirstDatagram => {}
        }
        UdpSource { port, arena, console, taken: 0, idle_end_ns: None, last_rx_ns: 0, ended: false }
    }

    /// The datagrams from other senders, refused.
    pub fn foreign(&self) -> ForeignSenders {
        self.port.refused()
    }

    /// End the stream after `idle_ns` without a datagram (once one came).
    pub fn with_idle_end(mut self, idle_ns: u64) -> UdpSource {
        self.idle_end_ns = Some(idle_ns);
        self
    }

    /// The address the socket is bound to.
    pub fn local_addr(&self) -> SocketAddr {
        self.port.local_addr()
    }

    /// Datagrams taken off the socket.
    pub fn taken(&self) -> u64 {
        self.taken
    }

    /// The console's address: named, or the first sender's once it spoke.
    pub fn console(&self) -> Option<SocketAddr> {
        self.port.peer().map(PeerAddr::addr)
    }

    /// The socket, for what is read off the hot path (kernel drops, buffer
    /// sizes) and for a handle on it ([`UdpPort::try_clone`]).
    pub fn port(&self) -> &UdpPort {
        &self.port
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

    /// The first datagram of a source told to pair with the first sender:
    /// its sender is the console from now on. Once per run, so the line
    /// on stderr costs the loop nothing per frame.
    #[cold]
    fn pair(&mut self, from: SocketAddr) {
        self.port.accept_only(from);
        self.console.set(Some(from));
        eprintln!(
            "emulator: UDP ingress udp://{} paired with its first sender, udp://{from}, as the console (--console-from first); \
             datagrams from any other address are refused and counted",
            self.port.local_addr()
        );
    }
}

impl FrameSource for UdpSource {
    #[inline]
    fn try_recv(&mut self, out: &mut FrameSample) -> Result<bool, PortError> {
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
                if self.port.peer().is_none() {
                    self.pair(d.from);
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
    fn sender(&self) -> Option<SocketAddr> {
        self.port.peer().map(PeerAddr::addr)
    }

    fn senders(&mut self) -> Vec<String> {
        self.sender().map(|a| vec![format!("udp://{a}")]).unwrap_or_default()
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

    /// The address the socket is bound to.
    pub fn local_addr(&self) -> SocketAddr {
        self.port.local_addr()
    }

    /// The socket (for a handle on it: [`UdpPort::try_clone`]).
    pub fn port(&self) -> &UdpPort {
        &self.port
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::udp::UdpOptions;

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
        let mut itp = UdpSource::new(loopback(), None, ConsolePolicy::FirstDatagram, Default::default());
        let to = PeerAddr::new(itp.local_addr());
        console.send_to(&[1u8; 300], &to).unwrap();
        let s = recv_one(&mut itp);
        assert_eq!((s.len, s.flags, s.console_index), (300, 0, 0));
        assert_eq!(itp.console(), Some(console.local_addr()));
        console.send_to(&[2u8; 10], &to).unwrap();
        let s = recv_one(&mut itp);
        assert_eq!((s.len, s.console_index), (10, 1));
        assert_eq!(&s.wire[..12], &[2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 0, 0], "bytes past the datagram are zero");
        // Paired with the first sender: another one is refused, and counted.
        let stranger = loopback();
        stranger.send_to(&[9u8; 124], &to).unwrap();
        console.send_to(&[4u8; 124], &to).unwrap();
        let s = recv_one(&mut itp);
        assert_eq!((s.wire[0], s.console_index), (4, 2));
        assert_eq!(itp.foreign().named().collect::<Vec<_>>(), vec![(stranger.local_addr(), 1)]);

        let arena = Rc::new(RefCell::new(Arena::new(2)));
        let mut raw = UdpSource::new(loopback(), Some(arena.clone()), ConsolePolicy::Named(console.local_addr()), Default::default());
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
        let mut src = UdpSource::new(loopback(), None, ConsolePolicy::Named(console.local_addr()), Default::default()).with_idle_end(1_000_000);
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
