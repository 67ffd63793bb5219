//! Live control of a running emulator (docs/interface.md, "Live control"):
//! `netfi ctl --run-id R show | switch | phase | pause | resume | watch`.
//!
//! Two halves, joined by two wait-free single-producer rings (`rtrb`):
//!
//! - the **control thread** ([`start`]), off the loop's core, serves the
//!   run's control service: it parses and validates each request with the
//!   scenario parser (a bad one is answered with the parser's error and
//!   changes nothing), builds the new phases ([`Timeline`]) and hands them
//!   to the loop; it records what the loop applied as events (streamed to
//!   `events.jsonl` beside the trace, and returned for the report), and
//!   publishes the telemetry intervals the trace writer closes;
//! - the loop's end, [`ControlPort`], which the emulator's loop polls every
//!   4096 turns, as it looks at the stop flag: it moves the waiting
//!   commands into the injector ([`crate::injector::Injector::switch`]:
//!   no allocation, no lock) and sends back what it did, with the
//!   phases a switch cut, to be dropped on the control thread.
//!
//! So a switch takes effect between two frames, frames already queued keep
//! their release times, and the loop never parses, allocates or waits.

mod port;
mod protocol;
mod server;

pub use port::ControlPort;
pub use protocol::{resolve, Action, ControlEvent, PhaseOf, Request, Response, State, Target};
pub use server::Settings;

use crate::scenario::MAX_RUN_PHASES;
use crate::transport::ipc::control::TelemetrySample;
use port::{Shared, RING};
use server::Server;
use std::sync::atomic::Ordering;
use std::sync::{mpsc, Arc};

/// The control thread's handle.
pub struct ControlHandle {
    shared: Arc<Shared>,
    thread: std::thread::JoinHandle<Vec<ControlEvent>>,
    telemetry: Option<mpsc::Sender<TelemetrySample>>,
}

impl ControlHandle {
    /// Keeps the control thread off `core` (the loop's); `false` where it
    /// cannot be.
    pub fn keep_off_core(&self, core: usize) -> bool {
        use std::os::unix::thread::JoinHandleExt;
        crate::host::keep_thread_off_core(self.thread.as_pthread_t(), core)
    }

    /// The telemetry aggregator to hand to the trace writer, if telemetry is on.
    pub fn aggregator(&self, interval_ns: u64) -> Option<Box<dyn crate::trace::Tap>> {
        let tx = self.telemetry.clone()?;
        Some(Box::new(crate::service::telemetry::Aggregator::new(interval_ns, tx)))
    }

    /// Stops the control thread; the events that took effect.
    pub fn finish(self) -> Vec<ControlEvent> {
        self.shared.stop.store(true, Ordering::Release);
        drop(self.telemetry);
        self.thread.join().unwrap_or_default()
    }
}

/// Why live control did not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error(transparent)]
    Node(#[from] crate::transport::ipc::NodeOpenError),
    /// The control or telemetry service.
    #[error(transparent)]
    Service(#[from] crate::transport::ipc::control::SideOpenError),
    /// `events.jsonl`.
    #[error(transparent)]
    Log(#[from] crate::durable::DurableError),
    #[error("starting the control thread")]
    Thread(#[source] std::io::Error),
    #[error("the control thread ended before opening its services")]
    Ended,
}

/// Starts the control thread (before the loop's core is pinned) and
/// returns the loop's end and the handle. Fails if the control or
/// telemetry service cannot be opened.
pub fn start(settings: Settings) -> Result<(ControlPort, ControlHandle), StartError> {
    let (cmd_tx, cmd_rx) = rtrb::RingBuffer::new(RING);
    let (app_tx, app_rx) = rtrb::RingBuffer::new(2 * RING);
    let shared = Arc::new(Shared::default());
    let (tel_tx, tel_rx) = mpsc::channel();
    let (ready_tx, ready_rx) = mpsc::channel();
    let server = Server::new(settings, cmd_tx, app_rx, shared.clone(), tel_rx);
    let thread = std::thread::Builder::new().name("netfi-control".into()).spawn(move || server.run(ready_tx)).map_err(StartError::Thread)?;
    match ready_rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            let _ = thread.join();
            return Err(e);
        }
        Err(_) => return Err(StartError::Ended),
    }
    let port = ControlPort { commands: cmd_rx, applied: app_tx, shared: shared.clone() };
    Ok((port, ControlHandle { shared, thread, telemetry: Some(tel_tx) }))
}

/// Headroom of phases a run reserves for switches.
pub const PHASE_ROOM: usize = MAX_RUN_PHASES;
