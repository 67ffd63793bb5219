//! Driving an interval: every frame sent at its time, both routes
//! busy-polled in between (chain intervals), or one route paced (floors).

use crate::common::args::stopped;
use crate::common::ends::{wire, Ends, Route};
use netfi::clock::{now_ns, sleep_until_ns};
use netfi::metrics::LatencyHistogram;

/// Frames sent before recording starts, in seconds of the interval's rate:
/// page faults of fresh shared memory, cold caches and the first
/// connections stay out of the figures.
pub const WARMUP_S: f64 = 0.5;

/// Before a frame is due, the driving thread sleeps until this long before
/// it (when nothing is in flight), then polls: other work on its core runs
/// in the gaps instead of preempting it at random moments.
const SLEEP_SLACK_NS: u64 = 100_000;

/// What one chain interval measured on the benchmark's side.
#[derive(Debug, Clone, Default)]
pub struct Drive {
    /// Receive − send − injected delay, through the emulator.
    pub chain: LatencyHistogram,
    /// Receive − send, straight.
    pub direct: LatencyHistogram,
    /// Chain split by the emulator's stamps (iceoryx2): send → taken off
    /// its port; taken → released; released → received.
    pub hop1: LatencyHistogram,
    pub inside: LatencyHistogram,
    pub hop2: LatencyHistogram,
    /// Actual − planned send time.
    pub send_lateness: LatencyHistogram,
    pub chain_sent: u64,
    pub chain_received: u64,
    pub direct_sent: u64,
    pub direct_received: u64,
    pub refused: u64,
    pub seconds: f64,
    /// From the first recorded send to the last send: the rate the driving
    /// thread really offered is the frames sent over this.
    pub send_seconds: f64,
}

impl Drive {
    fn in_flight(&self) -> bool {
        self.chain_sent > self.chain_received || self.direct_sent > self.direct_received
    }

    /// Takes every waiting frame of both routes, recording those after the
    /// warm-up (`warm` slots).
    pub fn poll_routes(&mut self, ends: &mut impl Ends, warm: u64, stamped: bool) {
        while let Some(a) = ends.poll(Route::Chain) {
            self.chain_received += 1;
            if a.slot >= warm {
                self.chain.record_signed(a.recv_ns as i64 - a.send_ns as i64 - a.injected_delay_ns as i64);
                if stamped {
                    self.hop1.record_signed(a.ingress_ns as i64 - a.send_ns as i64);
                    self.inside.record_signed(a.release_ns as i64 - a.ingress_ns as i64 - a.injected_delay_ns as i64);
                    self.hop2.record_signed(a.recv_ns as i64 - a.release_ns as i64);
                }
            }
        }
        // Only this thread sends on the direct route: nothing can arrive
        // there while nothing is in flight, and an empty poll of a port
        // costs about as much as a receive (a capacity trial never sends
        // on it).
        while self.direct_sent > self.direct_received {
            let Some(a) = ends.poll(Route::Direct) else { break };
            self.direct_received += 1;
            if a.slot >= warm {
                self.direct.record_signed(a.recv_ns as i64 - a.send_ns as i64);
            }
        }
    }

    /// Sends slot `slot` on its route (see [`Routes::of`]).
    pub fn send(&mut self, ends: &mut impl Ends, slot: u64, routes: Routes) {
        let route = routes.of(slot);
        let ok = ends.send(route, slot, &wire(slot));
        match (route, ok) {
            (Route::Chain, true) => self.chain_sent += 1,
            (Route::Direct, true) => self.direct_sent += 1,
            (_, false) => self.refused += 1,
        }
    }
}

/// The routes an interval sends on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Routes {
    /// Chain on even slots, direct on odd, half a period apart: the
    /// latency intervals.
    Alternate,
    /// Every slot through the emulator, a period apart: the capacity
    /// trials, where the driving thread's whole budget goes to the chain.
    ChainOnly,
}

impl Routes {
    fn count(self) -> u64 {
        match self {
            Routes::Alternate => 2,
            Routes::ChainOnly => 1,
        }
    }

    fn of(self, slot: u64) -> Route {
        if self == Routes::ChainOnly || slot.is_multiple_of(2) {
            Route::Chain
        } else {
            Route::Direct
        }
    }
}

/// Slots of an interval: `warmup + frames` per route, `routes` of them
/// sharing the period.
pub fn slots_for(rate_hz: f64, seconds: f64, routes: Routes) -> (u64, u64) {
    let warmup = (rate_hz * WARMUP_S).ceil() as u64;
    let frames = (rate_hz * seconds).round() as u64;
    (routes.count() * warmup, routes.count() * (warmup + frames))
}

/// Sends every slot at its time on each of `ends` and busy-polls every
/// route in between, in one thread; then waits up to `drain_ns` for the
/// chain's last frames. With several ends (one per stream), end k's slots
/// come k/n of a slot after end 0's (the consoles are not in step); the
/// figures are of all of them together. With `may_sleep` the thread sleeps
/// ahead of a slot while nothing is in flight.
pub fn drive<E: Ends>(ends: &mut [E], rate_hz: f64, seconds: f64, drain_ns: u64, may_sleep: bool, routes: Routes) -> Drive {
    let (warm, slots) = slots_for(rate_hz, seconds, routes);
    let n = ends.len() as u64;
    let slot_ns = 1e9 / rate_hz / routes.count() as f64;
    let at = |e: u64| (((e / n) as f64 + (e % n) as f64 / n as f64) * slot_ns) as u64;
    let mut d = Drive::default();
    let t0 = now_ns() + 1_000_000;
    let (mut e, events) = (0u64, slots * n);
    let (mut t_record, mut drain_until) = (0u64, u64::MAX);
    while !stopped() {
        let now = now_ns();
        if e < events && now >= t0 + at(e) {
            let slot = e / n;
            d.send(&mut ends[(e % n) as usize], slot, routes);
            if slot >= warm {
                if e == warm * n {
                    t_record = now;
                }
                d.send_lateness.record(now - (t0 + at(e)));
            }
            e += 1;
            if e == events {
                d.send_seconds = now.saturating_sub(t_record) as f64 / 1e9;
                drain_until = now_ns() + drain_ns;
            }
        }
        for end in ends.iter_mut() {
            let stamped = end.stamped();
            d.poll_routes(end, warm, stamped);
        }
        if e == events {
            if !d.in_flight() || now_ns() > drain_until {
                break;
            }
        } else if may_sleep && !d.in_flight() && t0 + at(e) > now_ns() + 2 * SLEEP_SLACK_NS {
            sleep_until_ns(t0 + at(e) - SLEEP_SLACK_NS);
        }
    }
    d.seconds = (now_ns().saturating_sub(t_record)) as f64 / 1e9;
    d
}

/// Calls `send(i)` for `i` in `0..frames` at `period_ns` apart, sleeping
/// until shortly before each when there is time; returns the frames the
/// transport took and the seconds after the warm-up.
pub fn pace(frames: u64, period_ns: f64, warm: u64, mut send: impl FnMut(u64) -> bool) -> (u64, f64) {
    let t0 = now_ns() + 1_000_000;
    let mut sent = 0;
    let mut t_record = t0;
    for i in 0..frames {
        if stopped() {
            break;
        }
        let target = t0 + (i as f64 * period_ns) as u64;
        if target > now_ns() + 2 * SLEEP_SLACK_NS {
            sleep_until_ns(target - SLEEP_SLACK_NS);
        }
        while now_ns() < target {
            std::hint::spin_loop();
        }
        if i == warm {
            t_record = now_ns();
        }
        if send(i) {
            sent += 1;
        }
    }
    (sent, (now_ns() - t_record) as f64 / 1e9)
}
