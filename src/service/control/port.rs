//! The loop's end of live control: the commands waiting in a wait-free
//! ring, applied between two frames, and what the loop tells the control
//! thread at every poll.

use crate::clock::now_ns;
use crate::scenario::{Switched, Timeline};
use crate::service::link::{Carried, Link};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// A command for the loop.
pub(super) enum Command {
    Switch { id: u64, at_ns: Option<u64>, timeline: Timeline },
    Pause { id: u64, paused: bool },
}

/// What the loop did with a command.
pub(super) enum Applied {
    Switched { id: u64, s: Switched },
    Refused { id: u64 },
    Paused { id: u64, paused: bool, t_ns: u64 },
}

/// What the loop tells the control thread at every poll.
#[derive(Default)]
pub(super) struct Shared {
    /// The first frame's time + 1 (0: none yet).
    pub(super) start_ns: AtomicU64,
    pub(super) entered: AtomicU64,
    pub(super) phase: AtomicU64,
    pub(super) paused: AtomicBool,
    pub(super) stop: AtomicBool,
}

/// Commands in flight at once (one per request; requests are answered one
/// at a time).
pub(super) const RING: usize = 8;

/// The loop's end: polled every 4096 turns.
pub struct ControlPort {
    pub(super) commands: rtrb::Consumer<Command>,
    pub(super) applied: rtrb::Producer<Applied>,
    pub(super) shared: Arc<Shared>,
}

impl ControlPort {
    /// Applies the commands waiting (between two frames) and publishes the
    /// loop's state. No allocation, lock or system call but the clock.
    pub fn poll<T: Carried>(&mut self, link: &mut Link<T>) {
        let inj = link.injector_mut();
        while let Ok(cmd) = self.commands.pop() {
            let now = now_ns();
            let done = match cmd {
                Command::Switch { id, at_ns, timeline } => match inj.switch(now, at_ns, timeline) {
                    Ok(s) => Applied::Switched { id, s },
                    Err(_refused) => Applied::Refused { id },
                },
                Command::Pause { id, paused } => {
                    inj.set_paused(paused);
                    Applied::Paused { id, paused, t_ns: inj.start_ns().map_or(0, |s| now.saturating_sub(s)) }
                }
            };
            // The ring holds twice the commands that can be in flight.
            let _ = self.applied.push(done);
        }
        let s = &self.shared;
        s.start_ns.store(inj.start_ns().map_or(0, |t| t + 1), Ordering::Relaxed);
        s.entered.store(inj.next_ingress_index(), Ordering::Relaxed);
        s.phase.store(inj.scenario().current_phase() as u64, Ordering::Relaxed);
        s.paused.store(inj.scenario().paused(), Ordering::Relaxed);
    }
}
