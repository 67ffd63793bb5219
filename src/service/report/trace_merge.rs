//! The run's trace: the emulator's rows (`trace_emulator.csv`, one per
//! frame and copy) joined with the robot's receive times (`received.csv`)
//! into `trace.csv`, and the delays of the frames that made it through,
//! for the delay check.
//!
//! A cut input (`NAME.partial`: its writer stopped before it was whole) is
//! read for what it has; a cut emulator trace makes a cut `trace.csv`
//! (left as `trace.csv.partial`, which the report names).

use super::delay::Delays;
use super::files::{partial_path, WriteError};
use crate::durable::PartialFile;
use super::phases::Fates;
use crate::trace::Column;
use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

/// The emulator's trace of the forward stream, in the run's directory.
pub const EMULATOR_TRACE: &str = "trace_emulator.csv";
/// The robot's receive times.
pub const RECEIVED: &str = "received.csv";
/// The joined trace.
pub const TRACE: &str = "trace.csv";

/// Why the trace could not be joined.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// An input could not be read.
    #[error("reading {}: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },
    /// `trace.csv` could not be written whole.
    #[error(transparent)]
    Write(#[from] WriteError),
    /// The emulator's trace, joined, could not be removed.
    #[error("removing {}: {source}", path.display())]
    Remove { path: PathBuf, source: std::io::Error },
}

/// What becomes of the emulator's trace once joined: removed (the
/// runner's join, made once), or kept (a report made from a run's
/// directory, which may be made again).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    Consume,
    Keep,
}

/// The joined trace, when there is a whole one, the delays, and each
/// frame's ingress time and fate.
#[derive(Debug, Default)]
pub struct Merged {
    pub trace: Option<PathBuf>,
    pub delays: Delays,
    pub fates: Fates,
}

/// The robot's receive times, by ingress index: the first receipt of each
/// index, and the further ones of indices received more than once (copies,
/// docs/spec.md §3.8), each with the release time it was scheduled for,
/// which tells a copy's receipt from its original's.
#[derive(Debug, Default)]
struct Receipts {
    /// `(recv_ns, release_sched_ns)` by ingress index; `recv_ns` 0: none.
    first: Vec<(u64, u64)>,
    more: BTreeMap<u64, Vec<(u64, u64)>>,
}

impl Receipts {
    /// Reads `received.csv` (or, cut, `received.csv.partial`, less a last
    /// row cut in the middle); none when neither is there.
    fn read(out: &Path) -> Result<Receipts, MergeError> {
        let whole = out.join(RECEIVED);
        let cut = !whole.exists();
        let path = if cut { partial_path(&whole) } else { whole };
        let mut r = Receipts::default();
        let Ok(f) = crate::load::open_regular(&path) else { return Ok(r) };
        let mut reader = std::io::BufReader::new(f);
        let mut line = String::new();
        let mut header = true;
        loop {
            line.clear();
            let n = reader.read_line(&mut line).map_err(|source| MergeError::Read { path: path.clone(), source })?;
            // The end, or the last row of a cut file, which its writer may
            // not have finished.
            if n == 0 || (cut && !line.ends_with('\n')) {
                return Ok(r);
            }
            if !std::mem::take(&mut header) {
                r.add(line.trim_end());
            }
        }
    }

    /// Adds a row `ingress_index,recv_ns[,release_sched_ns]`; a row that
    /// does not parse is skipped.
    fn add(&mut self, row: &str) {
        let mut it = row.split(',').map(str::parse::<u64>);
        let (Some(Ok(i)), Some(Ok(t))) = (it.next(), it.next()) else { return };
        let sched = it.next().and_then(Result::ok).unwrap_or(0);
        let i = i as usize;
        if self.first.len() <= i {
            self.first.resize(i + 1, (0, 0));
        }
        if self.first[i].0 == 0 {
            self.first[i] = (t, sched);
        } else {
            self.more.entry(i as u64).or_default().push((t, sched));
        }
    }

    /// Takes the receipt of the row of `index` scheduled for `sched`: one
    /// scheduled then (a `received.csv` without that column matches any),
    /// or else any left for that index.
    fn take(&mut self, index: usize, sched: Option<u64>) -> Option<u64> {
        let matches = |r: &(u64, u64)| r.1 == 0 || sched.is_none_or(|s| s == r.1);
        let first = *self.first.get(index).filter(|f| f.0 != 0)?;
        if !matches(&first) {
            if let Some(m) = self.more.get_mut(&(index as u64)) {
                if let Some(k) = m.iter().position(matches) {
                    return Some(m.remove(k).0);
                }
            }
        }
        // The first receipt goes; the next one, if any, takes its place.
        let next = self.more.get_mut(&(index as u64)).and_then(|m| (!m.is_empty()).then(|| m.remove(0)));
        self.first[index] = next.unwrap_or((0, 0));
        Some(first.0)
    }
}

/// Joins the emulator's trace in `out` with the robot's receive times into
/// `trace.csv`, and collects the delays of the frames that made it
/// through. Without an emulator trace, a `trace.csv` already joined (a
/// directory reported before, `Source::Keep`) is read for its delays.
pub fn merge_trace(out: &Path, source: Source) -> Result<Merged, MergeError> {
    let emu = out.join(EMULATOR_TRACE);
    let joined = out.join(TRACE);
    let (input, whole) = match (emu.exists(), partial_path(&emu).exists()) {
        (true, _) => (emu, true),
        (false, true) => (partial_path(&emu), false),
        (false, false) if source == Source::Keep && joined.exists() => {
            let (delays, fates) = read_delays(&joined)?;
            return Ok(Merged { trace: Some(joined), delays, fates });
        }
        (false, false) => return Ok(Merged::default()),
    };
    let mut recv = Receipts::read(out)?;
    let output = PartialFile::create(&joined)?;
    let (delays, fates, output) = join_rows(&input, output, &mut recv)?;
    // A cut input gives a cut output: it keeps its `.partial` name.
    let trace = if whole { Some(output.commit()?) } else { None };
    if source == Source::Consume {
        std::fs::remove_file(&input).map_err(|source| MergeError::Remove { path: input.clone(), source })?;
    }
    Ok(Merged { trace, delays, fates })
}

/// Writes the rows of `input` to `output` (synced) with the receive time
/// of each delivered row that has one, and returns their delays and every
/// frame's fate.
fn join_rows(input: &Path, output: PartialFile, recv: &mut Receipts) -> Result<(Delays, Fates, PartialFile), MergeError> {
    let cut = output.partial().to_path_buf();
    let write_err = |source| MergeError::Write(WriteError::Write { path: cut.clone(), source });
    let read_err = |source| MergeError::Read { path: input.to_path_buf(), source };
    let mut w = std::io::BufWriter::with_capacity(1 << 20, output);
    let mut delays = Delays::default();
    let mut fates = Fates::default();
    let rows = std::io::BufReader::new(crate::load::open_regular(input).map_err(read_err)?).lines();
    for (n, line) in rows.enumerate() {
        let line = line.map_err(read_err)?;
        if n > 0 {
            fate(&line, &mut fates);
        }
        let received = if n == 0 { None } else { receipt(&line, recv) };
        let Some(t) = received else {
            writeln!(w, "{line}").map_err(write_err)?;
            continue;
        };
        let mut cols: Vec<&str> = line.split(',').collect();
        let t_text = t.to_string();
        if let Some(c) = cols.get_mut(Column::RecvNs.index()) {
            *c = &t_text;
        }
        writeln!(w, "{}", cols.join(",")).map_err(write_err)?;
        if let (Some(send), Some(delay)) = (number(&cols, Column::SendNs), number(&cols, Column::DelayNs)) {
            delays.ingress_ns.push(number(&cols, Column::IngressNs).unwrap_or(0));
            delays.injected.push(delay);
            delays.seen.push(t.saturating_sub(send));
        }
    }
    // A failed flush or sync (a full disk) is an error too, not a cut file
    // under a whole one's name.
    let file = w.into_inner().map_err(|e| write_err(e.into_error()))?;
    Ok((delays, fates, file))
}

/// Adds a row's frame to `fates`: its ingress time and whether it was
/// dropped; a copy's row (a `copy` other than 0), a malformed frame's
/// (dropped before the scenario: not a fate the scenario gave) and a row
/// that does not parse add nothing.
fn fate(line: &str, fates: &mut Fates) {
    let cols: Vec<&str> = line.split(',').collect();
    let original = Column::Copy.of(&cols).is_none_or(|c| c.is_empty() || c == "0");
    let malformed = Column::Reason.of(&cols).is_some_and(|r| crate::injector::Invalid::of_reason(r).is_some());
    if let (true, Some(t), Some(f)) = (original, number(&cols, Column::IngressNs), Column::Fate.of(&cols)) {
        match malformed {
            true => fates.entered(t),
            false => fates.push(t, f == "dropped"),
        }
    }
}

/// The receipt of a delivered trace row, taken from `recv`.
fn receipt(line: &str, recv: &mut Receipts) -> Option<u64> {
    let cols: Vec<&str> = line.split(',').collect();
    if Column::Fate.of(&cols) != Some("delivered") {
        return None;
    }
    let index: usize = Column::IngressIndex.of(&cols)?.parse().ok()?;
    recv.take(index, number(&cols, Column::ReleaseSchedNs))
}

/// The number in column `c` of a row's cells, if it has one.
fn number(cols: &[&str], c: Column) -> Option<u64> {
    c.of(cols).and_then(|x| x.parse().ok())
}

/// The delays of the received rows of a joined trace, and every frame's fate.
fn read_delays(path: &Path) -> Result<(Delays, Fates), MergeError> {
    let read_err = |source| MergeError::Read { path: path.to_path_buf(), source };
    let mut delays = Delays::default();
    let mut fates = Fates::default();
    for line in std::io::BufReader::new(crate::load::open_regular(path).map_err(read_err)?).lines().skip(1) {
        let line = line.map_err(read_err)?;
        fate(&line, &mut fates);
        let cols: Vec<&str> = line.split(',').collect();
        let at = |c| number(&cols, c);
        if let (Some(send), Some(delay), Some(t)) = (at(Column::SendNs), at(Column::DelayNs), at(Column::RecvNs)) {
            delays.ingress_ns.push(at(Column::IngressNs).unwrap_or(0));
            delays.injected.push(delay);
            delays.seen.push(t.saturating_sub(send));
        }
    }
    Ok((delays, fates))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scratch::dir;

    const HEADER: &str = crate::trace::CSV_HEADER;

    /// A trace row: index, send, fate, delay, scheduled release, copy.
    fn row(index: u64, send: u64, fate: &str, delay: u64, sched: u64, copy: u8) -> String {
        format!("{index},{index},{index},{send},{send},{fate},,,,{delay},{sched},{sched},,{copy},0,0")
    }

    /// Frame 0 delivered, 1 dropped, 2 delivered with a copy (both
    /// received: the copy first), 3 delivered and never received.
    fn emulator_trace() -> String {
        let rows = [
            row(0, 1_000, "delivered", 500, 1_500, 0),
            row(1, 2_000, "dropped", 0, 0, 0),
            row(2, 3_000, "delivered", 100, 3_100, 0),
            row(2, 3_000, "delivered", 900, 3_900, 1),
            row(3, 4_000, "delivered", 0, 4_000, 0),
        ];
        format!("{HEADER}\n{}\n", rows.join("\n"))
    }

    const RECEIVED_ROWS: &str = "ingress_index,recv_ns,release_sched_ns\n0,1510\n2,3950,3900\n2,3120,3100\n";

    fn recv_of(trace: &str) -> Vec<String> {
        trace.lines().skip(1).map(|l| l.split(',').nth(Column::RecvNs.index()).unwrap_or("-").to_string()).collect()
    }

    #[test]
    fn each_receipt_goes_to_its_row_and_copies_to_theirs() {
        let d = dir("join");
        std::fs::write(d.join(EMULATOR_TRACE), emulator_trace()).unwrap();
        std::fs::write(d.join(RECEIVED), RECEIVED_ROWS).unwrap();
        let m = merge_trace(&d, Source::Consume).unwrap();
        assert_eq!(m.trace, Some(d.join(TRACE)));
        let trace = std::fs::read_to_string(d.join(TRACE)).unwrap();
        assert_eq!(trace.lines().next(), Some(HEADER));
        assert_eq!(recv_of(&trace), ["1510", "", "3120", "3950", ""]);
        assert_eq!(m.delays.injected, [500, 100, 900]);
        assert_eq!(m.delays.seen, [510, 120, 950]);
        assert_eq!(m.delays.ingress_ns, [1_000, 3_000, 3_000]);
        // Four frames (the copy is none), the second dropped.
        assert_eq!((m.fates.len(), m.fates.origin_ns()), (4, Some(1_000)));
        assert!(!d.join(EMULATOR_TRACE).exists(), "the joined emulator trace stays");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_kept_source_joins_again_and_a_joined_trace_alone_gives_its_delays() {
        let d = dir("keep");
        std::fs::write(d.join(EMULATOR_TRACE), emulator_trace()).unwrap();
        std::fs::write(d.join(RECEIVED), RECEIVED_ROWS).unwrap();
        let first = merge_trace(&d, Source::Keep).unwrap();
        let again = merge_trace(&d, Source::Keep).unwrap();
        assert!(d.join(EMULATOR_TRACE).exists());
        assert_eq!((first.delays.seen.len(), again.delays.seen), (3, first.delays.seen));
        std::fs::remove_file(d.join(EMULATOR_TRACE)).unwrap();
        let joined = merge_trace(&d, Source::Keep).unwrap();
        assert_eq!(joined.trace, Some(d.join(TRACE)));
        assert_eq!(joined.fates.len(), 4);
        assert_eq!((joined.delays.injected, joined.delays.seen), (vec![500, 100, 900], vec![510, 120, 950]));
        // The runner's join of a directory without an emulator trace has none.
        let none = merge_trace(&d, Source::Consume).unwrap();
        assert_eq!((none.trace, none.delays.seen.len()), (None, 0));
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn cut_inputs_are_read_for_what_they_have_and_a_cut_trace_stays_cut() {
        let d = dir("cut");
        // The emulator's trace cut in the middle of frame 3's row; the
        // robot's receipts cut in the middle of the copy's.
        let trace = emulator_trace();
        std::fs::write(partial_path(&d.join(EMULATOR_TRACE)), &trace[..trace.len() - 9]).unwrap();
        std::fs::write(partial_path(&d.join(RECEIVED)), "ingress_index,recv_ns,release_sched_ns\n0,1510\n2,3120,3100\n2,39").unwrap();
        let m = merge_trace(&d, Source::Consume).unwrap();
        assert_eq!(m.trace, None, "a cut trace is not the run's trace");
        let cut = std::fs::read_to_string(partial_path(&d.join(TRACE))).unwrap();
        assert!(!d.join(TRACE).exists());
        assert_eq!(cut.lines().count(), 6, "every row there was, the cut one too");
        assert_eq!(recv_of(&cut)[..4], ["1510", "", "3120", ""]);
        assert_eq!(m.delays.seen, [510, 120]);
        assert!(!partial_path(&d.join(EMULATOR_TRACE)).exists());
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn an_unwritable_trace_is_an_error_naming_it() {
        let d = dir("unwritable");
        std::fs::write(d.join(EMULATOR_TRACE), emulator_trace()).unwrap();
        std::fs::create_dir_all(partial_path(&d.join(TRACE))).unwrap();
        let e = merge_trace(&d, Source::Consume).unwrap_err();
        assert!(e.to_string().contains(&partial_path(&d.join(TRACE)).display().to_string()), "{e}");
        assert!(d.join(EMULATOR_TRACE).exists(), "the emulator's trace is kept when the join failed");
        std::fs::remove_dir_all(&d).ok();
    }
}
