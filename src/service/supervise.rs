//! When `netfi run` stops which process: a policy over what the runner
//! sees (which processes ended, and how; the time; a Ctrl-C), free of
//! processes and clocks, so every case can be tested.
//!
//! The processes are stopped in pipeline order — console, emulator,
//! simulator — so every report and the trace are flushed:
//!
//! - Ctrl-C / SIGTERM: stop the console; once it has ended, the emulator.
//! - A process died (ended otherwise than with exit status 0): the run
//!   ends now. The console is stopped; once it has ended, the emulator
//!   ([`PEER_SETTLE`] after the death at the earliest, so the emulator
//!   sees a dead console go); once the emulator has ended, the simulator
//!   ([`END_MARKER_GRACE`] later, for the emulator's end marker, or at
//!   once when the emulator died). Whatever does not end within
//!   [`KILL_GRACE`] of its stop is killed.
//! - The console ended normally but the emulator has not drained what it
//!   holds within the drain grace: stop it.
//! - The emulator ended normally 5 s ago and the simulator still runs (no
//!   end marker came): stop it; the console still streaming is stopped at
//!   the planned end.
//! - A console still running but not yet streaming (no `console.ready`)
//!   [`CONSOLE_READY`] after its start is stuck: it is named as a fault
//!   and the run is stopped as on Ctrl-C. (On a host whose disk is busy,
//!   a process may wait minutes in the kernel as iceoryx2 syncs its node's
//!   files to disk; without this the run would wait for the hard deadline
//!   with nothing said.)
//! - Past the hard deadline (planned + drain grace + 60 s): kill them all.
//!
//! Each stop is ordered once. Each stream's consoles and robots are one
//! role each ([`State::of_group`]): the role has died once none of them
//! runs and one failed, so one stream's dead console leaves the others
//! streaming to their end.
//!
//! A role the lab's own program plays ([`State::Lab`]: the run started no
//! process for it) is nothing to stop or wait for: the emulator ends when
//! the lab's console ends its stream (its end marker; an idle end on a
//! stream that has none), or is stopped on Ctrl-C, or at the planned end
//! when the run was given a duration; a lab's run has no hard deadline
//! otherwise.

use std::time::Duration;

/// A process as the runner sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    Running,
    /// Ended with exit status 0.
    Succeeded,
    /// Ended otherwise (exit status, signal).
    Failed,
    /// Played by the lab's own program, not a process of the run.
    Lab,
}

impl State {
    /// A process of the run that has ended.
    fn ended(self) -> bool {
        matches!(self, State::Succeeded | State::Failed)
    }

    /// Nothing of the run's left to wait for: ended, or the lab's.
    fn gone(self) -> bool {
        self != State::Running
    }

    /// The state of one role's processes together (the consoles or the
    /// robots of a run of several streams): running while any runs, then
    /// failed if any failed; the lab's when the run has none.
    pub fn of_group(states: impl IntoIterator<Item = State>) -> State {
        let (mut any, mut running, mut failed) = (false, false, false);
        for s in states {
            any = true;
            running |= s == State::Running;
            failed |= s == State::Failed;
        }
        match (any, running, failed) {
            (false, _, _) => State::Lab,
            (_, true, _) => State::Running,
            (_, false, true) => State::Failed,
            _ => State::Succeeded,
        }
    }
}

/// What the runner sees at one look.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Seen {
    /// Time since the console was started.
    pub now: Duration,
    /// A Ctrl-C / SIGTERM has reached the runner.
    pub stop_requested: bool,
    pub console: State,
    /// Every console still running has said it streams (`console.ready`).
    pub consoles_ready: bool,
    pub emulator: State,
    pub simulator: State,
}

/// One flag per role.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Roles {
    pub console: bool,
    pub emulator: bool,
    pub simulator: bool,
}

impl Roles {
    /// All three.
    pub const ALL: Roles = Roles { console: true, emulator: true, simulator: true };

    fn get_mut(&mut self, k: usize) -> &mut bool {
        match k {
            0 => &mut self.console,
            1 => &mut self.emulator,
            _ => &mut self.simulator,
        }
    }
}

/// What to do after a look. Stopping or killing a process that has ended
/// does nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Orders {
    /// Ask these to stop (SIGTERM).
    pub stop: Roles,
    /// Kill these (SIGKILL): they did not stop when asked.
    pub kill: Roles,
    /// The consoles not yet streaming are stuck: name them (once).
    pub consoles_stalled: bool,
    /// All three have ended (or are killed, then reaped): stop supervising.
    pub done: bool,
}

/// The runner's policy, with what it remembers between looks.
#[derive(Debug, Clone)]
pub struct Supervisor {
    /// When the run is to end (`None`: when its lab console ends it).
    planned: Option<Duration>,
    drain_grace: Duration,
    hard_deadline: Option<Duration>,
    interrupted: bool,
    stalled: bool,
    console_ended_at: Option<Duration>,
    emulator_ended_at: Option<Duration>,
    /// When a process was first seen dead.
    died_at: Option<Duration>,
    /// When each role (console, emulator, simulator) was asked to stop.
    stopped_at: [Option<Duration>; 3],
}

/// How long the emulator is given after its console ended to release what
/// it holds: the longest delay a scenario can realistically inject,
/// generously.
pub const DRAIN_GRACE: Duration = Duration::from_secs(30);

/// How long the simulator waits for an end marker after the emulator ended.
pub const SIMULATOR_GRACE: Duration = Duration::from_secs(5);

/// How long after its start a console may take to stream (its node and
/// ports open, the emulator subscribed): a console gives up waiting for
/// the emulator after 10 s by itself, so one still not streaming at 30 s
/// is stuck.
pub const CONSOLE_READY: Duration = Duration::from_secs(30);

/// After a death, how long the emulator is left running before it is
/// stopped: the runner reaps the dead process's iceoryx2 node at once, and
/// the emulator, which looks at its peers every few milliseconds, records
/// the peer gone.
pub const PEER_SETTLE: Duration = Duration::from_millis(300);

/// After a death, how long the simulator is given to take the emulator's
/// end marker before it is stopped.
pub const END_MARKER_GRACE: Duration = Duration::from_secs(1);

/// After a death, how long a process asked to stop has before it is
/// killed; also what a process left running by a failing runner gets.
pub const KILL_GRACE: Duration = Duration::from_secs(2);

impl Supervisor {
    /// A run whose stream is planned to last `planned_s` seconds (finite,
    /// at most a week: checked where the flags are parsed).
    pub fn new(planned_s: f64) -> Supervisor {
        Supervisor::until(Some(planned_s))
    }

    /// A run that lasts `planned_s` seconds, or, without one, until its
    /// (lab's) console ends its stream or a person stops it.
    pub fn until(planned_s: Option<f64>) -> Supervisor {
        let planned = planned_s.map(|s| Duration::from_secs_f64(s + 1.0));
        Supervisor {
            planned,
            drain_grace: DRAIN_GRACE,
            hard_deadline: planned.map(|p| p + DRAIN_GRACE + Duration::from_secs(60)),
            interrupted: false,
            stalled: false,
            console_ended_at: None,
            emulator_ended_at: None,
            died_at: None,
            stopped_at: [None; 3],
        }
    }

    /// Whether the run was interrupted (Ctrl-C / SIGTERM, or stuck consoles).
    pub fn interrupted(&self) -> bool {
        self.interrupted
    }

    /// Whether the run was stopped at a person's request (Ctrl-C,
    /// SIGTERM), not for stuck consoles: a normal end.
    pub fn stopped_on_request(&self) -> bool {
        self.interrupted && !self.stalled
    }

    /// Whether a process of the run died.
    pub fn died(&self) -> bool {
        self.died_at.is_some()
    }

    /// The orders after one look.
    pub fn look(&mut self, s: Seen) -> Orders {
        let mut o = Orders::default();
        let (c, e, m) = (s.console.gone(), s.emulator.gone(), s.simulator.gone());
        let stuck = !self.stalled && !s.consoles_ready && s.console == State::Running && s.now > CONSOLE_READY;
        if stuck {
            self.stalled = true;
            o.consoles_stalled = true;
        }
        if (s.stop_requested || stuck) && !self.interrupted {
            self.interrupted = true;
            o.stop.console = true;
        }
        if s.console.ended() && self.console_ended_at.is_none() {
            self.console_ended_at = Some(s.now);
        }
        if e && self.emulator_ended_at.is_none() {
            self.emulator_ended_at = Some(s.now);
        }
        if c && e && m {
            o.done = true;
            return o;
        }
        if self.died_at.is_none() && [s.console, s.emulator, s.simulator].contains(&State::Failed) {
            self.died_at = Some(s.now);
        }
        match self.died_at {
            Some(t) => self.wind_down(s, t, &mut o),
            None => self.go_on(s, &mut o),
        }
        if self.hard_deadline.is_some_and(|d| s.now > d) {
            o.kill = Roles::ALL;
            o.done = true;
        }
        self.once(s.now, &mut o);
        o
    }

    /// No process died: the stream goes to its end, or to the Ctrl-C.
    fn go_on(&self, s: Seen, o: &mut Orders) {
        let (c, e) = (s.console.gone(), s.emulator.gone());
        let since = |t: Option<Duration>| t.map(|t| s.now.saturating_sub(t));
        let due = self.planned.is_some_and(|p| s.now >= p);
        if !e && self.interrupted && c {
            o.stop.emulator = true;
        }
        // The lab's console ends the stream itself; a run given a duration
        // ends at it.
        if !e && s.console == State::Lab && due {
            o.stop.emulator = true;
        }
        if !e && since(self.console_ended_at).is_some_and(|d| d > self.drain_grace) {
            o.stop.emulator = true;
        }
        if e && !s.simulator.gone() && since(self.emulator_ended_at).is_some_and(|d| d > SIMULATOR_GRACE) {
            o.stop.simulator = true;
        }
        if e && !c && (self.interrupted || due) {
            o.stop.console = true;
        }
    }

    /// A process died at `died`: the others are stopped in order, and
    /// killed when they do not stop.
    fn wind_down(&self, s: Seen, died: Duration, o: &mut Orders) {
        if s.console == State::Running {
            o.stop.console = true;
        } else if s.emulator == State::Running && s.now.saturating_sub(died) >= PEER_SETTLE {
            o.stop.emulator = true;
        }
        let marker_late = self.emulator_ended_at.is_some_and(|t| s.now.saturating_sub(t) >= END_MARKER_GRACE);
        if s.simulator == State::Running && (s.emulator == State::Failed || marker_late) {
            o.stop.simulator = true;
        }
        for (k, state) in [s.console, s.emulator, s.simulator].into_iter().enumerate() {
            if state == State::Running && self.stopped_at[k].is_some_and(|t| s.now.saturating_sub(t) >= KILL_GRACE) {
                *o.kill.get_mut(k) = true;
            }
        }
    }

    /// Keeps only the first order to stop each role, remembering when.
    fn once(&mut self, now: Duration, o: &mut Orders) {
        for k in 0..3 {
            let stop = o.stop.get_mut(k);
            if *stop && self.stopped_at[k].is_some() {
                *stop = false;
            } else if *stop {
                self.stopped_at[k] = Some(now);
            }
        }
    }
}

#[cfg(test)]
mod tests;
