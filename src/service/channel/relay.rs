//! The emulator's side of a reverse channel that carries a fixed-size
//! sample of its own (the robot's feedback; in test builds, its force
//! readings): taken off one port, through the channel's path, released on
//! another, stamped on the way, the sender's end marker passed on. What
//! differs between such channels is their sample ([`Relayed`]); the
//! relaying ([`Relay`]) is written once.

use crate::sample::Payload;
use crate::service::emulator::path::{Channel, Ending, Take, GRACE_NS};
use crate::service::link::{Arrival, Carried};
use crate::service::schema::Account;
use crate::transport::{FramePublisher, FrameSink, FrameSource, FrameSubscriber, PortError};
use serde::{Deserialize, Serialize};

/// A sample a reverse channel relays: its path's name and trace, its end
/// marker, the sender's count, and the emulator's stamps.
pub trait Relayed: Payload + Carried {
    /// The path's name: its key in `emulator.json`'s paths.
    const NAME: &'static str;
    /// Its trace file, in the run's directory.
    const TRACE_FILE: &'static str;
    /// The end marker after `sent` samples.
    fn end_marker(sent: u64) -> Self;
    /// Whether this is the end marker.
    fn is_end(&self) -> bool;
    /// The sender's count of this sample; in an end marker, how many it sent.
    fn sender_index(&self) -> u64;
    /// When the sender sent it, ns.
    fn send_ns(&self) -> u64;
    /// The protocol sequence number it carries, if any.
    fn sequence(&self) -> Option<u32> {
        None
    }
    /// Stamps it as taken in: its index in the path, and when.
    fn taken(&mut self, ingress_index: u64, ingress_ns: u64);
    /// Stamps it as released: when it was due, the delay injected, and
    /// when it went out (`release_ns`, read as late as possible).
    fn released(&mut self, scheduled_ns: u64, release_ns: impl FnOnce() -> u64) -> u64;
}

/// What such a path adds to its report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RelayExtra {
    /// Samples the robot said it sent (from its end marker).
    pub sent_by_robot: Option<u64>,
}

/// A relay of `T` from `source` to `sink`: the robot's iceoryx2 ports, or
/// any source and sink of `T` (tests drive in-memory ones).
pub struct Relay<T, S = FrameSubscriber<T>, K = FramePublisher<T>>
where
    T: Payload,
{
    source: S,
    sink: K,
    sample: T,
}

impl<T: Relayed, S: FrameSource<T>, K: FrameSink<T>> Relay<T, S, K> {
    /// The relay from `source` to `sink`.
    pub fn new(source: S, sink: K) -> Relay<T, S, K> {
        Relay { source, sink, sample: T::ZERO }
    }

    /// The two ports.
    pub fn ports_mut(&mut self) -> (&mut S, &mut K) {
        (&mut self.source, &mut self.sink)
    }
}

impl<T: Relayed, S: FrameSource<T>, K: FrameSink<T>> Channel for Relay<T, S, K> {
    type Item = T;
    type Extra = RelayExtra;
    const NAME: &'static str = T::NAME;
    const TRACE_FILE: &'static str = T::TRACE_FILE;
    /// The robot ends its samples with an end marker once it has the
    /// emulator's; a robot that sends none (or is gone) does not hold the
    /// run.
    const ENDING: Ending = Ending::AfterForward { grace_ns: GRACE_NS };

    #[inline]
    fn take(&mut self, next_ingress_index: u64, clock: &mut impl FnMut() -> u64) -> Take<T> {
        let s = &mut self.sample;
        match self.source.try_recv(s) {
            Ok(true) if s.is_end() => Take::End(s.sender_index()),
            Ok(true) => {
                s.taken(next_ingress_index, clock());
                Take::Item(*s, None, Arrival { sequence: s.sequence(), console_index: s.sender_index(), send_ns: s.send_ns() })
            }
            Ok(false) => Take::Nothing,
            Err(e) => Take::Failed(e),
        }
    }

    /// Released stamped with its scheduled and actual release times and
    /// its injected delay.
    #[inline]
    fn release(&mut self, item: &T, scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
        let mut release_ns = 0;
        match self.sink.send_with(item, |s| release_ns = s.released(scheduled_ns, stamp)) {
            Ok(_) => Ok(release_ns),
            Err(e) => Err((crate::clock::now_ns(), e)),
        }
    }

    fn send_end(&mut self, released: u64) {
        let _ = self.sink.send_with(&T::end_marker(released), |_| {});
    }

    fn senders(&mut self) -> Option<usize> {
        self.source.peers()
    }

    fn unsubscribed(&self) -> u64 {
        self.sink.unsubscribed()
    }

    /// Balanced also asks that every sample the robot said it sent entered.
    fn finish(&mut self, account: &Account, sent: Option<u64>) -> (RelayExtra, bool) {
        (RelayExtra { sent_by_robot: sent }, sent.is_none_or(|n| n == account.entered))
    }
}
