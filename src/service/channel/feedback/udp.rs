//! The UDP return channel: with UDP on both sides, what the robot sends
//! back to the emulator's egress socket (a status or feedback frame, a
//! ping-pong reply) goes out of the ingress socket to the console, so the
//! console sees replies come from the address it sends to: to
//! `--return-to`, or else to the console's address once the ingress knows
//! it. It passes through a scenario of its own (`--return-scenario`;
//! without one, `Normal`: nothing injected, the path reported as
//! `untouched`). A datagram that arrives before any console is known has
//! nowhere to go: it is counted as `unroutable` and does not enter. UDP has
//! no end of stream: the path ends with the forward stream.
//!
//! Each datagram is received into a slot of the path's own arena, which
//! has one slot more than the queue holds, so a slot is always free; it is
//! freed when the datagram is sent or dropped.

use crate::injector::DropCause;
use crate::service::emulator::path::{Channel, Ending, Reverse, Take};
use super::{ReturnArgs, ReturnExtra, ReturnOpenError};
use crate::service::channel::declare::ChannelOpen;
use crate::service::emulator::opening::{Opening, PathPlan};
use crate::service::link::{Arrival, Carried};
use crate::service::schema::Account;
use crate::transport::udp::{Arena, ConsoleAddr, PeerAddr, UdpPort, ARENA_SLOT_BYTES};
use crate::transport::PortError;

/// A return datagram held by the link.
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

/// The return direction's sockets and arena.
pub struct UdpReturn {
    /// A handle on the egress socket: what the robot sends back.
    from_robot: UdpPort,
    /// A handle on the ingress socket.
    to_console: UdpPort,
    /// `--return-to`, or the console's address once known.
    dest: Option<PeerAddr>,
    console: ConsoleAddr,
    arena: Arena,
    shaped: bool,
    received: u64,
    unroutable: u64,
}

impl UdpReturn {
    /// Relays what arrives at `from_robot` out of `to_console`, to `to` or
    /// else to the console's address once `console` has it; `shaped` says
    /// whether a return scenario was asked for; the arena holds
    /// `queue_capacity + 1` datagrams.
    pub fn new(from_robot: UdpPort, to_console: UdpPort, to: Option<std::net::SocketAddr>, console: ConsoleAddr, shaped: bool, queue_capacity: usize) -> UdpReturn {
        UdpReturn {
            from_robot,
            to_console,
            dest: to.map(PeerAddr::new),
            console,
            arena: Arena::new(queue_capacity + 1),
            shaped,
            received: 0,
            unroutable: 0,
        }
    }
}

impl Channel for UdpReturn {
    type Item = Held;
    type Extra = ReturnExtra;
    const NAME: &'static str = crate::transport::udp::RETURN_PATH;
    const TRACE_FILE: &'static str = "trace_return.csv";
    const ENDING: Ending = Ending::WithForward;
    /// Every turn: a quiet poll is one `recvfrom`, as the forward's is, and
    /// a reply is as pressing as the command it answers.
    const QUIET_POLL_EVERY: u32 = 1;

    #[inline]
    fn take(&mut self, _next_ingress_index: u64, clock: &mut impl FnMut() -> u64) -> Take<Held> {
        let slot = self.arena.alloc().expect("the return arena has one slot more than its queue can hold");
        match self.from_robot.recv_from(self.arena.slot_mut(slot)) {
            Ok(Some(d)) => {
                self.received += 1;
                if self.dest.is_none() {
                    self.dest = self.console.get().map(PeerAddr::new);
                }
                if self.dest.is_none() {
                    self.unroutable += 1;
                    self.arena.free(slot);
                    return Take::Skipped;
                }
                let t = clock();
                let len = d.len.min(ARENA_SLOT_BYTES) as u32;
                let arrival = Arrival { sequence: None, console_index: self.received - 1, send_ns: t };
                Take::Item(Held { slot, len, ingress_ns: t }, None, arrival)
            }
            Ok(None) => {
                self.arena.free(slot);
                Take::Nothing
            }
            Err(e) => {
                self.arena.free(slot);
                Take::Failed(PortError { port: format!("udp://{}", self.from_robot.local_addr()), message: e.to_string() })
            }
        }
    }

    #[inline]
    fn dropped(&mut self, item: &Held, _cause: DropCause) {
        self.arena.free(item.slot);
    }

    /// Sends the datagram's bytes out of the ingress socket to the console,
    /// and frees its slot.
    #[inline]
    fn release(&mut self, item: &Held, _scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
        let bytes = &self.arena.slot(item.slot)[..item.len as usize];
        let release_ns = stamp();
        // A datagram enters only once a destination is known, and one stays
        // known.
        let sent = match &self.dest {
            Some(to) => self.to_console.send_to(bytes, to).map_err(|e| e.to_string()),
            None => Err("no console to return to".to_string()),
        };
        self.arena.free(item.slot);
        sent.map(|()| release_ns)
            .map_err(|message| (release_ns, PortError { port: format!("udp://{}", self.to_console.local_addr()), message }))
    }

    /// UDP has no end of stream: nothing to send.
    fn send_end(&mut self, _released: u64) {}

    fn finish(&mut self, account: &Account, _sent: Option<u64>) -> (ReturnExtra, bool) {
        let extra = ReturnExtra {
            mode: if self.shaped { "scenario" } else { "untouched" }.into(),
            destination: self.dest.as_ref().map_or("the console's address".to_string(), |t| format!("udp://{}", t.addr())),
            received: self.received,
            unroutable: self.unroutable,
            kernel_drops: self.from_robot.kernel_drops(),
            refused: self.from_robot.refused().report(),
        };
        (extra, self.received == account.entered + self.unroutable)
    }
}

/// The return path of a lane with UDP on both sides, as `plan` settled it.
pub fn open(a: &ReturnArgs, plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<ReturnOpenError>> {
    let session = o.sessions.udp.as_ref().expect("the UDP return path is asked for with UDP on both sides");
    let u = &o.shape.transports.udp;
    let port = |cause| ChannelOpen::Own(ReturnOpenError::ReturnPort(cause));
    let (mut from_robot, to_console) = session.return_ports().map_err(port)?.expect("both sides are UDP");
    if let Some(robot) = u.robot_from {
        from_robot.accept_only(robot);
    }
    let chan = UdpReturn::new(from_robot, to_console, u.return_to, session.console.clone(), a.return_scenario.is_some(), plan.queue_capacity);
    Ok(Box::new(plan.open(chan, o.expected_frames, o.out_dir)?))
}
