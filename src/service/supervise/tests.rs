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

fn stop(console: bool, emulator: bool, simulator: bool) -> Orders {
    Orders { stop: Roles { console, emulator, simulator }, ..Orders::default() }
}

fn kill(console: bool, emulator: bool, simulator: bool) -> Orders {
    Orders { kill: Roles { console, emulator, simulator }, ..Orders::default() }
}

#[test]
fn a_console_not_streaming_long_after_its_start_is_named_and_the_run_stopped() {
    let mut s = Supervisor::new(100.0);
    let waiting = |t| Seen { consoles_ready: false, ..seen(t, Running, Running, Running) };
    assert_eq!(s.look(waiting(29.0)), Orders::default(), "a console may take its time to start");
    let o = s.look(waiting(31.0));
    assert_eq!(o, Orders { consoles_stalled: true, ..stop(true, false, false) });
    assert!(s.interrupted());
    assert_eq!(s.look(waiting(32.0)), Orders::default(), "named and stopped once");
    // Stopped in order once the console has ended.
    assert_eq!(s.look(seen(33.0, Succeeded, Running, Running)), stop(false, true, false));
    // Consoles that stream, or that ended, are not stuck.
    let mut s = Supervisor::new(100.0);
    assert_eq!(s.look(seen(40.0, Running, Running, Running)), Orders::default());
    assert_eq!(s.look(Seen { consoles_ready: false, ..seen(41.0, Succeeded, Running, Running) }), Orders::default());
}

#[test]
fn a_normal_run_is_left_alone_until_all_three_end() {
    let mut s = Supervisor::new(10.0);
    assert_eq!(s.look(seen(1.0, Running, Running, Running)), Orders::default());
    assert_eq!(s.look(seen(10.0, Succeeded, Running, Running)), Orders::default());
    assert_eq!(s.look(seen(10.5, Succeeded, Succeeded, Running)), Orders::default());
    assert_eq!(s.look(seen(10.6, Succeeded, Succeeded, Succeeded)), Orders { done: true, ..Orders::default() });
    assert!(!s.interrupted() && !s.died());
}

#[test]
fn ctrl_c_stops_the_console_then_the_emulator() {
    let mut s = Supervisor::new(10.0);
    let o = s.look(Seen { stop_requested: true, ..seen(2.0, Running, Running, Running) });
    assert_eq!(o, stop(true, false, false));
    assert!(s.interrupted());
    let o = s.look(Seen { stop_requested: true, ..seen(2.1, Running, Running, Running) });
    assert_eq!(o, Orders::default(), "the console is stopped once");
    assert_eq!(s.look(seen(2.2, Succeeded, Running, Running)), stop(false, true, false));
    assert_eq!(s.look(seen(2.3, Succeeded, Running, Running)), Orders::default(), "the emulator is stopped once");
    assert_eq!(s.look(seen(9.0, Succeeded, Running, Running)), Orders::default(), "a stopping emulator is not killed: it may be draining");
}

#[test]
fn a_dead_console_stops_the_emulator_once_it_has_seen_it_go_then_the_simulator() {
    let mut s = Supervisor::new(10.0);
    assert_eq!(s.look(seen(3.0, Failed, Running, Running)), Orders::default(), "the emulator is given time to see its console go");
    assert!(s.died());
    assert_eq!(s.look(seen(3.5, Failed, Running, Running)), stop(false, true, false));
    assert_eq!(s.look(seen(3.6, Failed, Succeeded, Running)), Orders::default(), "the simulator takes the end marker");
    assert_eq!(s.look(seen(4.7, Failed, Succeeded, Running)), stop(false, false, true));
    assert_eq!(s.look(seen(4.8, Failed, Succeeded, Succeeded)), Orders { done: true, ..Orders::default() });
    assert!(!s.interrupted(), "a death is not an interruption");
}

#[test]
fn a_dead_emulator_stops_the_console_and_the_simulator_at_once() {
    let mut s = Supervisor::new(10.0);
    assert_eq!(s.look(seen(4.0, Running, Failed, Running)), stop(true, false, true));
    assert_eq!(s.look(seen(4.1, Running, Failed, Running)), Orders::default(), "each is stopped once");
    assert_eq!(s.look(seen(6.0, Succeeded, Failed, Running)), kill(false, false, true), "not stopped within the grace: killed");
    assert_eq!(s.look(seen(6.1, Succeeded, Failed, Failed)), Orders { done: true, ..Orders::default() });
}

#[test]
fn a_dead_simulator_stops_the_console_then_the_emulator() {
    let mut s = Supervisor::new(10.0);
    assert_eq!(s.look(seen(2.0, Running, Running, Failed)), stop(true, false, false));
    assert_eq!(s.look(seen(2.1, Succeeded, Running, Failed)), Orders::default());
    assert_eq!(s.look(seen(2.5, Succeeded, Running, Failed)), stop(false, true, false));
    assert_eq!(s.look(seen(4.0, Succeeded, Running, Failed)), Orders::default(), "2 s after its own stop, not the console's");
    assert_eq!(s.look(seen(4.5, Succeeded, Running, Failed)), kill(false, true, false));
}

#[test]
fn a_console_that_does_not_stop_after_a_death_is_killed() {
    let mut s = Supervisor::new(10.0);
    assert_eq!(s.look(seen(2.0, Running, Failed, Running)), stop(true, false, true));
    assert_eq!(s.look(seen(3.9, Running, Failed, Succeeded)), Orders::default());
    assert_eq!(s.look(seen(4.1, Running, Failed, Succeeded)), kill(true, false, false));
}

#[test]
fn an_emulator_that_does_not_drain_is_stopped_after_the_grace() {
    let mut s = Supervisor::new(10.0);
    s.look(seen(11.0, Succeeded, Running, Running));
    assert_eq!(s.look(seen(40.0, Succeeded, Running, Running)), Orders::default());
    assert_eq!(s.look(seen(41.5, Succeeded, Running, Running)), stop(false, true, false));
}

#[test]
fn the_simulator_is_stopped_when_the_emulator_ended_long_ago() {
    let mut s = Supervisor::new(10.0);
    assert_eq!(s.look(seen(11.0, Succeeded, Succeeded, Running)), Orders::default());
    assert_eq!(s.look(seen(16.5, Succeeded, Succeeded, Running)), stop(false, false, true));
    // An emulator that ended normally while the console streams: the
    // console goes on to the planned end.
    let mut s = Supervisor::new(10.0);
    assert_eq!(s.look(seen(4.0, Running, Succeeded, Running)), Orders::default());
    assert_eq!(s.look(seen(11.0, Running, Succeeded, Running)), stop(true, false, true));
}

#[test]
fn past_the_hard_deadline_everything_is_killed() {
    let mut s = Supervisor::new(10.0);
    let o = s.look(seen(102.0, Running, Running, Running));
    assert_eq!(o, Orders { kill: Roles::ALL, done: true, ..Orders::default() });
    let mut s = Supervisor::new(10.0);
    assert!(s.look(seen(100.0, Succeeded, Running, Running)).kill == Roles::default(), "11 + 30 + 60 s not yet passed");
}

#[test]
fn a_run_of_the_lab_s_console_and_robot_ends_with_its_emulator() {
    // No duration: the lab's console ends the stream; nothing else to stop.
    let mut s = Supervisor::until(None);
    assert_eq!(State::of_group([]), Lab);
    assert_eq!(s.look(seen(1.0, Lab, Running, Lab)), Orders::default());
    assert_eq!(s.look(seen(100_000.0, Lab, Running, Lab)), Orders::default(), "no hard deadline");
    assert_eq!(s.look(seen(100_001.0, Lab, Succeeded, Lab)), Orders { done: true, ..Orders::default() });
    assert!(!s.interrupted() && !s.died());
    // Ctrl-C goes straight to the emulator.
    let mut s = Supervisor::until(None);
    let o = s.look(Seen { stop_requested: true, ..seen(2.0, Lab, Running, Lab) });
    assert!(o.stop.emulator && s.stopped_on_request(), "{o:?}");
    // A duration ends it at the planned end.
    let mut s = Supervisor::until(Some(5.0));
    assert_eq!(s.look(seen(5.5, Lab, Running, Lab)), Orders::default());
    assert!(s.look(seen(6.1, Lab, Running, Lab)).stop.emulator);
    // netfi's own robot behind the lab's console: stopped once the emulator ended.
    let mut s = Supervisor::until(None);
    assert_eq!(s.look(seen(3.0, Lab, Succeeded, Running)), Orders::default());
    assert_eq!(s.look(seen(8.5, Lab, Succeeded, Running)), stop(false, false, true));
    // The emulator died: the run ends, nothing of the lab's is touched.
    let mut s = Supervisor::until(None);
    let o = s.look(seen(1.0, Lab, Failed, Lab));
    assert!(o.done, "{o:?}");
}
