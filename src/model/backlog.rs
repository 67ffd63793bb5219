//! What the two link stages (`rate`, docs/spec.md §3.12; `trace`, §3.13)
//! share: the packets a payload is cut into, the queue limit (tail drop,
//! reason `link_queue`), the packets still queued, and the link's counters.
//!
//! A decision is written once ([`LinkStage::admit`]); a stage says only how
//! it serves one packet ([`LinkStage::serve`]).
//!
//! A payload of `L` bytes goes as `⌈L / mtu_bytes⌉` packets, every one
//! `mtu_bytes` long but the last, each carrying `overhead_bytes` more on the
//! wire. The payload shares its packets' fate: it is admitted whole, when
//! the queue can take all its packets, or dropped whole.
//!
//! The queue remembers, per admitted packet, the time it leaves the queue
//! (the model says which time that is: the end of its serialization for
//! `rate`, the opportunity that starts carrying it for `trace`) and its wire
//! bytes. A packet still counts at `t` if it leaves after `t`. The ring is
//! allocated in `new` for the most packets the limit admits of the stage's
//! payload size, so a decision allocates nothing.

use super::{ParamError, Verdict};
use hdrhistogram::Histogram;
use std::collections::VecDeque;

/// The most packets a queue may hold (`queue_packets`, or `queue_bytes`
/// over the smallest packet).
pub const MAX_QUEUE_PACKETS: u64 = 1 << 22;
/// The most bytes a queue may hold (`queue_bytes`): 1 GiB.
pub const MAX_QUEUE_BYTES: u64 = 1 << 30;
/// The largest payload or MTU: 64 MiB.
pub const MAX_PAYLOAD_BYTES: u64 = 1 << 26;
/// The largest per-packet overhead.
pub const MAX_OVERHEAD_BYTES: u64 = 65_535;
/// The queue limit when a stage gives none: netem's default `limit`.
pub const DEFAULT_QUEUE_PACKETS: u64 = 1000;
/// The default MTU: Ethernet's.
pub const DEFAULT_MTU_BYTES: u64 = 1500;

/// The packet-shaping parameters both link stages take (each stage's
/// parameter struct carries them as its own fields, for precise errors).
#[derive(Debug, Clone, PartialEq)]
pub struct PacketParams {
    /// The payload each frame carries (today's frames: the 124-byte ITP
    /// frame; a variable-size path passes its own length per payload).
    pub payload_bytes: u64,
    /// The most payload bytes one packet carries.
    pub mtu_bytes: u64,
    /// Bytes each packet adds on the wire (headers, framing).
    pub overhead_bytes: u64,
    /// The queue limit in packets (netem's `limit`); the default when neither
    /// limit is given is [`DEFAULT_QUEUE_PACKETS`].
    pub queue_packets: Option<u64>,
    /// The queue limit in bytes (Mahimahi's `--uplink-queue-args bytes=`).
    pub queue_bytes: Option<u64>,
}

// Serde defaults of the stages' packet fields.
pub(super) fn default_payload() -> u64 {
    crate::frame::ITP_FRAME_LEN as u64
}
pub(super) fn is_default_payload(v: &u64) -> bool {
    *v == default_payload()
}
pub(super) fn default_mtu() -> u64 {
    DEFAULT_MTU_BYTES
}
pub(super) fn is_default_mtu(v: &u64) -> bool {
    *v == DEFAULT_MTU_BYTES
}
pub(super) fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// A link stage's parameter struct: its own fields, then the packet fields
/// both link stages take (as fields of the stage's own, for precise
/// errors: serde's `flatten` cannot name an unknown field), with
/// `packet_params()` reading them back and `with_default_packets(own
/// fields…)` building one with [`PacketParams::default`]'s.
macro_rules! link_params {
    ($(#[$m:meta])* pub struct $name:ident { $($(#[$fm:meta])* pub $f:ident: $t:ty,)* }) => {
        $(#[$m])*
        pub struct $name {
            $($(#[$fm])* pub $f: $t,)*
            #[serde(default = "default_payload", skip_serializing_if = "is_default_payload")]
            pub payload_bytes: u64,
            #[serde(default = "default_mtu", skip_serializing_if = "is_default_mtu")]
            pub mtu_bytes: u64,
            #[serde(default, skip_serializing_if = "is_zero")]
            pub overhead_bytes: u64,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub queue_packets: Option<u64>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub queue_bytes: Option<u64>,
        }

        impl $name {
            fn with_default_packets($($f: $t),*) -> $name {
                let p = PacketParams::default();
                $name {
                    $($f,)*
                    payload_bytes: p.payload_bytes,
                    mtu_bytes: p.mtu_bytes,
                    overhead_bytes: p.overhead_bytes,
                    queue_packets: p.queue_packets,
                    queue_bytes: p.queue_bytes,
                }
            }

            fn packet_params(&self) -> PacketParams {
                PacketParams {
                    payload_bytes: self.payload_bytes,
                    mtu_bytes: self.mtu_bytes,
                    overhead_bytes: self.overhead_bytes,
                    queue_packets: self.queue_packets,
                    queue_bytes: self.queue_bytes,
                }
            }
        }
    };
}
pub(super) use link_params;

impl Default for PacketParams {
    fn default() -> Self {
        PacketParams {
            payload_bytes: default_payload(),
            mtu_bytes: DEFAULT_MTU_BYTES,
            overhead_bytes: 0,
            queue_packets: None,
            queue_bytes: None,
        }
    }
}

/// A queue limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QueueLimit {
    Packets(u64),
    Bytes(u64),
}

/// Validated packet shaping: how a payload is cut, and the limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Packets {
    pub payload_bytes: u64,
    pub mtu_bytes: u64,
    pub overhead_bytes: u64,
    pub limit: QueueLimit,
}

impl Packets {
    /// Validates `p`; `wire` maps a packet's bytes (payload + overhead) to
    /// what it costs on the link (netem's cells), for the limit's check.
    pub fn new(p: &PacketParams) -> Result<Packets, ParamError> {
        let range = |field: &str, v: u64, lo: u64, hi: u64, what: &str| {
            if v < lo || v > hi {
                Err(ParamError::new(field, format!("{v} is out of range: expected {what} from {lo} to {hi}")))
            } else {
                Ok(())
            }
        };
        range("payload_bytes", p.payload_bytes, 1, MAX_PAYLOAD_BYTES, "a payload size in bytes")?;
        range("mtu_bytes", p.mtu_bytes, 1, MAX_PAYLOAD_BYTES, "the payload bytes of one packet")?;
        range("overhead_bytes", p.overhead_bytes, 0, MAX_OVERHEAD_BYTES, "bytes per packet")?;
        let limit = match (p.queue_packets, p.queue_bytes) {
            (Some(_), Some(_)) => {
                return Err(ParamError::new("queue_bytes", "give `queue_packets` or `queue_bytes`, not both"));
            }
            (Some(n), None) => {
                range("queue_packets", n, 1, MAX_QUEUE_PACKETS, "a queue limit in packets")?;
                QueueLimit::Packets(n)
            }
            (None, Some(b)) => QueueLimit::Bytes(b),
            (None, None) => QueueLimit::Packets(DEFAULT_QUEUE_PACKETS),
        };
        let packets = Packets { payload_bytes: p.payload_bytes, mtu_bytes: p.mtu_bytes, overhead_bytes: p.overhead_bytes, limit };
        if let QueueLimit::Bytes(b) = limit {
            let one = packets.largest_packet_bytes();
            if b < one || b > MAX_QUEUE_BYTES {
                return Err(ParamError::new(
                    "queue_bytes",
                    format!("{b} bytes: the queue must hold at least one packet ({one} bytes: payload up to the MTU, plus overhead) and at most {MAX_QUEUE_BYTES}"),
                ));
            }
            let ring = packets.ring_capacity();
            if ring > MAX_QUEUE_PACKETS as usize {
                return Err(ParamError::new(
                    "queue_bytes",
                    format!("{b} bytes hold {ring} packets of this payload; at most {MAX_QUEUE_PACKETS}"),
                ));
            }
        }
        Ok(packets)
    }

    /// Packets a payload of `len` bytes goes as (at least one).
    #[inline]
    pub fn count(&self, len: u64) -> u64 {
        len.div_ceil(self.mtu_bytes).max(1)
    }

    /// Wire bytes (payload + overhead) of packet `i` of a payload of `len`.
    #[inline]
    pub fn packet_bytes(&self, len: u64, i: u64) -> u64 {
        let n = self.count(len);
        let payload = if i + 1 < n { self.mtu_bytes } else { len - self.mtu_bytes * (n - 1) };
        payload + self.overhead_bytes
    }

    /// Wire bytes of a whole payload of `len`.
    #[inline]
    pub fn payload_wire_bytes(&self, len: u64) -> u64 {
        len + self.count(len) * self.overhead_bytes
    }

    /// The largest packet of the stage's payload (what a queue must hold).
    pub fn largest_packet_bytes(&self) -> u64 {
        self.payload_bytes.min(self.mtu_bytes) + self.overhead_bytes
    }

    /// The most packets of the stage's payload size the limit admits: the
    /// ring's capacity.
    pub fn ring_capacity(&self) -> usize {
        match self.limit {
            QueueLimit::Packets(n) => n as usize,
            QueueLimit::Bytes(b) => {
                let n = self.count(self.payload_bytes);
                let smallest = self.packet_bytes(self.payload_bytes, n - 1).min(self.packet_bytes(self.payload_bytes, 0));
                (b / smallest.max(1)) as usize + 1
            }
        }
    }
}

/// The packets queued at a link: when each leaves the queue, and its bytes.
#[derive(Debug, Clone)]
pub struct Backlog {
    ring: VecDeque<(u64, u64)>,
    bytes: u64,
    limit: QueueLimit,
}

impl Backlog {
    pub fn new(packets: &Packets) -> Backlog {
        Backlog { ring: VecDeque::with_capacity(packets.ring_capacity()), bytes: 0, limit: packets.limit }
    }

    /// Forgets the packets that have left by `t_ns`.
    #[inline]
    pub fn advance(&mut self, t_ns: u64) {
        while let Some(&(leave_ns, bytes)) = self.ring.front() {
            if leave_ns > t_ns {
                break;
            }
            self.bytes -= bytes;
            self.ring.pop_front();
        }
    }

    /// Whether `packets` more packets of `bytes` wire bytes in all fit.
    #[inline]
    pub fn fits(&self, packets: u64, bytes: u64) -> bool {
        match self.limit {
            QueueLimit::Packets(n) => self.ring.len() as u64 + packets <= n,
            QueueLimit::Bytes(b) => self.bytes + bytes <= b,
        }
    }

    /// Queues one packet that leaves the queue at `leave_ns`.
    #[inline]
    pub fn push(&mut self, leave_ns: u64, bytes: u64) {
        self.ring.push_back((leave_ns, bytes));
        self.bytes += bytes;
    }

    /// Packets queued (as of the last [`Backlog::advance`]).
    pub fn packets(&self) -> u64 {
        self.ring.len() as u64
    }

    /// Wire bytes queued (as of the last [`Backlog::advance`]).
    pub fn bytes(&self) -> u64 {
        self.bytes
    }
}

/// What a link stage keeps besides its own service: how a payload is cut,
/// the packets queued, and the counters.
#[derive(Debug, Clone)]
pub struct LinkQueue {
    pub packets: Packets,
    pub backlog: Backlog,
    pub stats: LinkStats,
}

impl LinkQueue {
    pub fn new(packets: Packets) -> LinkQueue {
        LinkQueue { packets, backlog: Backlog::new(&packets), stats: LinkStats::default() }
    }

    /// The queue now (as of the last frame): packets and wire bytes.
    pub fn queued(&self) -> (u64, u64) {
        (self.backlog.packets(), self.backlog.bytes())
    }
}

/// A link stage (`rate`, `trace`): how it serves one packet. The rest of
/// its decision, the same for both, is [`LinkStage::admit`].
pub trait LinkStage {
    /// The stage's packets, queue and counters.
    fn queue(&mut self) -> &mut LinkQueue;

    /// Serves one packet of `bytes` wire bytes of a payload that reached
    /// the stage at `t_ns`, behind everything admitted before it: when the
    /// packet leaves the queue, and when its last byte has left the link.
    fn serve(&mut self, t_ns: u64, bytes: u64) -> (u64, u64);

    /// Decides a payload of `len` bytes reaching the stage at `t_ns`:
    /// dropped whole when the queue cannot take all its packets, else
    /// each packet served in turn and queued; it leaves with its last.
    #[inline]
    fn admit(&mut self, t_ns: u64, len: u64) -> Verdict {
        let q = self.queue();
        q.backlog.advance(t_ns);
        let n = q.packets.count(len);
        let wire = q.packets.payload_wire_bytes(len);
        if !q.backlog.fits(n, wire) {
            q.stats.dropped(t_ns, n);
            return Verdict::Drop;
        }
        let mut departure_ns = t_ns;
        for i in 0..n {
            let bytes = self.queue().packets.packet_bytes(len, i);
            let (leave_ns, last_ns) = self.serve(t_ns, bytes);
            departure_ns = last_ns;
            self.queue().backlog.push(leave_ns, bytes);
        }
        let q = self.queue();
        q.stats.admitted(t_ns, n, wire, departure_ns, &q.backlog);
        Verdict::Pass { delay_ns: departure_ns.saturating_sub(t_ns) }
    }
}

/// A link stage's counters since it started.
#[derive(Debug, Clone)]
pub struct LinkStats {
    /// Payloads (frames) admitted and dropped for the queue.
    pub frames: u64,
    pub frames_dropped: u64,
    /// Packets admitted and dropped (a dropped payload drops all its packets).
    pub packets: u64,
    pub packets_dropped: u64,
    /// Wire bytes admitted.
    pub bytes: u64,
    /// The first frame's arrival and the last departure so far.
    pub first_ns: Option<u64>,
    pub last_departure_ns: u64,
    /// The most packets and bytes queued when a frame arrived (itself
    /// included).
    pub queue_packets_max: u64,
    pub queue_bytes_max: u64,
    /// Each admitted frame's time at the stage (arrival to its last packet's
    /// departure: queueing and serialization), ns: every u64, each
    /// percentile at most [`crate::metrics::ERROR_FRACTION_MAX`] above the
    /// exact value.
    pub delay_ns: Histogram<u64>,
    /// Admitted frames that did not go on: dropped after the link, by a
    /// later stage or because the release queue was full. They crossed the
    /// link (its bytes, delays and queue count them), but the link passed
    /// on `frames − frames_dropped_after`.
    pub frames_dropped_after: u64,
}

impl Default for LinkStats {
    fn default() -> Self {
        LinkStats {
            frames: 0,
            frames_dropped: 0,
            packets: 0,
            packets_dropped: 0,
            bytes: 0,
            first_ns: None,
            last_departure_ns: 0,
            queue_packets_max: 0,
            queue_bytes_max: 0,
            // Every u64 at three significant digits (a trace link's frames
            // may wait days): about 450 KiB per link stage, allocated here,
            // never on a decision.
            delay_ns: Histogram::new_with_bounds(1, u64::MAX, 3).expect("static bounds are valid"),
            frames_dropped_after: 0,
        }
    }
}

impl LinkStats {
    /// Records one admitted frame.
    #[inline]
    pub fn admitted(&mut self, t_ns: u64, packets: u64, bytes: u64, departure_ns: u64, backlog: &Backlog) {
        self.first_ns.get_or_insert(t_ns);
        self.frames += 1;
        self.packets += packets;
        self.bytes += bytes;
        self.last_departure_ns = self.last_departure_ns.max(departure_ns);
        self.queue_packets_max = self.queue_packets_max.max(backlog.packets());
        self.queue_bytes_max = self.queue_bytes_max.max(backlog.bytes());
        self.delay_ns.saturating_record(departure_ns - t_ns);
    }

    /// Records one payload dropped for the queue.
    #[inline]
    pub fn dropped(&mut self, t_ns: u64, packets: u64) {
        self.first_ns.get_or_insert(t_ns);
        self.frames_dropped += 1;
        self.packets_dropped += packets;
    }

    /// Records that a frame this link admitted was dropped after it.
    #[inline]
    pub fn dropped_after(&mut self) {
        self.frames_dropped_after += 1;
    }

    /// Frames the link admitted that went on (not dropped after it).
    pub fn frames_passed(&self) -> u64 {
        self.frames - self.frames_dropped_after
    }

    /// The `q`-quantile of the frames' time at the stage, ms.
    pub fn delay_ms_quantile(&self, q: f64) -> f64 {
        self.delay_ns.value_at_quantile(q) as f64 / 1e6
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packets(payload: u64, mtu: u64, overhead: u64, limit: QueueLimit) -> Packets {
        let (queue_packets, queue_bytes) = match limit {
            QueueLimit::Packets(n) => (Some(n), None),
            QueueLimit::Bytes(b) => (None, Some(b)),
        };
        Packets::new(&PacketParams { payload_bytes: payload, mtu_bytes: mtu, overhead_bytes: overhead, queue_packets, queue_bytes }).unwrap()
    }

    #[test]
    fn a_payload_is_cut_at_the_mtu() {
        let p = packets(4000, 1500, 40, QueueLimit::Packets(10));
        assert_eq!(p.count(4000), 3);
        assert_eq!([p.packet_bytes(4000, 0), p.packet_bytes(4000, 1), p.packet_bytes(4000, 2)], [1540, 1540, 1040]);
        assert_eq!(p.payload_wire_bytes(4000), 4120);
        assert_eq!(p.count(124), 1);
        assert_eq!(p.packet_bytes(124, 0), 164);
    }

    #[test]
    fn a_limit_below_one_packet_or_two_limits_are_refused() {
        let base = PacketParams { queue_bytes: Some(123), ..PacketParams::default() };
        let e = Packets::new(&base).unwrap_err();
        assert_eq!(e.field, "queue_bytes");
        assert!(e.problem.contains("at least one packet (124 bytes"), "{e}");
        let e = Packets::new(&PacketParams { queue_packets: Some(0), ..PacketParams::default() }).unwrap_err();
        assert_eq!(e.field, "queue_packets");
        let e = Packets::new(&PacketParams { queue_packets: Some(2), queue_bytes: Some(2000), ..PacketParams::default() }).unwrap_err();
        assert!(e.problem.contains("not both"), "{e}");
        assert!(Packets::new(&PacketParams { queue_bytes: Some(124), ..PacketParams::default() }).is_ok());
    }

    #[test]
    fn the_backlog_counts_what_has_not_left() {
        let p = packets(124, 1500, 0, QueueLimit::Bytes(300));
        let mut b = Backlog::new(&p);
        assert!(b.fits(1, 124));
        b.push(10, 124);
        b.push(20, 124);
        assert!(!b.fits(1, 124));
        b.advance(10);
        assert_eq!((b.packets(), b.bytes()), (1, 124));
        assert!(b.fits(1, 124));
    }
}
