//! `trace` (docs/spec.md §3.13): a link whose capacity follows a Mahimahi
//! link trace, with mm-link's semantics (`src/frontend/link_queue.cc`).
//!
//! The trace. One integer a line, a time in ms from the start of the trace,
//! not decreasing; each line is one delivery opportunity of
//! `opportunity_bytes` (mm-link's `PACKET_SIZE`, 1504: a 1500-byte packet
//! and its 4-byte TUN header); a time written k times is k opportunities in
//! that ms. The last time `P` is the trace's period: at the end the trace
//! repeats, shifted by `P` (so a file holding only `1` is one opportunity
//! every ms). A trace is refused, naming the file and the line, when it is
//! empty, has a blank or non-numeric line, a time that decreases, or only
//! zeros (`P = 0`), as mm-link refuses it. The file is read by the shell
//! ([`crate::load`]); [`Schedule::parse`] takes its text.
//!
//! Law. The trace's time 0 is when the first frame reaches the stage. A
//! packet (see [`super::backlog`] for how a payload becomes packets) that
//! arrives at `t` can use the opportunities after `t` (mm-link burns the
//! opportunities up to now before it enqueues a packet). Packets are served
//! in arrival order; an opportunity carries up to `opportunity_bytes` of
//! them: a packet may span several opportunities and leaves at the one
//! that carries its last byte; what that opportunity has left goes to the
//! next packet if one is queued by then, and is lost otherwise. A frame
//! leaves with its last packet; the delay it gets is that opportunity's
//! time minus its arrival. Each packet's departure is computed when it
//! arrives, exactly, from the bytes queued ahead of it: FIFO service on a
//! fixed schedule depends on nothing that comes later.
//!
//! Queue. As in mm-link's dropping queues, a packet counts against the
//! limit from its arrival until the opportunity that starts carrying it
//! (the packet in transit is no longer queued). A frame whose packets do
//! not all fit is dropped whole, reason `link_queue`. Where mm-link differs:
//! its queues are unbounded by default (here: 1000 packets, as netem), its
//! clock is in whole ms (here ns: a packet arriving at 4.7 ms may use the
//! opportunity at 5 ms, as in mm-link, and one at exactly 5 ms may not),
//! and it refuses a packet larger than one opportunity (here a packet spans
//! opportunities, and a payload larger than the MTU goes as several).

use super::backlog::{default_mtu, default_payload, is_default_mtu, is_default_payload, is_zero, link_params, LinkQueue, LinkStage, LinkStats, PacketParams, Packets};
use super::{Model, ParamError, StageRng, Verdict};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// mm-link's bytes per delivery opportunity (`PACKET_SIZE`).
pub const MM_OPPORTUNITY_BYTES: u64 = 1504;
/// The longest trace period: one year, in ms.
pub const MAX_PERIOD_MS: u64 = crate::model::units::MAX_PHASE_START_MS as u64;
/// The most lines a trace may have.
pub const MAX_LINES: usize = 1 << 26;

/// A parsed link trace: its delivery opportunities, in ms.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Schedule {
    ms: Vec<u64>,
}

/// What is wrong with a trace's text, and on which line (1-based).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}{problem}", line.map(|l| format!("line {l}: ")).unwrap_or_default())]
pub struct ScheduleError {
    pub line: Option<usize>,
    pub problem: String,
}

impl Schedule {
    /// Parses a Mahimahi trace (see the module docs for what is refused).
    pub fn parse(text: &str) -> Result<Schedule, ScheduleError> {
        let err = |line: Option<usize>, problem: String| ScheduleError { line, problem };
        let mut ms: Vec<u64> = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = Some(i + 1);
            let s = raw.trim();
            if s.is_empty() {
                return Err(err(line, "blank line: every line is one time in ms".into()));
            }
            // The line itself is not repeated: the file may not be a trace
            // at all, and its content is no business of an error message.
            let v: u64 = s.parse().map_err(|_| err(line, "not a time: expected a whole number of ms".into()))?;
            if v > MAX_PERIOD_MS {
                return Err(err(line, format!("a time beyond one year: expected at most {MAX_PERIOD_MS} ms")));
            }
            if let Some(&prev) = ms.last() {
                if v < prev {
                    return Err(err(line, "earlier than the line before: times must not decrease".into()));
                }
            }
            if ms.len() == MAX_LINES {
                return Err(err(line, format!("more than {MAX_LINES} lines")));
            }
            ms.push(v);
        }
        match ms.last() {
            None => Err(err(None, "the trace is empty: it needs at least one time".into())),
            Some(0) => Err(err(Some(ms.len()), "every time is 0: the trace must last for some time (its last time is its period)".into())),
            Some(_) => Ok(Schedule { ms }),
        }
    }

    /// A schedule from times already in hand (validated as [`Schedule::parse`] does).
    pub fn from_ms(ms: &[u64]) -> Result<Schedule, ScheduleError> {
        let text: String = ms.iter().map(|m| format!("{m}\n")).collect();
        Schedule::parse(&text)
    }

    /// Opportunities per period.
    pub fn len(&self) -> usize {
        self.ms.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ms.is_empty()
    }

    /// The period `P`, ms (the last time).
    pub fn period_ms(&self) -> u64 {
        *self.ms.last().expect("a schedule is never empty")
    }

    /// The time of opportunity `k` (counting through the repeats), ms from the
    /// trace's start.
    #[inline]
    pub fn at_ms(&self, k: u64) -> u64 {
        let n = self.ms.len() as u64;
        (k / n) * self.period_ms() + self.ms[(k % n) as usize]
    }

    /// The first opportunity at or after ms `m`.
    #[inline]
    pub fn first_at_or_after_ms(&self, m: u64) -> u64 {
        let p = self.period_ms();
        let n = self.ms.len() as u64;
        let (mut cycle, mut r) = (m / p, m % p);
        // The end of one cycle (time P) is the same moment as the start of
        // the next: an opportunity at P in the previous cycle comes first.
        if r == 0 && cycle > 0 {
            cycle -= 1;
            r = p;
        }
        cycle * n + self.ms.partition_point(|&x| x < r) as u64
    }

    /// The mean capacity, bit/s, at `opportunity_bytes` per opportunity.
    pub fn mean_rate_bit_s(&self, opportunity_bytes: u64) -> f64 {
        self.ms.len() as f64 * opportunity_bytes as f64 * 8.0 / (self.period_ms() as f64 / 1e3)
    }
}

link_params! {
    #[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
    #[serde(deny_unknown_fields)]
    pub struct LinkTraceParams {
        /// The trace file, relative to the scenario file.
        pub file: String,
        /// Bytes one opportunity carries.
        #[serde(default = "default_opportunity", skip_serializing_if = "is_default_opportunity")]
        pub opportunity_bytes: u64,
        /// The parsed trace, filled in by whoever read `file`.
        #[serde(skip)]
        pub schedule: Option<Arc<Schedule>>,
    }
}

fn default_opportunity() -> u64 {
    MM_OPPORTUNITY_BYTES
}
fn is_default_opportunity(v: &u64) -> bool {
    *v == MM_OPPORTUNITY_BYTES
}

impl LinkTraceParams {
    /// A trace link over `schedule` with the default packets and queue.
    pub fn new(file: impl Into<String>, schedule: Schedule) -> LinkTraceParams {
        LinkTraceParams::with_default_packets(file.into(), MM_OPPORTUNITY_BYTES, Some(Arc::new(schedule)))
    }
}

/// A validated `trace` stage and its queue.
#[derive(Debug, Clone)]
pub struct LinkTrace {
    schedule: Arc<Schedule>,
    opportunity_bytes: u64,
    /// The trace's time 0 (the first frame's arrival).
    base_ns: Option<u64>,
    /// The opportunity the last packet left at, and the bytes it has left.
    cursor: Option<(u64, u64)>,
    /// The opportunity the first frame could use (for the utilisation).
    first_k: u64,
    queue: LinkQueue,
}

impl LinkTrace {
    pub fn new(p: &LinkTraceParams) -> Result<LinkTrace, ParamError> {
        let Some(schedule) = p.schedule.clone() else {
            return Err(ParamError::new("file", format!("the trace `{}` was not read: load the scenario from its file", p.file)));
        };
        if p.opportunity_bytes == 0 || p.opportunity_bytes > super::backlog::MAX_PAYLOAD_BYTES {
            return Err(ParamError::new(
                "opportunity_bytes",
                format!("{} is out of range: expected 1 to {}", p.opportunity_bytes, super::backlog::MAX_PAYLOAD_BYTES),
            ));
        }
        let packets = Packets::new(&p.packet_params())?;
        Ok(LinkTrace {
            schedule,
            opportunity_bytes: p.opportunity_bytes,
            base_ns: None,
            cursor: None,
            first_k: 0,
            queue: LinkQueue::new(packets),
        })
    }

    pub fn schedule(&self) -> &Schedule {
        &self.schedule
    }

    pub fn opportunity_bytes(&self) -> u64 {
        self.opportunity_bytes
    }

    pub fn packets(&self) -> &Packets {
        &self.queue.packets
    }

    pub fn stats(&self) -> &LinkStats {
        &self.queue.stats
    }

    pub(crate) fn stats_mut(&mut self) -> &mut LinkStats {
        &mut self.queue.stats
    }

    /// The trace's time 0, once a frame has come.
    pub fn base_ns(&self) -> Option<u64> {
        self.base_ns
    }

    /// The queue now (as of the last frame): packets and wire bytes.
    pub fn queued(&self) -> (u64, u64) {
        self.queue.queued()
    }

    /// The time of opportunity `k`, ns (after the first frame).
    #[inline]
    pub fn opportunity_ns(&self, k: u64) -> u64 {
        self.base_ns.unwrap_or(0).saturating_add(self.schedule.at_ms(k).saturating_mul(1_000_000))
    }

    /// The first opportunity strictly after `t_ns`.
    #[inline]
    fn first_after(&self, t_ns: u64) -> u64 {
        // A frame may reach the stage before the first one did, after an
        // upstream reorder: it waits for the trace's first opportunities.
        let rel = t_ns.saturating_sub(self.base_ns.unwrap_or(t_ns));
        self.schedule.first_at_or_after_ms(rel / 1_000_000 + 1)
    }

    /// The bytes carried over the opportunities offered from the first frame
    /// to the last departure.
    pub fn utilisation(&self) -> f64 {
        if self.queue.stats.first_ns.is_none() {
            return 0.0;
        }
        let last = self.first_after(self.queue.stats.last_departure_ns);
        let offered = last.saturating_sub(self.first_k) as f64 * self.opportunity_bytes as f64;
        if offered > 0.0 {
            self.queue.stats.bytes as f64 / offered
        } else {
            0.0
        }
    }

    /// Decides a payload of `len` bytes reaching the stage at `t_ns`.
    #[inline]
    pub fn decide_len(&mut self, t_ns: u64, len: u64) -> Verdict {
        if self.base_ns.is_none() {
            self.base_ns = Some(t_ns);
            self.first_k = self.first_after(t_ns);
        }
        self.admit(t_ns, len)
    }

    /// Carries one packet of `bytes` arriving at `t_ns` behind everything
    /// admitted: the opportunities carrying its first and last byte, and the
    /// bytes the last one has left.
    #[inline]
    fn carry(&self, t_ns: u64, bytes: u64) -> (u64, u64, u64) {
        let (k, left) = match self.cursor {
            // The last packet's opportunity is still to come and has room.
            Some((k, left)) if left > 0 && self.opportunity_ns(k) > t_ns => (k, left),
            // Otherwise the next opportunity after both it and now, whole.
            Some((k, _)) => (self.first_after(t_ns).max(k + 1), self.opportunity_bytes),
            None => (self.first_after(t_ns), self.opportunity_bytes),
        };
        if bytes <= left {
            return (k, k, left - bytes);
        }
        let rest = bytes - left;
        let more = rest.div_ceil(self.opportunity_bytes);
        (k, k + more, more * self.opportunity_bytes - rest)
    }
}

impl LinkStage for LinkTrace {
    #[inline]
    fn queue(&mut self) -> &mut LinkQueue {
        &mut self.queue
    }

    /// A packet leaves the queue when the opportunity that starts carrying
    /// it comes, and the link with the one that carries its last byte.
    #[inline]
    fn serve(&mut self, t_ns: u64, bytes: u64) -> (u64, u64) {
        let (start_k, end_k, left) = self.carry(t_ns, bytes);
        self.cursor = Some((end_k, left));
        (self.opportunity_ns(start_k), self.opportunity_ns(end_k))
    }
}

impl Model for LinkTrace {
    #[inline]
    fn decide(&mut self, t_ns: u64, _rng: &mut StageRng) -> Verdict {
        self.decide_len(t_ns, self.queue.packets.payload_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_traces_name_their_line() {
        let cases: [(&str, Option<usize>, &str); 6] = [
            ("", None, "empty"),
            ("1\n2\nx\n", Some(3), "not a time: expected a whole number of ms"),
            ("1\n\n2\n", Some(2), "blank line"),
            ("5\n7\n6\n", Some(3), "must not decrease"),
            ("0\n0\n0\n", Some(3), "every time is 0"),
            ("-1\n", Some(1), "not a time"),
        ];
        for (text, line, piece) in cases {
            let e = Schedule::parse(text).unwrap_err();
            assert_eq!(e.line, line, "{text:?}: {e}");
            assert!(e.problem.contains(piece), "{e}");
        }
        assert_eq!(Schedule::parse("0\n3\r\n3\n").unwrap().len(), 3);
    }

    #[test]
    fn opportunities_repeat_with_the_period() {
        let s = Schedule::parse("0\n2\n2\n5\n").unwrap();
        let times: Vec<u64> = (0..9).map(|k| s.at_ms(k)).collect();
        assert_eq!(times, [0, 2, 2, 5, 5, 7, 7, 10, 10]);
        // The first opportunity at or after each ms, against a linear scan.
        for m in 0..30 {
            let scan = (0..).find(|&k| s.at_ms(k) >= m).unwrap();
            assert_eq!(s.first_at_or_after_ms(m), scan, "ms {m}");
        }
    }

    fn link(trace: &str, extra: impl FnOnce(&mut LinkTraceParams)) -> LinkTrace {
        let mut p = LinkTraceParams::new("t", Schedule::parse(trace).unwrap());
        extra(&mut p);
        LinkTrace::new(&p).unwrap()
    }

    #[test]
    fn packets_share_an_opportunity_and_span_them() {
        // One opportunity per ms. Twelve 124-byte frames fill 1488 of an
        // opportunity's 1504 bytes; the thirteenth spans into the next.
        let mut m = link("1\n", |_| {});
        let mut rng = <StageRng as rand::SeedableRng>::seed_from_u64(1);
        let t0 = 1_000_000_000;
        let delays: Vec<u64> = (0..14)
            .map(|_| match m.decide(t0, &mut rng) {
                Verdict::Pass { delay_ns } => delay_ns,
                v => panic!("{v:?}"),
            })
            .collect();
        assert!(delays[..12].iter().all(|&d| d == 1_000_000), "{delays:?}");
        assert_eq!(delays[12..], [2_000_000, 2_000_000]);
        // At exactly an opportunity's time a frame cannot use it.
        assert_eq!(m.decide(t0 + 5_000_000, &mut rng), Verdict::Pass { delay_ns: 1_000_000 });
        assert_eq!(m.decide(t0 + 7_300_000, &mut rng), Verdict::Pass { delay_ns: 700_000 });
    }

    #[test]
    fn the_queue_counts_packets_not_yet_in_transit() {
        let mut m = link("1\n", |p| p.queue_packets = Some(2));
        let mut rng = <StageRng as rand::SeedableRng>::seed_from_u64(1);
        assert!(matches!(m.decide(0, &mut rng), Verdict::Pass { .. }));
        assert!(matches!(m.decide(0, &mut rng), Verdict::Pass { .. }));
        assert_eq!(m.decide(0, &mut rng), Verdict::Drop);
        // At 1 ms both have gone into transit.
        assert!(matches!(m.decide(1_000_000, &mut rng), Verdict::Pass { .. }));
        assert_eq!(m.stats().frames_dropped, 1);
    }

    #[test]
    fn frames_out_of_time_order_are_served_in_arrival_order() {
        // After a reordering stage a frame may reach the link earlier than
        // the one before it: it queues behind it.
        let mut m = link("1\n", |_| {});
        let mut rng = <StageRng as rand::SeedableRng>::seed_from_u64(1);
        let t0 = 50_000_000;
        assert_eq!(m.decide(t0, &mut rng), Verdict::Pass { delay_ns: 1_000_000 });
        assert_eq!(m.decide(t0 - 20_000_000, &mut rng), Verdict::Pass { delay_ns: 21_000_000 });
        let mut r = crate::model::Rate::new(&crate::model::RateParams::new(8e6)).unwrap();
        assert_eq!(r.decide(t0, &mut rng), Verdict::Pass { delay_ns: 124_000 });
        assert_eq!(r.decide(t0 - 1_000_000, &mut rng), Verdict::Pass { delay_ns: 1_248_000 });
    }

    #[test]
    fn an_unread_trace_is_refused() {
        let mut p = LinkTraceParams::new("x.up", Schedule::parse("1\n").unwrap());
        p.schedule = None;
        assert_eq!(LinkTrace::new(&p).unwrap_err().field, "file");
    }
}
