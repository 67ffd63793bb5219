//! The emulator's telemetry: per interval (100 ms by default,
//! `--telemetry-ms`), the frames that entered, were released and dropped,
//! the realized loss, and the percentiles of the injected delay and of the
//! release lateness of the frames released in it. Published on the run's
//! telemetry service (docs/interface.md, "Telemetry") and printed by
//! `netfi ctl watch`.
//!
//! Nothing of it runs on the emulator's loop. The loop already pushes one
//! trace event per ingress and per release into the wait-free trace ring
//! ([`crate::trace`]); the trace's writer thread, which drains that ring
//! anyway, hands each event to an [`Aggregator`] (a [`Tap`]). Events are
//! placed in intervals by their own time stamps (the loop's clock), not by
//! when the writer saw them; an interval is closed once the writer's clock
//! is [`GRACE_NS`] past its end (the ring is drained every few
//! milliseconds), and an event that comes later still is counted in the
//! interval open then. The loop's cost is therefore exactly what it was
//! without telemetry: zero added work per frame.

use crate::clock::now_ns;
use crate::metrics::LatencyHistogram;
use crate::trace::Tap;
use crate::transport::ipc::control::TelemetrySample;
use std::sync::mpsc;

/// How long after an interval's end the writer waits for its last events.
pub const GRACE_NS: u64 = 20_000_000;

/// The default interval, ms.
pub const DEFAULT_INTERVAL_MS: u64 = 100;

/// Cuts the trace's events into intervals and sends each closed one.
pub struct Aggregator {
    interval_ns: u64,
    /// The first frame's ingress time: interval 0 starts there.
    base_ns: Option<u64>,
    seq: u64,
    entered: u64,
    delivered: u64,
    dropped: u64,
    injected: LatencyHistogram,
    lateness: LatencyHistogram,
    out: mpsc::Sender<TelemetrySample>,
}

impl Aggregator {
    /// Intervals of `interval_ns`, each sent on `out` when closed.
    pub fn new(interval_ns: u64, out: mpsc::Sender<TelemetrySample>) -> Aggregator {
        Aggregator {
            interval_ns: interval_ns.max(1_000_000),
            base_ns: None,
            seq: 0,
            entered: 0,
            delivered: 0,
            dropped: 0,
            injected: LatencyHistogram::new(),
            lateness: LatencyHistogram::new(),
            out,
        }
    }

    /// Closes every interval that ends at or before `t_ns`.
    fn roll(&mut self, t_ns: u64) {
        let Some(base) = self.base_ns else { return };
        while t_ns >= base + (self.seq + 1) * self.interval_ns {
            let _ = self.out.send(self.sample());
            self.seq += 1;
            (self.entered, self.delivered, self.dropped) = (0, 0, 0);
            self.injected.reset();
            self.lateness.reset();
        }
    }

    /// The current interval as a sample (phase and pause are the control
    /// thread's to fill in).
    fn sample(&self) -> TelemetrySample {
        let (i, l) = (self.injected.summary(), self.lateness.summary());
        TelemetrySample {
            version: TelemetrySample::VERSION,
            flags: 0,
            seq: self.seq,
            start_ns: self.seq * self.interval_ns,
            length_ns: self.interval_ns,
            entered: self.entered,
            delivered: self.delivered,
            dropped: self.dropped,
            loss_rate: if self.entered > 0 { self.dropped as f64 / self.entered as f64 } else { f64::NAN },
            phase: 0,
            reserved: 0,
            injected_ns: [i.p50, i.p90, i.p99, i.max],
            lateness_ns: [l.p50, l.p99, l.p999, l.max],
        }
    }
}

impl Tap for Aggregator {
    fn ingress(&mut self, ingress_ns: u64, dropped: bool) {
        let base = *self.base_ns.get_or_insert(ingress_ns);
        if ingress_ns >= base {
            self.roll(ingress_ns);
        }
        self.entered += 1;
        self.dropped += u64::from(dropped);
    }

    fn release(&mut self, release_ns: u64, injected_ns: u64, lateness_ns: u64) {
        if self.base_ns.is_none() {
            return;
        }
        self.roll(release_ns);
        self.delivered += 1;
        self.injected.record(injected_ns);
        self.lateness.record(lateness_ns);
    }

    fn tick(&mut self) {
        self.roll(now_ns().saturating_sub(GRACE_NS));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_fall_in_the_intervals_of_their_time_stamps() {
        let (tx, rx) = mpsc::channel();
        let mut a = Aggregator::new(100_000_000, tx);
        let t0 = 5_000_000_000;
        // Interval 0: 10 frames, 3 dropped, 7 released 2 ms late after 50 ms.
        for k in 0..10 {
            a.ingress(t0 + k * 1_000_000, k < 3);
        }
        for k in 3..10 {
            a.release(t0 + k * 1_000_000 + 50_000_000, 50_000_000, 2_000);
        }
        // Interval 2 (1 frame); interval 1 is empty.
        a.ingress(t0 + 250_000_000, false);
        let got: Vec<TelemetrySample> = rx.try_iter().collect();
        assert_eq!(got.len(), 2);
        assert_eq!((got[0].seq, got[0].entered, got[0].dropped, got[0].delivered), (0, 10, 3, 7));
        assert!((got[0].loss_rate - 0.3).abs() < 1e-12);
        assert!(got[0].injected_ns[0].abs_diff(50_000_000) <= 50_000, "{:?}", got[0].injected_ns);
        assert!(got[0].lateness_ns[3].abs_diff(2_000) <= 2, "{:?}", got[0].lateness_ns);
        assert_eq!((got[1].seq, got[1].entered, got[1].start_ns), (1, 0, 100_000_000));
        assert!(got[1].loss_rate.is_nan());
    }
}
