//! The rows as text: one CSV line a frame (or a copy), formatted in place.

use super::table::{CopyRow, Row};
use crate::durable::PartialFile;
use crate::injector::DropCause;
use std::io::Write;
use std::path::Path;

/// The CSV's header line.
pub const CSV_HEADER: &str =
    "ingress_index,sequence,console_index,send_ns,ingress_ns,fate,reason,phase,stage,delay_ns,release_sched_ns,release_ns,recv_ns,copy,copies_dropped,corrupted";

/// The index of `recv_ns` among the CSV's columns: the emulator leaves it
/// empty and the runner fills it in.
pub const RECV_COLUMN: usize = 12;

/// One CSV line built in place: integers by `itoa`, nothing allocated. At a
/// million frames a second the trace writer formats a million rows, on a
/// core it shares with the emulator's peers; the `write!` of before (with a
/// `String` per empty-or-number field) cost it about a third of that core.
struct Line {
    buf: [u8; Line::CAP],
    len: usize,
}

impl Line {
    /// 14 numbers of at most 20 digits, the fate and reason words (under
    /// 32 bytes each), 15 commas and the newline: 359 bytes at most.
    const CAP: usize = 384;

    fn new() -> Line {
        Line { buf: [0; Line::CAP], len: 0 }
    }

    fn text(&mut self, t: &str) {
        self.buf[self.len..self.len + t.len()].copy_from_slice(t.as_bytes());
        self.len += t.len();
    }

    fn num(&mut self, v: u64) {
        let mut b = itoa::Buffer::new();
        self.text(b.format(v));
    }

    fn opt(&mut self, v: Option<u64>) {
        if let Some(v) = v {
            self.num(v);
        }
    }

    /// A comma, then the field.
    fn then_text(&mut self, t: &str) {
        self.text(",");
        self.text(t);
    }

    fn then_opt(&mut self, v: Option<u64>) {
        self.text(",");
        self.opt(v);
    }
}

/// Formats one row: the frame `r`, or with `copy` one of its copies
/// (`recv_ns` empty: the runner joins it later).
pub fn format_row(w: &mut impl Write, i: u64, r: &Row, copy: Option<&CopyRow>, recv: Option<u64>) -> std::io::Result<()> {
    let (dropped, sched, released, corrupted) = match copy {
        None => (r.dropped, r.release_sched_ns, r.release_ns, r.corrupted),
        Some(c) => (None, c.release_sched_ns, c.release_ns, c.corrupted),
    };
    let (fate, reason, where_) = match dropped {
        None if released.is_some() => ("delivered", "", None),
        None => ("held", "", None),
        Some(c) => {
            let at = match c {
                DropCause::Stage { phase, stage, .. } => Some((u64::from(phase) + 1, u64::from(stage) + 1)),
                _ => None,
            };
            ("dropped", c.reason(), at)
        }
    };
    let scheduled = dropped.is_none();
    let (copy_no, copies_dropped) = match copy {
        None => (0, Some(u64::from(r.copies_dropped))),
        Some(c) => (u64::from(c.copy), None),
    };
    let mut l = Line::new();
    l.num(i);
    l.then_opt(r.sequence.map(u64::from));
    for v in [r.console_index, r.send_ns, r.ingress_ns] {
        l.then_opt(Some(v));
    }
    l.then_text(fate);
    l.then_text(reason);
    l.then_opt(where_.map(|w| w.0));
    l.then_opt(where_.map(|w| w.1));
    l.then_opt(scheduled.then(|| sched.saturating_sub(r.ingress_ns)));
    l.then_opt(scheduled.then_some(sched));
    l.then_opt(released);
    l.then_opt(recv);
    l.then_opt(Some(copy_no));
    l.then_opt(copies_dropped);
    l.then_opt(scheduled.then_some(u64::from(corrupted)));
    l.text("\n");
    w.write_all(&l.buf[..l.len])
}

/// Writes a table as CSV, joined with receive times (`recv_ns[i]` for
/// ingress index i; 0 = not received): as `path.partial`, renamed to
/// `path` once whole.
pub fn write_csv(path: &Path, rows: &[Row], recv_ns: &[u64]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::with_capacity(1 << 20, PartialFile::create(path).map_err(std::io::Error::other)?);
    writeln!(w, "{CSV_HEADER}")?;
    for (i, r) in rows.iter().enumerate() {
        if r.present {
            format_row(&mut w, i as u64, r, None, recv_ns.get(i).copied().filter(|t| *t != 0))?;
        }
    }
    w.into_inner().map_err(|e| e.into_error())?.commit().map_err(std::io::Error::other)?;
    Ok(())
}
