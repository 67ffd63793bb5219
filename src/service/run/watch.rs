//! The runner's watch over its processes: what it sees, given to the
//! [`Supervisor`], and its orders carried out; the run's dead iceoryx2
//! peers reaped meanwhile.

use super::procs::{Proc, Procs};
use crate::service::plan::Plan;
use crate::service::signals;
use crate::service::supervise::{Orders, Seen, State, Supervisor, CONSOLE_READY, KILL_GRACE};
use crate::transport::{IpcConfig, RunId};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How often the runner looks at its processes.
const LOOK_EVERY: Duration = Duration::from_millis(5);

/// How often the runner reaps the run's dead iceoryx2 peers (and at once
/// when a process ends).
const REAP_EVERY: Duration = Duration::from_millis(200);

/// Reaps the dead iceoryx2 peers of every stream of the run.
fn reap(ipcs: &[IpcConfig]) {
    for cfg in ipcs {
        if let Ok(r) = crate::transport::cleanup_dead_nodes(cfg) {
            for dead in r.dead() {
                eprintln!("reaped a dead peer: {dead}");
            }
        }
    }
}

/// What the runner knows of a run's consoles: where each says it streams,
/// and whether all have.
struct Consoles {
    ready: Vec<PathBuf>,
    all_ready: bool,
}

/// Watches the processes until they have ended, stopping them as the
/// [`Supervisor`] says (each stream's console and robot as one role);
/// reaps the run's dead iceoryx2 peers meanwhile (off the emulator's core,
/// so the survivors see their peer counts drop and a restarted peer can
/// take over its port); names each console not streaming
/// ([`CONSOLE_READY`]) after its start. Returns whether the run was
/// stopped at a person's request (Ctrl-C, SIGTERM; not stuck consoles).
pub fn supervise(plan: &Plan, procs: &mut Procs) -> bool {
    let started = Instant::now();
    let mut policy = Supervisor::until(plan.until_s);
    let ipcs: Vec<_> = plan.streams.iter().filter_map(|s| RunId::new(&s.run_id).ok().map(IpcConfig::new)).collect();
    let mut last_reap = Instant::now();
    let mut consoles = Consoles { ready: plan.streams.iter().filter(|s| s.console.is_some()).map(|s| s.out.join("console.ready")).collect(), all_ready: false };
    let mut ended = 0;
    loop {
        std::thread::sleep(LOOK_EVERY);
        let now_ended = procs.all_mut().map(|p| p.poll() as usize).sum::<usize>();
        // A process that just ended is reaped at once: its peers see it go.
        if now_ended > ended || last_reap.elapsed() > REAP_EVERY {
            last_reap = Instant::now();
            reap(&ipcs);
        }
        ended = now_ended;
        if signals::ensure_installed() {
            eprintln!("WARNING: the Ctrl-C handler had been replaced; put back");
        }
        let seen = look(started, procs, &mut consoles);
        let (was_interrupted, had_died) = (policy.interrupted(), policy.died());
        let o = policy.look(seen);
        if policy.interrupted() && !was_interrupted {
            eprintln!("stopping: console, then emulator, then simulator");
        }
        if policy.died() && !had_died {
            let dead: Vec<_> = procs.all().filter(|p| p.state() == State::Failed).map(|p| p.role).collect();
            eprintln!("the {} died: stopping the run", dead.join(", "));
        }
        obey(&o, procs, &consoles.ready);
        if o.done {
            return policy.stopped_on_request();
        }
    }
}

/// What the runner sees of its processes now.
fn look(started: Instant, procs: &Procs, consoles: &mut Consoles) -> Seen {
    let all_ready = procs.consoles.iter().zip(&consoles.ready).all(|(p, r)| p.status.is_some() || r.exists());
    consoles.all_ready |= all_ready;
    Seen {
        now: started.elapsed(),
        stop_requested: signals::stop_requested(),
        console: State::of_group(procs.consoles.iter().map(Proc::state)),
        consoles_ready: consoles.all_ready,
        emulator: procs.emulator.state(),
        simulator: State::of_group(procs.simulators.iter().map(Proc::state)),
    }
}

/// Carries out the supervisor's orders `o`; `ready` is each console's
/// mark that it streams.
fn obey(o: &Orders, procs: &mut Procs, ready: &[PathBuf]) {
    if o.consoles_stalled {
        let what = format!("was not streaming {} s after its start", CONSOLE_READY.as_secs());
        procs.consoles.iter_mut().zip(ready).filter(|(p, r)| p.status.is_none() && !r.exists()).for_each(|(p, _)| p.stuck(&what));
    }
    let stop = [o.stop.console, o.stop.emulator, o.stop.simulator];
    let kill = [o.kill.console, o.kill.emulator, o.kill.simulator];
    let why = match o.done {
        true => "was still running at the run's hard deadline, and was killed".to_string(),
        false => format!("did not stop within {} s of SIGTERM, and was killed", KILL_GRACE.as_secs()),
    };
    for (k, group) in [&mut procs.consoles[..], std::slice::from_mut(&mut procs.emulator), &mut procs.simulators[..]].into_iter().enumerate() {
        for p in group.iter_mut() {
            if stop[k] {
                p.terminate();
            }
            if kill[k] {
                p.kill(&why);
            }
        }
    }
    if o.done {
        // Killed at the hard deadline: reaped before the report is made.
        for p in procs.all_mut() {
            let _ = p.child.wait();
            p.poll();
        }
    }
}
