//! The per-frame trace (docs/spec.md §6): one row per frame that reached the
//! emulator, written to disk as the run goes, off the hot path.
//!
//! The emulator's loop pushes fixed-size [`TraceEvent`]s into a wait-free
//! single-producer ring ([`TraceSink::push`]: no allocation, no lock, no
//! system call); a writer thread drains the ring every few milliseconds.
//! A frame's row is complete once its fate is final (dropped, or
//! released); complete rows are appended to the CSV in ingress order
//! (buffered, flushed at least once a second), so the writer holds only the
//! rows of frames still queued (at most [`MAX_PENDING_ROWS`]: a row older
//! than that is written as it stands). Memory stays flat however long the
//! run, and a killed emulator leaves its trace up to its last second.
//!
//! When given a directory for them, the writer also keeps the decision
//! time and the release lateness of the frames of each second and appends
//! them as one interval each to `decision.hlog` and `lateness.hlog`
//! (HdrHistogram interval logs, one interval per second): the loop records
//! nothing for it, the rows carry the values. The run's totals stay in the
//! link's own histograms.
//!
//! If the ring is ever full the event is counted in
//! [`TraceSink::overflowed`] and the frame's row stays incomplete — the
//! run's counts are unaffected. A write that fails (a full disk) is an
//! error naming the file, returned by [`TraceWriter::finish`]; the writer
//! keeps draining the ring so the loop is never held up.
//!
//! Every file here (the trace, the histogram logs, and a [`CsvLog`]'s) is
//! written as `NAME.partial` and renamed to `NAME` once whole, flushed and
//! synced ([`crate::durable`]): a file cut by a full disk or a killed
//! process keeps the `.partial` name, so a reader tells it from a whole one.
//!
//! # `trace.csv`
//! One header line, then one row per ingress index, in ingress order, and
//! after it one row per copy of that frame a `duplicate` stage made and
//! the queue took (docs/spec.md §3.8): a copy is released as a frame of its
//! own, under its original's ingress index. The rows of one frame then
//! account for it exactly: the copies made are its copy rows plus
//! `copies_dropped`, and every row has one fate. Summed over the file,
//! `entered + duplicated = delivered + dropped + held`, where `entered` is
//! the rows with `copy` 0, `duplicated` the other rows plus the sum of
//! `copies_dropped`, and `dropped` the `dropped` rows plus that sum.
//!
//! The columns ([`Column`], the header line generated from them):
//!
//! | column | meaning |
//! |---|---|
//! | `ingress_index` | the emulator's count of frames that entered (0, 1, …); a copy has its original's |
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
//! | `copy` | 0 for the frame as it entered; k for its k-th copy the queue took |
//! | `copies_dropped` | on a `copy` 0 row: copies of the frame that a later stage or a full queue dropped (their reasons are in the report's drop counts) |
//! | `corrupted` | for a scheduled row: 1 if a `corrupt` stage flipped bits of it (docs/spec.md §3.9), else 0 |
//!
//! A copy row repeats its frame's `sequence`, `console_index`, `send_ns`
//! and `ingress_ns`. A release is matched to the row it belongs to by its
//! scheduled time (the original first when a copy is due at the same
//! time); a copy still held at the end shows the release time its stages
//! asked for.
//!
//! Times are integers; empty cells are missing values. `pandas.read_csv` and
//! `polars.read_csv` read it as it is.

mod column;
mod csv_log;
mod ring;
mod row;
mod table;
mod writer;

pub use column::{Column, Header, CSV_HEADER};
pub use csv_log::CsvLog;
pub use ring::{TraceEvent, TraceSink, RING_CAPACITY};
pub use row::{format_row, write_csv};
pub use table::{CopyRow, Row, Tap, MAX_PENDING_ROWS};
pub use writer::{start, TraceError, TraceWriter, Written};

use std::time::Duration;

/// How often the CSV is flushed and a histogram interval is appended.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

#[cfg(test)]
mod tests;
