//! The per-frame trace (SPEC §6): one row per frame that reached the
//! emulator, written off the hot path.
//!
//! The emulator's loop pushes fixed-size [`TraceEvent`]s into a wait-free
//! single-producer ring ([`TraceSink::push`]: no allocation, no lock, no
//! system call); a writer thread drains the ring every few milliseconds into
//! a table indexed by ingress index. If the ring is ever full the event is
//! counted in [`TraceSink::overflowed`] and the frame's row stays
//! incomplete — the run's counts are unaffected. At the end the table is
//! joined with the simulator's receive times and written as CSV.
//!
//! # `trace.csv`
//! One header line, then one row per ingress index, in ingress order:
//!
//! | column | meaning |
//! |---|---|
//! | `ingress_index` | the emulator's count of frames that entered (0, 1, …) |
//! | `sequence` | the ITP frame's `sequence` field (empty if malformed) |
//! | `console_index` | the console's send counter |
//! | `send_ns` | console send time, CLOCK_MONOTONIC ns |
//! | `ingress_ns` | time the emulator took it off the console port |
//! | `fate` | `delivered`, `dropped`, or `held` (scheduled, still queued at the end) |
//! | `reason` | for `dropped`: the model that dropped it, `queue_full`, `wrong_size` or `bad_checksum` |
//! | `phase`, `stage` | for drops by a model: its phase and stage (from 1) |
//! | `delay_ns` | injected delay (scheduled release − ingress) |
//! | `release_sched_ns` | scheduled release time |
//! | `release_ns` | actual release time (just before publishing) |
//! | `recv_ns` | simulator receive time (empty if not received) |
//!
//! Times are integers; empty cells are missing values. `pandas.read_csv` and
//! `polars.read_csv` read it as it is.

use crate::injector::DropCause;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// What the emulator reports about a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceEvent {
    Ingress {
        ingress_index: u64,
        sequence: Option<u32>,
        console_index: u64,
        send_ns: u64,
        ingress_ns: u64,
        /// `None` if scheduled.
        dropped: Option<DropCause>,
        release_sched_ns: u64,
    },
    Release { ingress_index: u64, release_ns: u64 },
}

/// One row of the trace table.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Row {
    pub present: bool,
    pub sequence: Option<u32>,
    pub console_index: u64,
    pub send_ns: u64,
    pub ingress_ns: u64,
    pub dropped: Option<DropCause>,
    pub release_sched_ns: u64,
    pub release_ns: Option<u64>,
}

/// The hot path's end of the ring.
pub struct TraceSink {
    tx: rtrb::Producer<TraceEvent>,
    overflowed: u64,
}

impl TraceSink {
    /// Pushes an event; never blocks or allocates.
    #[inline]
    pub fn push(&mut self, ev: TraceEvent) {
        if self.tx.push(ev).is_err() {
            self.overflowed += 1;
        }
    }

    /// Events lost because the ring was full.
    pub fn overflowed(&self) -> u64 {
        self.overflowed
    }
}

/// The writer thread's handle.
pub struct TraceWriter {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<Vec<Row>>,
}

/// Ring capacity in events: at 100 kHz two events per frame, ~1.3 s of
/// events before the writer must have drained.
pub const RING_CAPACITY: usize = 1 << 18;

/// Starts the writer thread (call before pinning the hot thread, so the
/// writer is not confined to its core) and returns the hot path's sink.
pub fn start(expected_frames: usize) -> (TraceSink, TraceWriter) {
    let (mut tx, mut rx) = rtrb::RingBuffer::<TraceEvent>::new(RING_CAPACITY);
    // Write every slot once before the hot path starts, so the ring's pages
    // are resident: otherwise a fresh page is faulted in every few dozen
    // frames, on the hot thread, for the first pass through the ring.
    let blank = TraceEvent::Release { ingress_index: 0, release_ns: 0 };
    while tx.push(blank).is_ok() {}
    while rx.pop().is_ok() {}
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let thread = std::thread::Builder::new()
        .name("netfi-trace".into())
        .spawn(move || {
            let mut rows: Vec<Row> = Vec::with_capacity(expected_frames);
            loop {
                let stopping = stop2.load(Ordering::Acquire);
                while let Ok(ev) = rx.pop() {
                    apply(&mut rows, ev);
                }
                if stopping {
                    return rows;
                }
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
        })
        .expect("spawning the trace writer thread");
    (TraceSink { tx, overflowed: 0 }, TraceWriter { stop, thread })
}

fn apply(rows: &mut Vec<Row>, ev: TraceEvent) {
    let idx = match ev {
        TraceEvent::Ingress { ingress_index, .. } | TraceEvent::Release { ingress_index, .. } => ingress_index as usize,
    };
    if rows.len() <= idx {
        rows.resize(idx + 1, Row::default());
    }
    let row = &mut rows[idx];
    match ev {
        TraceEvent::Ingress { sequence, console_index, send_ns, ingress_ns, dropped, release_sched_ns, .. } => {
            *row = Row { present: true, sequence, console_index, send_ns, ingress_ns, dropped, release_sched_ns, release_ns: row.release_ns };
        }
        TraceEvent::Release { release_ns, .. } => row.release_ns = Some(release_ns),
    }
}

impl TraceWriter {
    /// Keeps the writer thread off `core`: a busy-polling loop pinned there
    /// would otherwise be preempted whenever the writer wakes on it (every
    /// few milliseconds) and its releases would be late by as much. Nothing
    /// changes where `core` is the only core the thread may use.
    pub fn keep_off_core(&self, core: usize) {
        use std::os::unix::thread::JoinHandleExt;
        if let Some(set) = crate::host::cores_except(core) {
            // SAFETY: `set` is a valid cpu_set_t and the pthread is alive
            // (it is joined only in `finish`, which consumes `self`).
            unsafe {
                libc::pthread_setaffinity_np(self.thread.as_pthread_t(), std::mem::size_of::<libc::cpu_set_t>(), &set);
            }
        }
    }

    /// Stops the writer after it has drained everything pushed so far and
    /// returns the table. Call after the hot loop has ended.
    pub fn finish(self) -> Vec<Row> {
        self.stop.store(true, Ordering::Release);
        self.thread.join().expect("the trace writer thread panicked")
    }
}

/// Writes the table as CSV, joined with receive times (`recv_ns[i]` for
/// ingress index i; 0 = not received).
pub fn write_csv(path: &Path, rows: &[Row], recv_ns: &[u64]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    writeln!(w, "ingress_index,sequence,console_index,send_ns,ingress_ns,fate,reason,phase,stage,delay_ns,release_sched_ns,release_ns,recv_ns")?;
    for (i, r) in rows.iter().enumerate() {
        if !r.present {
            continue;
        }
        let recv = recv_ns.get(i).copied().filter(|t| *t != 0);
        let (fate, reason, phase, stage) = match r.dropped {
            None if r.release_ns.is_some() => ("delivered", "", String::new(), String::new()),
            None => ("held", "", String::new(), String::new()),
            Some(c) => {
                let (p, s) = match c {
                    DropCause::Stage { phase, stage, .. } => ((phase + 1).to_string(), (stage + 1).to_string()),
                    _ => (String::new(), String::new()),
                };
                ("dropped", c.reason(), p, s)
            }
        };
        let opt = |v: Option<u64>| v.map(|x| x.to_string()).unwrap_or_default();
        let scheduled = r.dropped.is_none();
        writeln!(
            w,
            "{i},{},{},{},{},{fate},{reason},{phase},{stage},{},{},{},{}",
            r.sequence.map(|s| s.to_string()).unwrap_or_default(),
            r.console_index,
            r.send_ns,
            r.ingress_ns,
            opt(scheduled.then(|| r.release_sched_ns - r.ingress_ns)),
            opt(scheduled.then_some(r.release_sched_ns)),
            opt(r.release_ns),
            opt(recv),
        )?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelKind;

    #[test]
    fn events_become_rows_and_csv() {
        let (mut sink, writer) = start(4);
        sink.push(TraceEvent::Ingress { ingress_index: 0, sequence: Some(7), console_index: 0, send_ns: 10, ingress_ns: 20, dropped: None, release_sched_ns: 120 });
        sink.push(TraceEvent::Ingress {
            ingress_index: 1,
            sequence: Some(8),
            console_index: 1,
            send_ns: 30,
            ingress_ns: 40,
            dropped: Some(DropCause::Stage { phase: 0, stage: 1, kind: ModelKind::GeLomax }),
            release_sched_ns: 0,
        });
        sink.push(TraceEvent::Release { ingress_index: 0, release_ns: 121 });
        sink.push(TraceEvent::Ingress { ingress_index: 2, sequence: None, console_index: 2, send_ns: 50, ingress_ns: 60, dropped: None, release_sched_ns: 70 });
        let rows = writer.finish();
        assert_eq!(rows.len(), 3);
        let path = std::env::temp_dir().join(format!("netfi-trace-{}.csv", std::process::id()));
        write_csv(&path, &rows, &[125]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_file(&path).ok();
        let lines: Vec<_> = text.lines().collect();
        assert_eq!(lines[1], "0,7,0,10,20,delivered,,,,100,120,121,125");
        assert_eq!(lines[2], "1,8,1,30,40,dropped,ge_lomax,1,2,,,,");
        assert_eq!(lines[3], "2,,2,50,60,held,,,,10,70,,");
        assert_eq!(sink.overflowed(), 0);
    }
}
