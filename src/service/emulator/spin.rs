//! The emulator's one loop, over N ≥ 1 lanes (streams), pinned to one
//! core. Each round turns every lane once, lane 0 first ([`round`]); with
//! one lane, that lane's turn may prepare a release ahead of its time
//! (the lane's `release_spin_ns`); with several, after each lane's turn, if
//! any lane's earliest release is due, every lane's due frames go out at
//! once, so a release waits behind at most one lane's turn, not a round.
//! Everything else happens every 4096 lane turns (4096 rounds of one
//! lane, 64 rounds of 64: a stop is seen as soon with many lanes as with
//! one): live control (on lane 0), a look for a stop and for dead peers,
//! who sent bad input, each lane's end, and every 16th time the peers
//! connected. Nothing in a round
//! allocates or locks: the lanes are a slice fixed before the loop starts.

use crate::clock::now_ns;
use crate::service::control::ControlPort;
use crate::service::emulator::{lane::Lane, path::ForwardChannel};
use crate::service::schema::Ended;
use crate::transport::{IpcNode, Role};

/// Lane turns between two looks off the hot path: every 4096 rounds with
/// one lane, every ⌈4096 / N⌉ rounds with N ([`look_every_rounds`]), so a
/// stop, a dead peer or a lane's end is seen as soon whatever the lanes (a
/// look asks every lane, so its share of the loop stays the same).
pub const LOOK_EVERY_TURNS: u64 = 4096;

/// Rounds between two looks with `lanes` lanes: [`LOOK_EVERY_TURNS`] lane
/// turns, at least one round.
pub fn look_every_rounds(lanes: usize) -> u64 {
    (LOOK_EVERY_TURNS / lanes.max(1) as u64).max(1)
}

/// The peers connected are noted every this many looks.
const WATCH_PEERS_EVERY_LOOKS: u64 = 16;

/// What the loop's look off the hot path (every [`LOOK_EVERY_TURNS`]
/// lane turns) found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Look {
    /// Nothing new: go on.
    Go,
    /// SIGINT/SIGTERM: stop now.
    Stop,
}

/// How the loop ended.
#[derive(Debug, Clone)]
pub struct LoopEnd {
    /// `EndMarker`, `Signal` or `PeerDied`.
    pub ended_by: Ended,
    /// Rounds of the loop.
    pub rounds: u64,
    pub t_start: u64,
    pub t_end: u64,
}

impl LoopEnd {
    /// How a lane ended within a loop that ended so: a stop, its robot's
    /// death, or its end marker.
    pub fn lane_ended_by(&self, robot_died: bool) -> Ended {
        match (self.ended_by, robot_died) {
            (Ended::Signal, _) => Ended::Signal,
            (_, true) => Ended::PeerDied,
            _ => Ended::EndMarker,
        }
    }

    /// The loop's time, ns.
    pub fn duration_ns(&self) -> u64 {
        self.t_end - self.t_start
    }
}

/// Releases every lane's due frames; the earliest release left.
#[inline]
fn release_all<F: ForwardChannel>(lanes: &mut [Lane<F>]) -> u64 {
    let now = now_ns();
    let mut next = u64::MAX;
    for l in lanes.iter_mut() {
        l.forward.release_due(now);
        next = next.min(l.next_release_ns());
    }
    next
}

/// One round of the loop: each lane's turn, lane 0 first. With several
/// lanes, after each turn, if any lane's earliest release is due (a frame
/// just taken with no delay, or another lane's), every lane's due frames go
/// out now, not a round later; `due` is the earliest release of any lane as
/// last seen (`u64::MAX` at first), returned as the round leaves it.
#[inline]
pub fn round<F: ForwardChannel>(lanes: &mut [Lane<F>], mut due: u64) -> u64 {
    if let [lane] = lanes {
        lane.turn();
        return due;
    }
    for k in 0..lanes.len() {
        let l = &mut lanes[k];
        l.turn();
        due = due.min(l.next_release_ns());
        // The clock read that follows the turn ends it: its busy time is
        // its own, not the other lanes' turns after it.
        let now = now_ns();
        l.end_turn(now);
        if due <= now {
            due = release_all(lanes);
        }
    }
    due
}

/// Turns the lanes until each has ended and drained, or a stop is
/// requested. Every [`LOOK_EVERY_TURNS`] lane turns (4096 rounds of one
/// lane, 64 of 64): live control, the `look` (a stop; each lane whose
/// robot died, marked in the slice it is given), who sent bad input, the
/// lanes' end; every 16th time, the peers connected.
pub fn spin<F: ForwardChannel>(
    lanes: &mut [Lane<F>],
    mut look: impl FnMut(&mut [bool]) -> Look,
    mut control: Option<&mut ControlPort>,
) -> LoopEnd {
    let t_start = now_ns();
    lanes.iter_mut().for_each(|l| l.watch_peers(None));
    let mut died = vec![false; lanes.len()];
    let (mut rounds, mut due) = (0u64, u64::MAX);
    let every = look_every_rounds(lanes.len());
    let (mut until_look, mut looks) = (every, 0u64);
    let ended_by = loop {
        due = round(lanes, due);
        rounds = rounds.wrapping_add(1);
        until_look -= 1;
        if until_look != 0 {
            continue;
        }
        until_look = every;
        looks += 1;
        if let Some(c) = control.as_deref_mut() {
            c.poll(&mut lanes[0].forward.link);
        }
        if look(&mut died) == Look::Stop {
            break Ended::Signal;
        }
        let now = now_ns();
        for (l, d) in lanes.iter_mut().zip(died.iter_mut()) {
            if std::mem::take(d) {
                l.robot_died(now);
            }
            l.look_at_bad_input();
        }
        if looks % WATCH_PEERS_EVERY_LOOKS == 0 {
            let t_s = (now - t_start) as f64 / 1e9;
            lanes.iter_mut().for_each(|l| l.watch_peers(Some(t_s)));
        }
        // Every lane is asked, so each sends its end markers once drained.
        if lanes.iter_mut().fold(true, |all, l| l.finished(now) && all) {
            break if lanes.iter().any(|l| l.robot_died) { Ended::PeerDied } else { Ended::EndMarker };
        }
    };
    LoopEnd { ended_by, rounds, t_start, t_end: now_ns() }
}

/// How often each lane's run is searched for dead peers when the emulator
/// stands alone.
const REAP_EVERY_NS: u64 = 200_000_000;

/// Each lane's dead peers, found when the emulator stands alone (under
/// `netfi run` the runner reaps, off the loop's core; two reapers may wait
/// on each other). One lane's run is reaped per look, in turn, so a look
/// costs one lane's scan and each lane is reaped every 200 ms.
pub struct Reaper<'a> {
    nodes: Vec<Option<&'a IpcNode>>,
    next: usize,
    next_ns: u64,
    /// The dead peers found, per lane.
    pub dead: Vec<Vec<String>>,
}

impl<'a> Reaper<'a> {
    /// A reaper of the lanes' `nodes`; one that never reaps unless `alone`.
    pub fn new(nodes: &[Option<&'a IpcNode>], alone: bool) -> Self {
        let dead = vec![Vec::new(); nodes.len()];
        let nodes = if alone { nodes.to_vec() } else { Vec::new() };
        Reaper { nodes, next: 0, next_ns: now_ns(), dead }
    }

    /// Reaps the next lane's run if its time has come; marks in
    /// `robot_died` the lane whose robot was found dead. A dead console is
    /// reported, and its stream goes on (a restarted console may take
    /// over).
    pub fn look(&mut self, robot_died: &mut [bool]) {
        let now = now_ns();
        if self.nodes.is_empty() || now < self.next_ns {
            return;
        }
        let k = self.next;
        self.next = (k + 1) % self.nodes.len();
        self.next_ns = now + REAP_EVERY_NS / self.nodes.len() as u64;
        let Some(Ok(r)) = self.nodes[k].map(IpcNode::reap_dead_peers) else { return };
        for p in r.dead() {
            eprintln!("emulator: stream {k}: a peer died: {p}");
            self.dead[k].push(p.to_string());
            robot_died[k] |= p.role == Some(Role::Simulator);
        }
    }
}
