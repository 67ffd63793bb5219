//! `rate` (docs/spec.md §3.12): a bottleneck of `R` bit/s with a drop-tail
//! queue, netem's `rate RATE [packet_overhead] [cellsize] [celloverhead]`
//! with `limit`.
//!
//! Law. A frame's payload of `L` bytes goes as packets ([`super::backlog`]:
//! `⌈L / mtu_bytes⌉` of them, `overhead_bytes` more each on the wire). A
//! packet of `b` wire bytes costs `c = 8·b` bits, or with cells (netem's
//! `cellsize C`, `celloverhead H`) `c = 8·⌈b / C⌉·(C + H)`. Packets are
//! served one at a time in the order they reach the stage; packet `j`,
//! reaching it at `a_j`, finishes at
//!
//! ```text
//! D_j = max(D_{j-1}, a_j) + c_j / R        (exact: rational time, no drift)
//! ```
//!
//! and the frame leaves when its last packet does: the stage's delay is
//! `⌈D_last⌉ − a` in ns, the queueing (`max(D_{j-1}, a) − a`, the backlog
//! in bits over `R`) plus the serialization of its own packets. The link is
//! work-conserving: it is never idle while a packet waits.
//!
//! Queue. A packet counts against the limit from its arrival until it has
//! left (`D_j`), as in netem, where a packet stays in the tfifo until its
//! `time_to_send`. A frame whose packets do not all fit (`queue_packets`,
//! default 1000 as netem's `limit`, or `queue_bytes` of wire bytes) is
//! dropped whole: the drop reason is `link_queue`. A dropped frame adds
//! nothing to the backlog; no randomness is drawn.
//!
//! Where netem differs: netem computes each packet's time in whole ns,
//! truncating (`len · NSEC_PER_SEC / rate`), so its clock drifts by up to
//! 1 ns per packet; here time is kept exactly and only rounded up to the ns
//! at release. netem's packet length is the L2 frame (`qdisc_pkt_len`); here
//! it is the payload, and headers go in `overhead_bytes` (netem's
//! `packet_overhead` may be negative; here it is 0 or more). netem counts
//! its `limit` in packets only; `queue_bytes` is Mahimahi's byte limit.
//! netem refers a packet to the tfifo's tail, delay and jitter included;
//! here the stage only queues, and a `delay` or `jitter` stage before or
//! after it composes as a separate step of the pipeline. A payload larger
//! than the MTU is cut into packets that share its fate (netem sends
//! whatever the socket gave it, GSO segments included).

use super::backlog::{default_mtu, default_payload, is_default_mtu, is_default_payload, is_zero, link_params, LinkQueue, LinkStage, LinkStats, PacketParams, Packets};
use super::{Model, ParamError, StageRng, Verdict};
use serde::{Deserialize, Serialize};

/// The fastest link: 1 Tbit/s (so `t · R` fits a u128 for any u64 time).
pub const MAX_RATE_BIT_S: f64 = 1e12;

link_params! {
    #[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
    #[serde(deny_unknown_fields)]
    pub struct RateParams {
        /// The bottleneck's rate, a whole number of bit/s from 1 to 10^12.
        pub rate_bit_s: f64,
        /// netem's `cellsize`: packets go as whole cells of this many bytes.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pub cell_bytes: Option<u64>,
        /// netem's `celloverhead`: bytes each cell adds.
        #[serde(default, skip_serializing_if = "is_zero")]
        pub cell_overhead_bytes: u64,
    }
}

impl RateParams {
    /// A link of `rate_bit_s` with the default packets (124-byte payloads,
    /// 1500-byte MTU, no overhead, 1000 packets of queue).
    pub fn new(rate_bit_s: f64) -> RateParams {
        RateParams::with_default_packets(rate_bit_s, None, 0)
    }
}

/// A validated `rate` stage and its queue.
#[derive(Debug, Clone)]
pub struct Rate {
    rate_bit_s: u64,
    cell: Option<(u64, u64)>,
    /// When the link has sent everything admitted, in units of `1/R` ns
    /// (so a packet of `c` bits takes exactly `c · 10^9` of them).
    free_tick: u128,
    /// The link's busy time so far, in the same units.
    busy_ticks: u128,
    queue: LinkQueue,
}

impl Rate {
    pub fn new(p: &RateParams) -> Result<Rate, ParamError> {
        let r = p.rate_bit_s;
        if !r.is_finite() || !(1.0..=MAX_RATE_BIT_S).contains(&r) || r.fract() != 0.0 {
            return Err(ParamError::new(
                "rate_bit_s",
                format!("{r} is not a link rate: expected a whole number of bit/s from 1 to {MAX_RATE_BIT_S:e} (a rate of zero carries nothing)"),
            ));
        }
        let cell = match p.cell_bytes {
            None if p.cell_overhead_bytes != 0 => {
                return Err(ParamError::new("cell_overhead_bytes", "applies to cells: give `cell_bytes` too"));
            }
            None => None,
            Some(c) if c == 0 || c > super::backlog::MAX_PAYLOAD_BYTES => {
                return Err(ParamError::new("cell_bytes", format!("{c} is out of range: expected 1 to {}", super::backlog::MAX_PAYLOAD_BYTES)));
            }
            Some(_) if p.cell_overhead_bytes > super::backlog::MAX_OVERHEAD_BYTES => {
                return Err(ParamError::new(
                    "cell_overhead_bytes",
                    format!("{} is out of range: expected 0 to {}", p.cell_overhead_bytes, super::backlog::MAX_OVERHEAD_BYTES),
                ));
            }
            Some(c) => Some((c, p.cell_overhead_bytes)),
        };
        let packets = Packets::new(&p.packet_params())?;
        Ok(Rate { rate_bit_s: r as u64, cell, free_tick: 0, busy_ticks: 0, queue: LinkQueue::new(packets) })
    }

    pub fn rate_bit_s(&self) -> u64 {
        self.rate_bit_s
    }

    pub fn packets(&self) -> &Packets {
        &self.queue.packets
    }

    /// netem's cells, if any: (`cellsize`, `celloverhead`).
    pub fn cell(&self) -> Option<(u64, u64)> {
        self.cell
    }

    pub fn stats(&self) -> &LinkStats {
        &self.queue.stats
    }

    pub(crate) fn stats_mut(&mut self) -> &mut LinkStats {
        &mut self.queue.stats
    }

    /// The queue now (as of the last frame): packets and wire bytes.
    pub fn queued(&self) -> (u64, u64) {
        self.queue.queued()
    }

    /// The bits a packet of `bytes` wire bytes costs (netem's cells).
    #[inline]
    pub fn cost_bits(&self, bytes: u64) -> u64 {
        match self.cell {
            None => 8 * bytes,
            Some((size, overhead)) => 8 * bytes.div_ceil(size) * (size + overhead),
        }
    }

    /// The fraction of time the link was sending, from the first frame to
    /// the last departure.
    pub fn utilisation(&self) -> f64 {
        let Some(first) = self.queue.stats.first_ns else { return 0.0 };
        let span_ns = self.queue.stats.last_departure_ns.saturating_sub(first);
        if span_ns == 0 {
            return 0.0;
        }
        (self.busy_ticks as f64 / self.rate_bit_s as f64) / span_ns as f64
    }

    /// Decides a payload of `len` bytes reaching the stage at `t_ns`.
    #[inline]
    pub fn decide_len(&mut self, t_ns: u64, len: u64) -> Verdict {
        self.admit(t_ns, len)
    }
}

impl LinkStage for Rate {
    #[inline]
    fn queue(&mut self) -> &mut LinkQueue {
        &mut self.queue
    }

    /// A packet is sent after everything admitted before it (from now, if
    /// the link is idle), and leaves the queue when its last bit is sent.
    #[inline]
    fn serve(&mut self, t_ns: u64, bytes: u64) -> (u64, u64) {
        let r = u128::from(self.rate_bit_s);
        let ticks = u128::from(self.cost_bits(bytes)) * 1_000_000_000;
        self.free_tick = self.free_tick.max(u128::from(t_ns) * r) + ticks;
        self.busy_ticks += ticks;
        // Rounded up: a frame never leaves before its last bit.
        let departure_ns = u64::try_from(self.free_tick.div_ceil(r)).unwrap_or(u64::MAX);
        (departure_ns, departure_ns)
    }
}

impl Model for Rate {
    #[inline]
    fn decide(&mut self, t_ns: u64, _rng: &mut StageRng) -> Verdict {
        self.decide_len(t_ns, self.queue.packets.payload_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rate(text: &str) -> Result<Rate, ParamError> {
        Rate::new(&toml::from_str::<RateParams>(text).unwrap())
    }

    #[test]
    fn zero_and_fractional_rates_are_refused() {
        for bad in ["rate_bit_s = 0", "rate_bit_s = 1.5", "rate_bit_s = 2e12", "rate_bit_s = -8"] {
            let e = rate(bad).unwrap_err();
            assert_eq!(e.field, "rate_bit_s", "{bad}");
            assert!(e.problem.contains("whole number of bit/s"), "{e}");
        }
        assert!(rate("rate_bit_s = 1").is_ok());
        let e = rate("rate_bit_s = 1e6\ncell_overhead_bytes = 4").unwrap_err();
        assert_eq!(e.field, "cell_overhead_bytes");
    }

    #[test]
    fn a_burst_queues_behind_itself_exactly() {
        // 8 Mbit/s: one byte per µs, a 124-byte frame takes 124 µs.
        let mut m = rate("rate_bit_s = 8e6").unwrap();
        let mut rng = <StageRng as rand::SeedableRng>::seed_from_u64(1);
        for k in 0..10u64 {
            assert_eq!(m.decide(5_000, &mut rng), Verdict::Pass { delay_ns: 124_000 * (k + 1) });
        }
        // Idle again: only its own serialization.
        assert_eq!(m.decide(10_000_000, &mut rng), Verdict::Pass { delay_ns: 124_000 });
    }

    #[test]
    fn cells_round_each_packet_up() {
        // netem: 124 + 4 = 128 bytes in 48-byte cells of 53: 3 cells, 159 bytes.
        let m = rate("rate_bit_s = 1e6\ncell_bytes = 48\ncell_overhead_bytes = 5\noverhead_bytes = 4").unwrap();
        assert_eq!(m.cost_bits(128), 8 * 159);
    }

    #[test]
    fn a_frame_that_does_not_fit_is_dropped_whole() {
        // 3000-byte payloads go as two packets; the queue holds three.
        let mut m = rate("rate_bit_s = 8e6\npayload_bytes = 3000\nqueue_packets = 3").unwrap();
        let mut rng = <StageRng as rand::SeedableRng>::seed_from_u64(1);
        assert!(matches!(m.decide(0, &mut rng), Verdict::Pass { delay_ns: 3_000_000 }));
        assert_eq!(m.decide(0, &mut rng), Verdict::Drop);
        let s = m.stats();
        assert_eq!((s.frames, s.packets, s.frames_dropped, s.packets_dropped), (1, 2, 1, 2));
        // The first packet has left after 1.5 ms: two more fit.
        assert!(matches!(m.decide(1_500_000, &mut rng), Verdict::Pass { .. }));
    }
}
