//! When `netfi run` stops which process: a policy over what the runner
//! sees (which processes ended, and how; the time; a Ctrl-C), free of
//! processes and clocks, so every case can be tested.
//!
//! The processes are stopped in pipeline order — console, emulator,
//! simulator — so every report and the trace are flushed:
//!
//! - Ctrl-C / SIGTERM: stop the console; once it has ended, the emulator.
//! - The console failed: the others keep going to the planned end, then
//!   the emulator is stopped.
//! - The console ended normally but the emulator has not drained what it
//!   holds within the drain grace: stop it.
//! - The emulator is gone (died, or ended 5 s ago): the simulator gets no
//!   end marker; stop it.
//! - The emulator is gone and the console still streams into nothing: stop
//!   it at the planned end.
//! - A console still running but not yet streaming (no `console.ready`)
//!   [`CONSOLE_READY`] after its start is stuck: it is named as a fault
//!   and the run is stopped as on Ctrl-C. (On a host whose disk is busy,
//!   a process may wait minutes in the kernel as iceoryx2 syncs its node's
//!   files to disk; without this the run would wait for the hard deadline
//!   with nothing said.)
//! - Past the hard deadline (planned + drain grace + 60 s): kill them all.

use std::time::Duration;

/// A process as the runner sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    Running,
    /// Ended with exit status 0.
    Succeeded,
    /// Ended otherwise (exit status, signal).
    Failed,
}

impl State {
    fn ended(self) -> bool {
        self != State::Running
    }

    /// The state of one role's processes together (the consoles or the
    /// robots of a run of several streams): running while any runs, then
    /// failed if any failed.
    pub fn of_group(states: impl IntoIterator<Item = State>) -> State {
        let (mut running, mut failed) = (false, false);
        for s in states {
            running |= s == State::Running;
            failed |= s == State::Failed;
        }
        match (running, failed) {
            (true, _) => State::Running,
            (false, true) => State::Failed,
            (false, false) => State::Succeeded,
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

/// What to do after a look. Stopping a process that has ended does nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Orders {
    pub stop_console: bool,
    pub stop_emulator: bool,
    pub stop_simulator: bool,
    /// Kill whatever still runs, then reap: the run is over.
    pub kill_all: bool,
    /// The consoles not yet streaming are stuck: name them (once).
    pub consoles_stalled: bool,
    /// All three have ended (or were killed): stop supervising.
    pub done: bool,
}

/// The runner's policy, with what it remembers between looks.
#[derive(Debug, Clone)]
pub struct Supervisor {
    planned: Duration,
    drain_grace: Duration,
    hard_deadline: Duration,
    interrupted: bool,
    stalled: bool,
    console_ended_at: Option<Duration>,
    emulator_ended_at: Option<Duration>,
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

impl Supervisor {
    /// A run whose stream is planned to last `planned_s` seconds.
    pub fn new(planned_s: f64) -> Supervisor {
        let planned = Duration::from_secs_f64(planned_s + 1.0);
        Supervisor {
            planned,
            drain_grace: DRAIN_GRACE,
            hard_deadline: planned + DRAIN_GRACE + Duration::from_secs(60),
            interrupted: false,
            stalled: false,
            console_ended_at: None,
            emulator_ended_at: None,
        }
    }

    /// Whether the run was interrupted (Ctrl-C / SIGTERM, or stuck consoles).
    pub fn interrupted(&self) -> bool {
        self.interrupted
    }

    /// The orders after one look.
    pub fn look(&mut self, s: Seen) -> Orders {
        let mut o = Orders::default();
        let (c, e, m) = (s.console.ended(), s.emulator.ended(), s.simulator.ended());
        let stuck = !self.stalled && !s.consoles_ready && s.console == State::Running && s.now > CONSOLE_READY;
        if stuck {
            self.stalled = true;
            o.consoles_stalled = true;
        }
        if (s.stop_requested || stuck) && !self.interrupted {
            self.interrupted = true;
            o.stop_console = true;
        }
        if c && self.console_ended_at.is_none() {
            self.console_ended_at = Some(s.now);
        }
        if e && self.emulator_ended_at.is_none() {
            self.emulator_ended_at = Some(s.now);
        }
        if c && e && m {
            o.done = true;
            return o;
        }
        let since = |t: Option<Duration>| t.map(|t| s.now.saturating_sub(t));
        let past_plan = s.now >= self.planned;
        let console_failed = s.console == State::Failed;
        if !e && (self.interrupted && c || console_failed && past_plan) {
            o.stop_emulator = true;
        }
        if !e && since(self.console_ended_at).is_some_and(|d| d > self.drain_grace) {
            o.stop_emulator = true;
        }
        if e && !m && (s.emulator == State::Failed || since(self.emulator_ended_at).is_some_and(|d| d > SIMULATOR_GRACE)) {
            o.stop_simulator = true;
        }
        if e && !c && (self.interrupted || past_plan) {
            o.stop_console = true;
        }
        if s.now > self.hard_deadline {
            o.kill_all = true;
            o.done = true;
        }
        o
    }
}

#[cfg(test)]
mod tests {
    use super::State::*;
    use super::*;

    #[test]
    fn a_group_runs_while_any_runs_then_fails_if_any_failed() {
        assert_eq!(State::of_group([Succeeded, Running, Failed]), Running);
        assert_eq!(State::of_group([Succeeded, Failed]), Failed);
        assert_eq!(State::of_group([Succeeded, Succeeded]), Succeeded);
        assert_eq!(State::of_group([Succeeded]), Succeeded);
    }

    fn seen(t: f64, console: State, emulator: State, simulator: State) -> Seen {
        Seen { now: Duration::from_secs_f64(t), stop_requested: false, console, consoles_ready: true, emulator, simulator }
    }

    #[test]
    fn a_console_not_streaming_long_after_its_start_is_named_and_the_run_stopped() {
        let mut s = Supervisor::new(100.0);
        let waiting = |t| Seen { consoles_ready: false, ..seen(t, Running, Running, Running) };
        assert_eq!(s.look(waiting(29.0)), Orders::default(), "a console may take its time to start");
        let o = s.look(waiting(31.0));
        assert_eq!(o, Orders { stop_console: true, consoles_stalled: true, ..Orders::default() });
        assert!(s.interrupted());
        assert_eq!(s.look(waiting(32.0)), Orders::default(), "named and stopped once");
        // Stopped in order once the console has ended.
        assert_eq!(s.look(seen(33.0, Succeeded, Running, Running)), Orders { stop_emulator: true, ..Orders::default() });
        // Consoles that stream, or that ended, are not stuck.
        let mut s = Supervisor::new(100.0);
        assert_eq!(s.look(seen(40.0, Running, Running, Running)), Orders::default());
        assert_eq!(s.look(Seen { consoles_ready: false, ..seen(41.0, Failed, Running, Running) }), Orders::default());
    }

    #[test]
    fn a_normal_run_is_left_alone_until_all_three_end() {
        let mut s = Supervisor::new(10.0);
        assert_eq!(s.look(seen(1.0, Running, Running, Running)), Orders::default());
        assert_eq!(s.look(seen(10.0, Succeeded, Running, Running)), Orders::default());
        assert_eq!(s.look(seen(10.5, Succeeded, Succeeded, Running)), Orders::default());
        assert_eq!(s.look(seen(10.6, Succeeded, Succeeded, Succeeded)), Orders { done: true, ..Orders::default() });
        assert!(!s.interrupted());
    }

    #[test]
    fn ctrl_c_stops_the_console_then_the_emulator() {
        let mut s = Supervisor::new(10.0);
        let o = s.look(Seen { stop_requested: true, ..seen(2.0, Running, Running, Running) });
        assert_eq!(o, Orders { stop_console: true, ..Orders::default() });
        assert!(s.interrupted());
        let o = s.look(Seen { stop_requested: true, ..seen(2.1, Running, Running, Running) });
        assert_eq!(o, Orders::default(), "the console is stopped once");
        let o = s.look(seen(2.2, Succeeded, Running, Running));
        assert_eq!(o, Orders { stop_emulator: true, ..Orders::default() });
    }

    #[test]
    fn a_failed_console_leaves_the_emulator_running_to_the_planned_end() {
        let mut s = Supervisor::new(10.0);
        assert_eq!(s.look(seen(3.0, Failed, Running, Running)), Orders::default());
        assert_eq!(s.look(seen(11.0, Failed, Running, Running)), Orders { stop_emulator: true, ..Orders::default() });
    }

    #[test]
    fn an_emulator_that_does_not_drain_is_stopped_after_the_grace() {
        let mut s = Supervisor::new(10.0);
        s.look(seen(11.0, Succeeded, Running, Running));
        assert_eq!(s.look(seen(40.0, Succeeded, Running, Running)), Orders::default());
        assert_eq!(s.look(seen(41.5, Succeeded, Running, Running)), Orders { stop_emulator: true, ..Orders::default() });
    }

    #[test]
    fn the_simulator_is_stopped_when_the_emulator_died_or_ended_long_ago() {
        let mut s = Supervisor::new(10.0);
        let o = s.look(seen(4.0, Running, Failed, Running));
        assert!(o.stop_simulator && !o.stop_console, "{o:?}: the console goes on to the planned end");
        let o = s.look(seen(11.0, Running, Failed, Running));
        assert!(o.stop_simulator && o.stop_console, "{o:?}");
        let mut s = Supervisor::new(10.0);
        assert_eq!(s.look(seen(11.0, Succeeded, Succeeded, Running)), Orders::default());
        assert_eq!(s.look(seen(16.5, Succeeded, Succeeded, Running)), Orders { stop_simulator: true, ..Orders::default() });
    }

    #[test]
    fn past_the_hard_deadline_everything_is_killed() {
        let mut s = Supervisor::new(10.0);
        let o = s.look(seen(102.0, Running, Running, Running));
        assert_eq!(o, Orders { kill_all: true, done: true, ..Orders::default() });
        let mut s = Supervisor::new(10.0);
        assert!(!s.look(seen(100.0, Succeeded, Running, Running)).kill_all, "11 + 30 + 60 s not yet passed");
    }
}
