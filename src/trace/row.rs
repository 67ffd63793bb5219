//! The rows as text: one CSV line a frame (or a copy), formatted in place.

use super::column::{Column, CSV_HEADER};
use super::table::{CopyRow, Row};
use crate::durable::PartialFile;
use crate::injector::DropCause;
use std::io::Write;
use std::path::Path;

/// One CSV line built in place: integers by `itoa`, nothing allocated. At a
/// million frames a second the trace writer formats a million rows, on a
/// core it shares with the emulator's peers; the `write!` of before (with a
/// `String` per empty-or-number field) cost it about a third of that core.
/// Each cell is written under its [`Column`], in the columns' order
/// (checked in debug builds), so the rows stay under the header.
struct Line {
    buf: [u8; Line::CAP],
    len: usize,
    /// Cells written so far.
    cells: usize,
}

impl Line {
    /// 14 numbers of at most 20 digits, the fate and reason words (under
    /// 32 bytes each), 15 commas and the newline: 359 bytes at most.
    const CAP: usize = 384;

    fn new() -> Line {
        Line { buf: [0; Line::CAP], len: 0, cells: 0 }
    }

    fn raw(&mut self, t: &str) {
        self.buf[self.len..self.len + t.len()].copy_from_slice(t.as_bytes());
        self.len += t.len();
    }

    /// Starts column `c`'s cell: a comma before every cell but the first.
    #[inline]
    fn cell(&mut self, c: Column) {
        debug_assert_eq!(c.index(), self.cells, "the trace's cell {c} written out of the columns' order");
        self.cells += 1;
        if c.index() > 0 {
            self.raw(",");
        }
    }

    /// Column `c`'s cell: the text `t`.
    fn text(&mut self, c: Column, t: &str) {
        self.cell(c);
        self.raw(t);
    }

    /// Column `c`'s cell: the number `v`, or empty.
    fn num(&mut self, c: Column, v: Option<u64>) {
        self.cell(c);
        if let Some(v) = v {
            let mut b = itoa::Buffer::new();
            self.raw(b.format(v));
        }
    }

    /// The line's end, after every column's cell.
    fn end(&mut self) -> &[u8] {
        debug_assert_eq!(self.cells, Column::COUNT, "a trace row has a cell in every column");
        self.raw("\n");
        &self.buf[..self.len]
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
    l.num(Column::IngressIndex, Some(i));
    l.num(Column::Sequence, r.sequence.map(u64::from));
    l.num(Column::ConsoleIndex, Some(r.console_index));
    l.num(Column::SendNs, Some(r.send_ns));
    l.num(Column::IngressNs, Some(r.ingress_ns));
    l.text(Column::Fate, fate);
    l.text(Column::Reason, reason);
    l.num(Column::Phase, where_.map(|w| w.0));
    l.num(Column::Stage, where_.map(|w| w.1));
    l.num(Column::DelayNs, scheduled.then(|| sched.saturating_sub(r.ingress_ns)));
    l.num(Column::ReleaseSchedNs, scheduled.then_some(sched));
    l.num(Column::ReleaseNs, released);
    l.num(Column::RecvNs, recv);
    l.num(Column::Copy, Some(copy_no));
    l.num(Column::CopiesDropped, copies_dropped);
    l.num(Column::Corrupted, scheduled.then_some(u64::from(corrupted)));
    w.write_all(l.end())
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
