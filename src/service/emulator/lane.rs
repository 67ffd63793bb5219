//! A lane: one console → robot stream of the emulator, its forward path
//! and its reverse paths (feedback, video, the UDP return), in one fixed
//! list fixed before the loop starts. The loop turns each lane
//! ([`Lane::turn`]); everything a lane does off the hot path (its end, its
//! peers, who sent bad input) is asked every 4096 turns.

use crate::clock::now_ns;
use crate::service::emulator::busy::BusyClock;
use crate::service::emulator::path::{Ending, ForwardChannel, Path, Reverse, REVERSE_EVERY};
use crate::service::schema::{LoopBusy, PeerEvent};

/// How close a release must be for an idle loop of one stream to prepare
/// it now and wait for its moment on the clock alone rather than poll its
/// ports once more. A release is then stamped within a clock read of its
/// time, after the queue's pop and the copy into the publisher's sample,
/// instead of anywhere in the turn that straddles it. The window is a few
/// idle turns (150–350 ns each here, longer when a frame comes in), so that
/// the loop sees every release inside it at least once. The loop only
/// prepares when its last look at the ingress found nothing, so a busy
/// stream never waits; an idle one may take in a frame up to this much
/// later.
pub const RELEASE_SPIN_NS: u64 = 1_000;


/// One stream of the emulator.
pub struct Lane<F: ForwardChannel> {
    /// The console → robot path.
    pub forward: Path<F>,
    /// The reverse paths, polled once per turn in this order.
    pub reverse: Vec<Box<dyn Reverse>>,
    /// How near a release an idle turn waits for it on the clock
    /// ([`RELEASE_SPIN_NS`]; 0: never, as when one loop serves several
    /// streams, where a wait would delay the others).
    pub release_spin_ns: u64,
    /// The last turn found nothing waiting at the ingress.
    idle: bool,
    /// The loop's busy turns and their time.
    pub busy: BusyClock,
    /// Consoles and robots connected, as last seen.
    peers: (Option<usize>, Option<usize>),
    /// Changes in them.
    pub peer_events: Vec<PeerEvent>,
    /// Its robot was found dead.
    pub robot_died: bool,
    /// Bad input seen at the last look.
    bad_seen: u64,
    /// The reverse paths took or released something at their last poll.
    reverse_busy: bool,
    /// Turns since the reverse paths were last polled.
    reverse_wait: u32,
    /// Quiet reverse paths are polled every this many turns: the least
    /// any of them asks ([`Reverse::quiet_poll_every`]), [`REVERSE_EVERY`]
    /// at most.
    reverse_every: u32,
}

impl<F: ForwardChannel> Lane<F> {
    /// The stream of `forward` and its `reverse` paths.
    pub fn new(forward: Path<F>, reverse: Vec<Box<dyn Reverse>>) -> Self {
        let reverse_every = reverse.iter().map(|r| r.quiet_poll_every()).fold(REVERSE_EVERY, u32::min).max(1);
        Lane {
            forward,
            reverse,
            release_spin_ns: RELEASE_SPIN_NS,
            idle: false,
            busy: BusyClock::default(),
            peers: (None, None),
            peer_events: Vec::new(),
            robot_died: false,
            bad_seen: 0,
            reverse_busy: false,
            reverse_wait: 0,
            reverse_every,
        }
    }

    /// One turn: every forward release that is due, oldest first (or, when
    /// idle with a release within `release_spin_ns`, that release prepared
    /// and sent on its time); each reverse path's poll (every
    /// [`REVERSE_EVERY`]th turn while they are quiet, unless one asks for
    /// more); every frame waiting
    /// at the ingress, up to the forward channel's batch.
    #[inline]
    pub fn turn(&mut self) {
        let now = now_ns();
        self.busy.begin(now, self.work());
        match self.due_until(now) {
            t if t > now => {
                self.busy.waited(t - now);
                self.forward.release_ahead(t)
            }
            _ => self.forward.release_due(now),
        }
        self.reverse_wait += 1;
        if self.reverse_busy || self.reverse_wait >= self.reverse_every {
            self.reverse_wait = 0;
            let mut busy = false;
            for r in self.reverse.iter_mut() {
                busy |= r.poll();
            }
            self.reverse_busy = busy;
        }
        self.idle = self.forward.take(now_ns);
    }

    /// Frames taken and released so far: a turn that moved it was busy.
    #[inline]
    fn work(&self) -> u64 {
        self.forward.link.next_ingress_index().wrapping_add(self.forward.link.released())
    }

    /// The time up to which releases are due in this turn: `now`, or, when
    /// the loop is idle and its next release falls within
    /// `release_spin_ns`, that release's time. Nothing is taken in
    /// meanwhile, so no frame can come due earlier.
    #[inline]
    fn due_until(&self, now: u64) -> u64 {
        match self.forward.link.next_release_ns() {
            Some(t) if self.idle && t > now && t - now <= self.release_spin_ns => t,
            _ => now,
        }
    }

    /// The earliest forward release, `u64::MAX` when none is held.
    #[inline]
    pub fn next_release_ns(&self) -> u64 {
        self.forward.link.next_release_ns().unwrap_or(u64::MAX)
    }

    /// Ends the loop's current turn at `now` (read after it by a loop that
    /// does other work between turns, as one serving several streams does);
    /// else the next turn's start ends it.
    #[inline]
    pub fn end_turn(&mut self, now: u64) {
        self.busy.end(now, self.work());
    }

    /// The loop's busy turns so far and the capacity they imply.
    pub fn loop_busy(&self) -> LoopBusy {
        LoopBusy::of(&self.busy, self.forward.link.next_ingress_index(), self.work())
    }

    /// Off the hot path, at `now`: whether the stream may end. Once the
    /// forward stream has drained, its robot is sent the end marker (once),
    /// and each reverse path ends by its own rule (each is asked, so each
    /// sends its end marker in time). A lane whose robot died ends once no
    /// reverse path is left to tell the console.
    pub fn finished(&mut self, now: u64) -> bool {
        let mut all = self.forward.finished(now, None);
        let forward_end = self.forward.ended_at();
        for r in self.reverse.iter_mut() {
            all &= r.finished(now, forward_end);
        }
        all || (self.robot_died && !self.reverse.iter().any(|r| r.ending() != Ending::WithForward))
    }

    /// Its robot is gone: the console is told through the reverse paths
    /// (their end markers come early, so the console ends its stream) and
    /// the stream drains as usual, every frame accounted for.
    pub fn robot_died(&mut self, now: u64) {
        self.robot_died = true;
        self.reverse.iter_mut().for_each(|r| r.end(now));
    }

    /// After the loop: closes every path of the lane ([`Path::close`]),
    /// so that their traces are written while the other lanes close.
    pub fn close(&mut self) {
        self.forward.close();
        self.reverse.iter_mut().for_each(|r| r.close());
    }

    /// Off the hot path: names who sent the bad input seen since the last
    /// look.
    pub fn look_at_bad_input(&mut self) {
        self.forward.chan.name_bad_senders(&mut self.bad_seen);
    }

    /// Notes a change in the consoles or robots connected, `t_s` seconds
    /// into the loop (at the first look, only what is there).
    pub fn watch_peers(&mut self, t_s: Option<f64>) {
        let now = (self.forward.chan.senders(), self.forward.chan.receivers());
        if let Some(t_s) = t_s {
            if now.0 != self.peers.0 {
                self.peer_events.push(PeerEvent { t_s, peer: "console".into(), connected: now.0.unwrap_or(0) });
            }
            if now.1 != self.peers.1 {
                self.peer_events.push(PeerEvent { t_s, peer: "simulator".into(), connected: now.1.unwrap_or(0) });
            }
        }
        self.peers = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sample::FrameSample;
    use crate::scenario::Scenario;
    use crate::service::emulator::forward::Forward;
    use crate::service::emulator::path::{Channel, Take};
    use crate::service::link::{Arrival, Carried, Link};
    use crate::service::schema::{Account, PathReport};
    use crate::transport::{MemoryPort, PortError};
    use serde::{Deserialize, Serialize};
    use std::collections::VecDeque;

    // A channel of the tests' own, in one place: items from a queue in
    // memory to a vector, ending on a marker or after a short grace.

    #[derive(Debug, Clone, Copy, Default, PartialEq)]
    struct Note {
        n: u64,
        ingress_ns: u64,
    }

    impl Carried for Note {
        fn ingress_ns(&self) -> u64 {
            self.ingress_ns
        }
    }

    enum Msg {
        Note(u64),
        End(u64),
    }

    #[derive(Default)]
    struct Notes {
        inbox: VecDeque<Msg>,
        outbox: Vec<Note>,
        ended: Option<u64>,
    }

    #[derive(Debug, Serialize, Deserialize)]
    struct NotesExtra {
        out: usize,
    }

    impl Channel for Notes {
        type Item = Note;
        type Extra = NotesExtra;
        const NAME: &'static str = "notes";
        const TRACE_FILE: &'static str = "trace_notes.csv";
        const ENDING: Ending = Ending::AfterForward { grace_ns: 20_000_000 };

        fn take(&mut self, _next: u64, clock: &mut impl FnMut() -> u64) -> Take<Note> {
            match self.inbox.pop_front() {
                Some(Msg::Note(n)) => {
                    let t = clock();
                    Take::Item(Note { n, ingress_ns: t }, None, Arrival { sequence: None, console_index: n, send_ns: t })
                }
                Some(Msg::End(sent)) => Take::End(sent),
                None => Take::Nothing,
            }
        }

        fn release(&mut self, item: &Note, _scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
            self.outbox.push(*item);
            Ok(stamp())
        }

        fn send_end(&mut self, released: u64) {
            self.ended = Some(released);
        }

        fn finish(&mut self, account: &Account, sent: Option<u64>) -> (NotesExtra, bool) {
            (NotesExtra { out: self.outbox.len() }, self.outbox.len() as u64 == account.delivered && sent.is_none_or(|s| s == account.entered))
        }
    }

    fn scenario(text: &str, seed: u64) -> Scenario {
        Scenario::new(&crate::scenario::parse_str(text, "t.toml", "t").unwrap(), seed).unwrap()
    }

    /// A lane of a Normal forward stream of `frames` frames (their end
    /// marker last) between ports in memory.
    fn lane(frames: u64, dir: &std::path::Path) -> Lane<Forward<MemoryPort, MemoryPort>> {
        let mut source = MemoryPort::with_capacity(frames as usize + 1);
        let mut s = FrameSample::ZERO;
        crate::frame::ItpFrame::default().write_to_sample(&mut s);
        for i in 0..frames {
            s.console_index = i;
            source.queue.push_back(s);
        }
        source.queue.push_back(FrameSample::end_marker(frames));
        let chan = Forward::new(source, MemoryPort::with_capacity(frames as usize + 1), false, false);
        Lane::new(Path::new(chan, scenario("", 1), 1, 64, frames, dir, false).unwrap(), Vec::new())
    }

    /// Turns `lane` until it has finished, asking as the loop does; the
    /// turns it took.
    fn run(lane: &mut Lane<Forward<MemoryPort, MemoryPort>>) -> u64 {
        let mut turns = 0u64;
        loop {
            lane.turn();
            turns += 1;
            if turns % 64 == 0 && lane.finished(now_ns()) {
                return turns;
            }
            assert!(turns < 50_000_000, "the lane never finished");
        }
    }

    #[test]
    fn a_channel_is_one_impl_and_one_line_of_wiring_and_its_path_accounts_for_every_item() {
        let dir = crate::scratch::dir("notes");
        let mut l = lane(10, &dir);
        let mut notes = Notes::default();
        notes.inbox.extend((0..1000).map(Msg::Note));
        notes.inbox.push_back(Msg::End(1000));
        // The wiring: one line.
        l.reverse.push(Box::new(Path::new(notes, scenario("[[stage]]\nmodel = \"bernoulli\"\np = 0.3\n", 9), 9, 64, 1000, &dir, false).unwrap()));
        run(&mut l);
        assert_eq!(l.forward.chan.sink.queue.back().map(|s| (s.is_end(), s.console_index)), Some((true, 10)), "the robot got the end marker");
        let path = l.reverse[0].as_any_mut().downcast_mut::<Path<Notes>>().unwrap();
        let (out, ended) = (path.chan.outbox.len() as u64, path.chan.ended);
        let r: PathReport<NotesExtra> = serde_json::from_value(l.reverse.pop().unwrap().finish(1_000_000).unwrap()).unwrap();
        let a = &r.account;
        assert!(r.balanced, "{r:?}");
        assert_eq!((a.entered, a.delivered, a.held_at_end, r.extra.out as u64), (1000, out, 0, out));
        assert_eq!(a.dropped_total() + a.delivered, 1000);
        assert_eq!(ended, Some(out), "the end marker carries what was released");
        // Bernoulli 0.3 over 1 000: 700 ± 4.5σ (σ = 14.5).
        assert!((635..=765).contains(&out), "{out} of 1000 delivered through 30% loss");
        let rows = std::fs::read_to_string(dir.join("trace_notes.csv")).unwrap().lines().count() - 1;
        assert_eq!(rows, 1000, "one trace row per item");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_reverse_path_without_its_marker_ends_after_the_grace_and_a_dead_robot_ends_it_at_once() {
        let dir = crate::scratch::dir("grace");
        let mut l = lane(3, &dir);
        let mut notes = Notes::default();
        notes.inbox.extend((0..5).map(Msg::Note));
        l.reverse.push(Box::new(Path::new(notes, scenario("", 2), 2, 16, 16, &dir, false).unwrap()));
        let t0 = now_ns();
        run(&mut l);
        assert!(now_ns() - t0 >= 20_000_000, "ended before the grace without the sender's marker");
        let r: PathReport<NotesExtra> = serde_json::from_value(l.reverse.pop().unwrap().finish(1).unwrap()).unwrap();
        assert_eq!((r.account.entered, r.account.delivered), (5, 5));
        assert!(r.balanced);
        // A robot found dead: its reverse paths end now, and so does the lane
        // once the forward stream has drained.
        let mut l = lane(3, &dir);
        l.reverse.push(Box::new(Path::new(Notes::default(), scenario("", 2), 2, 16, 16, &dir, false).unwrap()));
        l.robot_died(now_ns());
        let t0 = now_ns();
        run(&mut l);
        assert!(now_ns() - t0 < 20_000_000, "a dead robot's path waited for its grace");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A Normal lane: every frame is due the moment it is taken.
    fn normal_loop() -> Lane<Forward<MemoryPort, MemoryPort>> {
        let chan = Forward::new(MemoryPort::with_capacity(8), MemoryPort::with_capacity(8), false, true);
        let link = Link::new(scenario("", 1), 16, 16).unwrap();
        Lane::new(Path::of(link, chan, 1, std::env::temp_dir().join("netfi-lane-unused.csv"), false), Vec::new())
    }

    fn frames(port: &mut MemoryPort, n: u64) {
        let mut s = FrameSample::ZERO;
        crate::frame::ItpFrame::default().write_to_sample(&mut s);
        for i in 0..n {
            s.console_index = i;
            port.queue.push_back(s);
        }
    }

    /// One turn; whether it took or released a frame, seen from the ports.
    fn turn(fwd: &mut Lane<Forward<MemoryPort, MemoryPort>>) -> bool {
        let ports = |l: &Lane<Forward<MemoryPort, MemoryPort>>| (l.forward.chan.source.queue.len(), l.forward.chan.sink.queue.len());
        let before = ports(fwd);
        fwd.turn();
        before != ports(fwd)
    }

    #[test]
    fn busy_turns_are_the_turns_that_took_or_released_a_frame() {
        let mut fwd = normal_loop();
        let t0 = now_ns();
        for _ in 0..10 {
            assert!(!turn(&mut fwd));
        }
        assert_eq!((fwd.busy.turns, fwd.busy.busy_turns, fwd.busy.busy_ns), (10, 0, 0));
        frames(&mut fwd.forward.chan.source, 3);
        let mut busy = 0;
        while fwd.forward.chan.sink.queue.len() < 3 {
            busy += u64::from(turn(&mut fwd));
            assert!(fwd.busy.turns < 1000, "three frames never came through");
        }
        // The last busy turn is closed by the next one, which is idle.
        assert!(!turn(&mut fwd));
        let closed = fwd.busy;
        assert!(busy >= 2, "a frame is taken in one turn and released in a later one");
        assert_eq!(closed.busy_turns, busy);
        assert!(closed.busy_ns > 0 && closed.busy_ns <= now_ns() - t0);
        for _ in 0..100 {
            assert!(!turn(&mut fwd));
        }
        fwd.end_turn(now_ns());
        assert_eq!((fwd.busy.turns, fwd.busy.busy_turns, fwd.busy.busy_ns), (closed.turns + 100, closed.busy_turns, closed.busy_ns));
        let b = fwd.loop_busy();
        assert_eq!((b.turns, b.busy_turns, b.busy_ns, b.frames), (closed.turns + 100, busy, closed.busy_ns, 3));
        let per_frame = closed.busy_ns as f64 / 3.0;
        assert_eq!(b.busy_ns_per_frame, Some(per_frame));
        assert_eq!(b.capacity_frames_per_s, Some(1e9 / per_frame));
    }

    #[test]
    fn a_turn_ended_by_the_loop_is_counted_once() {
        let mut fwd = normal_loop();
        frames(&mut fwd.forward.chan.source, 1);
        // Taken in one turn, released in the next; each ended by the loop
        // (as one serving several streams does), then the next turn begins.
        let mut busy = 0;
        for _ in 0..4 {
            busy += u64::from(turn(&mut fwd));
            fwd.end_turn(now_ns());
            let ns = fwd.busy.busy_ns;
            fwd.end_turn(now_ns());
            assert_eq!(fwd.busy.busy_ns, ns, "a turn ended twice");
        }
        assert_eq!(fwd.forward.chan.sink.queue.len(), 1);
        assert_eq!((fwd.busy.turns, fwd.busy.busy_turns), (4, busy));
        assert_eq!(busy, 2);
        assert_eq!(fwd.loop_busy().frames, 1);
    }


    /// A reverse channel that counts the polls of its port, polled while
    /// quiet every `EVERY` turns, and delivers what its inbox holds.
    #[derive(Default)]
    struct Asked<const EVERY: u32> {
        asked: u64,
        inbox: VecDeque<u64>,
        outbox: Vec<Note>,
    }

    impl<const EVERY: u32> Channel for Asked<EVERY> {
        type Item = Note;
        type Extra = NotesExtra;
        const NAME: &'static str = "asked";
        const TRACE_FILE: &'static str = "trace_asked.csv";
        const ENDING: Ending = Ending::WithForward;
        const QUIET_POLL_EVERY: u32 = EVERY;

        fn take(&mut self, _next: u64, clock: &mut impl FnMut() -> u64) -> Take<Note> {
            self.asked += 1;
            match self.inbox.pop_front() {
                Some(n) => {
                    let t = clock();
                    Take::Item(Note { n, ingress_ns: t }, None, Arrival { sequence: None, console_index: n, send_ns: t })
                }
                None => Take::Nothing,
            }
        }

        fn release(&mut self, item: &Note, _scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
            self.outbox.push(*item);
            Ok(stamp())
        }

        fn send_end(&mut self, _released: u64) {}

        fn finish(&mut self, _account: &Account, _sent: Option<u64>) -> (NotesExtra, bool) {
            (NotesExtra { out: self.outbox.len() }, true)
        }
    }

    fn asked<const EVERY: u32>(l: &mut Lane<Forward<MemoryPort, MemoryPort>>) -> &mut Path<Asked<EVERY>> {
        l.reverse[0].as_any_mut().downcast_mut::<Path<Asked<EVERY>>>().unwrap()
    }

    /// Quiet reverse paths are polled every 4th turn, unless one asks for
    /// every turn (the UDP return: its quiet poll costs what the forward's
    /// does); an item with no delay goes out in the poll that took it.
    #[test]
    fn a_reverse_path_that_asks_is_polled_every_turn_and_releases_what_it_took_at_once() {
        let link = || Link::new(scenario("", 1), 16, 16).unwrap();
        let unused = || std::env::temp_dir().join("netfi-lane-unused.csv");
        let quiet = Path::of(link(), Asked::<4>::default(), 1, unused(), false);
        let mut l = Lane::new(normal_loop().forward, vec![Box::new(quiet)]);
        (0..100).for_each(|_| l.turn());
        assert_eq!(asked::<4>(&mut l).chan.asked, 25);
        let eager = Path::of(link(), Asked::<1>::default(), 1, unused(), false);
        let mut l = Lane::new(normal_loop().forward, vec![Box::new(eager)]);
        (0..100).for_each(|_| l.turn());
        assert_eq!(asked::<1>(&mut l).chan.asked, 100);
        asked::<1>(&mut l).chan.inbox.push_back(7);
        l.turn();
        let p = asked::<1>(&mut l);
        assert_eq!(p.chan.outbox.iter().map(|n| n.n).collect::<Vec<_>>(), [7], "taken and released in one poll");
        assert_eq!((p.link.released(), p.link.held()), (1, 0));
    }

    /// The loop looks (for a stop, dead peers, each lane's end) every 4096
    /// lane turns whatever the lanes: with 64 lanes every 64 rounds, not
    /// every 4096 (a stop was then seen 64 times later). A stop asked for
    /// at a look ends the loop at that very round.
    #[test]
    fn the_loop_looks_every_4096_lane_turns_whatever_the_lanes() {
        use crate::service::emulator::spin::{self, look_every_rounds, Look, LOOK_EVERY_TURNS};
        let dir = crate::scratch::dir("looks");
        for n in [1usize, 3, 64] {
            // Lanes whose console has sent nothing yet: they never end.
            let mut lanes: Vec<_> = (0..n)
                .map(|k| {
                    let d = dir.join(format!("{n}-{k}"));
                    std::fs::create_dir_all(&d).unwrap();
                    let chan = Forward::new(MemoryPort::with_capacity(1), MemoryPort::with_capacity(1), false, false);
                    Lane::new(Path::new(chan, scenario("", 1), 1, 64, 0, &d, false).unwrap(), Vec::new())
                })
                .collect();
            let mut looks = 0u64;
            let end = spin::spin(
                &mut lanes,
                |_| {
                    looks += 1;
                    if looks == 10 { Look::Stop } else { Look::Go }
                },
                None,
            );
            assert_eq!(end.ended_by, crate::service::schema::Ended::Signal, "{n} lanes");
            assert_eq!(end.rounds, 10 * look_every_rounds(n), "{n} lanes: the stop was not taken at the look that saw it");
            assert!(look_every_rounds(n) * n as u64 <= LOOK_EVERY_TURNS, "{n} lanes: more than {LOOK_EVERY_TURNS} turns between looks");
            assert!(look_every_rounds(n) * (n as u64 + 1) > LOOK_EVERY_TURNS, "{n} lanes: looks more often than needed");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
