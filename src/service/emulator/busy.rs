//! The loop's busy time: which turns took or released a frame, and how
//! long they took, counted from the clock read each turn makes anyway
//! ([`BusyClock`]); and the figures it gives ([`LoopBusy`]).

use crate::service::schema::LoopBusy;

/// A busy turn longer than this is taken to have lost its core
/// ([`LoopBusy::long_turns`]): more than a full batch (64 frames
/// at 3 µs each) takes, less than a scheduler's time slice (milliseconds)
/// or a descheduled vCPU.
pub const LONG_TURN_NS: u64 = 200_000;

impl LoopBusy {
    /// The figures of `clock` over `frames` frames taken, and `work`
    /// frames taken and released in all.
    pub fn of(clock: &BusyClock, frames: u64, work: u64) -> LoopBusy {
        let short_work = work.saturating_sub(clock.long_work);
        let short = (frames > 0 && short_work > 0)
            .then(|| (clock.busy_ns - clock.long_ns) as f64 / short_work as f64 * work as f64 / frames as f64);
        LoopBusy {
            turns: clock.turns,
            busy_turns: clock.busy_turns,
            busy_ns: clock.busy_ns,
            frames,
            long_turns: clock.long_turns,
            long_ns: clock.long_ns,
            ..LoopBusy::default()
        }
        .with_rates(short)
    }

    /// The figures derived from the counts: time a frame and the capacity
    /// it implies, and `short` (the time a frame without the long turns)
    /// with its own.
    fn with_rates(mut self, short: Option<f64>) -> LoopBusy {
        let rate = |ns: Option<f64>| ns.filter(|&n| n > 0.0).map(|n| 1e9 / n);
        self.busy_ns_per_frame = (self.frames > 0).then(|| self.busy_ns as f64 / self.frames as f64);
        self.capacity_frames_per_s = rate(self.busy_ns_per_frame);
        self.short_turns_ns_per_frame = short;
        self.short_turns_capacity_frames_per_s = rate(short);
        self
    }
}

impl LoopBusy {
    /// The figures of one loop that served several streams, from each
    /// stream's: a stream's busy turns are its own turns of the loop
    /// (`streams::round` closes each at the next clock read), so their
    /// counts and times add up. The figure without the long turns is the
    /// streams' own, weighted by their frames (each stream's frames in
    /// long turns are not kept apart in its figures). `None` without
    /// streams.
    pub fn total<'a>(parts: impl IntoIterator<Item = &'a LoopBusy>) -> Option<LoopBusy> {
        let mut t: Option<LoopBusy> = None;
        let mut short_weighted = (0.0f64, 0u64);
        for p in parts {
            let s = t.get_or_insert_with(LoopBusy::default);
            s.turns += p.turns;
            s.busy_turns += p.busy_turns;
            s.busy_ns += p.busy_ns;
            s.frames += p.frames;
            s.long_turns += p.long_turns;
            s.long_ns += p.long_ns;
            if let Some(short) = p.short_turns_ns_per_frame {
                short_weighted.0 += short * p.frames as f64;
                short_weighted.1 += p.frames;
            }
        }
        Some(t?.with_rates((short_weighted.1 > 0).then(|| short_weighted.0 / short_weighted.1 as f64)))
    }
}

/// Counts the loop's busy turns and their time ([`LoopBusy`]) with the
/// clock read each turn makes anyway: a turn's start closes the turn before
/// it, whose work is told by a count of frames taken and released that the
/// link keeps anyway. Per turn: one compare, and an add when it was busy; no
/// clock read, allocation or lock of its own.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusyClock {
    /// Turns begun.
    pub turns: u64,
    /// Turns closed that took or released a frame.
    pub busy_turns: u64,
    /// Their time, ns.
    pub busy_ns: u64,
    /// Of those, the turns longer than [`LONG_TURN_NS`], their time, and
    /// the frames they took and released.
    pub long_turns: u64,
    pub long_ns: u64,
    long_work: u64,
    /// The open turn's start (0: none open) and the work count then.
    start_ns: u64,
    work: u64,
}

impl BusyClock {
    /// A turn begins at `now` with `work` frames taken and released so
    /// far: the turn before it, if still open, ends here.
    #[inline]
    pub fn begin(&mut self, now: u64, work: u64) {
        self.end(now, work);
        self.start_ns = now;
        self.work = work;
        self.turns += 1;
    }

    /// The open turn, if any, ends at `now` with `work` frames taken and
    /// released so far; it was busy if that count moved.
    #[inline]
    pub fn end(&mut self, now: u64, work: u64) {
        if self.start_ns != 0 && work != self.work {
            let ns = now.saturating_sub(self.start_ns);
            self.busy_turns += 1;
            self.busy_ns += ns;
            if ns > LONG_TURN_NS {
                self.long_turns += 1;
                self.long_ns += ns;
                self.long_work += work.wrapping_sub(self.work);
            }
        }
        self.start_ns = 0;
    }

    /// The open turn waits `ns` for a release prepared ahead: that wait is
    /// not the frames' cost.
    #[inline]
    pub fn waited(&mut self, ns: u64) {
        self.start_ns += ns;
    }
}


#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_streams_busy_figures_add_up_in_the_total() {
        let clock = |busy_ns, long_ns, long_work| BusyClock { turns: 100, busy_turns: 40, busy_ns, long_turns: u64::from(long_ns > 0), long_ns, long_work, ..BusyClock::default() };
        // 1 000 frames in 2 ms, none in long turns; 3 000 in 9 ms, 1 ms of it
        // one long turn that took 500 of 6 000 takes and releases.
        let a = LoopBusy::of(&clock(2_000_000, 0, 0), 1_000, 2_000);
        let b = LoopBusy::of(&clock(9_000_000, 1_000_000, 500), 3_000, 6_000);
        let t = LoopBusy::total([&a, &b]).unwrap();
        assert_eq!((t.turns, t.busy_turns, t.busy_ns, t.frames, t.long_turns, t.long_ns), (200, 80, 11_000_000, 4_000, 1, 1_000_000));
        assert_eq!(t.busy_ns_per_frame, Some(2_750.0));
        assert_eq!(t.capacity_frames_per_s, Some(1e9 / 2_750.0));
        // a: 2 000 ns a frame; b: 8 ms over 5 500 short works, scaled by 2:
        // 2 909.09 ns; weighted by frames (1 000, 3 000).
        let b_short = 8_000_000.0 / 5_500.0 * 2.0;
        assert!((b.short_turns_ns_per_frame.unwrap() - b_short).abs() < 1e-9);
        let want = (2_000.0 * 1_000.0 + b_short * 3_000.0) / 4_000.0;
        assert!((t.short_turns_ns_per_frame.unwrap() - want).abs() < 1e-9, "{t:?}");
        assert_eq!(LoopBusy::total([]), None);
    }
}
