//! `trace.csv` read as a stream, one row at a time, into fixed-size
//! summaries: loss, delay and what netfi added per time bin, loss-run
//! lengths, and the histograms of the delays drawn and seen, for the whole
//! run and for each of its first [`MAX_STRETCHES`] stretches under one
//! condition. Memory stays bounded however long the run: at most
//! [`MAX_BINS`] bins, one counter per distinct loss-run length, and two
//! HdrHistograms per stretch kept.
//!
//! Time is the frame's ingress time from the run's first frame: the clock
//! of the run's phases and of its control events.

use super::HtmlError;
use crate::trace::{Column, Header};
use hdrhistogram::Histogram;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

/// The most time bins kept; when the run outlasts them, neighbours merge
/// and the bin width doubles.
pub const MAX_BINS: usize = 256;

/// The most stretches of a run whose delays are kept apart (each for a
/// plot of its own); the figures of every stretch are in the report.
pub const MAX_STRETCHES: usize = 16;

/// The frames of one time bin.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Bin {
    /// Frames that entered the emulator.
    pub frames: u64,
    pub dropped: u64,
    /// Delivered frames, and those of them the simulator received.
    pub delivered: u64,
    pub received: u64,
    /// Sum of the injected delays of delivered frames, ns.
    pub drawn_sum_ns: u128,
    /// Sum and maximum of receive − send of received frames, ns.
    pub seen_sum_ns: u128,
    pub seen_max_ns: u64,
    /// Sum and maximum of what netfi added to received frames (receive −
    /// send − injected delay), ns.
    pub added_sum_ns: u128,
    pub added_max_ns: u64,
    /// Released frames, and the sum and maximum of their release lateness
    /// (actual − scheduled release), ns.
    pub released: u64,
    pub late_sum_ns: u128,
    pub late_max_ns: u64,
}

impl Bin {
    fn merge(&mut self, o: &Bin) {
        self.frames += o.frames;
        self.dropped += o.dropped;
        self.delivered += o.delivered;
        self.received += o.received;
        self.drawn_sum_ns += o.drawn_sum_ns;
        self.seen_sum_ns += o.seen_sum_ns;
        self.seen_max_ns = self.seen_max_ns.max(o.seen_max_ns);
        self.added_sum_ns += o.added_sum_ns;
        self.added_max_ns = self.added_max_ns.max(o.added_max_ns);
        self.released += o.released;
        self.late_sum_ns += o.late_sum_ns;
        self.late_max_ns = self.late_max_ns.max(o.late_max_ns);
    }
}

/// The delays drawn and seen of the frames of one stretch of the run.
#[derive(Debug, Clone)]
pub struct Delays {
    /// Injected delays of delivered frames, ns.
    pub drawn_ns: Histogram<u64>,
    /// receive − send of received frames, ns.
    pub seen_ns: Histogram<u64>,
}

impl Delays {
    fn new() -> Delays {
        // Three significant digits from 1 ns to an hour: a delay histogram
        // of a few hundred kB whatever the run's length.
        let h = || Histogram::new_with_bounds(1, 3_600_000_000_000, 3).expect("valid histogram bounds");
        Delays { drawn_ns: h(), seen_ns: h() }
    }

    /// Values outside the bounds are clamped, not lost.
    fn record(&mut self, drawn: Option<u64>, seen: Option<u64>) {
        if let Some(d) = drawn {
            self.drawn_ns.saturating_record(d.max(1));
        }
        if let Some(v) = seen {
            self.seen_ns.saturating_record(v.max(1));
        }
    }
}

/// What the trace says, summarized.
#[derive(Debug, Clone)]
pub struct TraceSummary {
    /// Width of a bin, ns; bin `i` covers `[i·w, (i+1)·w)` after the first
    /// frame's ingress.
    pub bin_ns: u64,
    pub bins: Vec<Bin>,
    /// Loss-run length (consecutive dropped frames, in ingress order) → count.
    pub loss_runs: BTreeMap<u64, u64>,
    /// The whole run's delays.
    pub delays: Delays,
    /// Where each stretch of the run begins (ns from the first frame, the
    /// first at 0), and the delays of the first [`MAX_STRETCHES`].
    pub stretch_starts_ns: Vec<u64>,
    pub stretches: Vec<Delays>,
    pub rows: u64,
    /// Dropped frames since the last delivered one.
    open_run: u64,
}

/// The columns read, by name (the header decides their positions): a
/// header without one of them is not a trace's.
const READ: [Column; 7] = [Column::SendNs, Column::IngressNs, Column::Fate, Column::DelayNs, Column::ReleaseSchedNs, Column::ReleaseNs, Column::RecvNs];

impl TraceSummary {
    /// An empty summary whose first bin is `bin_ns` wide, of a run of one
    /// condition.
    pub fn new(bin_ns: u64) -> TraceSummary {
        TraceSummary::with_stretches(bin_ns, &[])
    }

    /// An empty summary of a run whose stretches under one condition begin
    /// at `starts_ns` (ns from the first frame, in order; the first at 0).
    pub fn with_stretches(bin_ns: u64, starts_ns: &[u64]) -> TraceSummary {
        let kept = starts_ns.len().min(MAX_STRETCHES);
        TraceSummary {
            bin_ns: bin_ns.max(1),
            bins: Vec::new(),
            loss_runs: BTreeMap::new(),
            delays: Delays::new(),
            stretch_starts_ns: starts_ns.to_vec(),
            stretches: (0..kept).map(|_| Delays::new()).collect(),
            rows: 0,
            open_run: 0,
        }
    }

    /// The bin of time `t_ns` (since the first send), merging bins until it fits.
    fn bin(&mut self, t_ns: u64) -> &mut Bin {
        let mut i = (t_ns / self.bin_ns) as usize;
        while i >= MAX_BINS {
            let merged: Vec<Bin> = self.bins.chunks(2).map(|c| {
                let mut b = c[0];
                if let Some(o) = c.get(1) {
                    b.merge(o);
                }
                b
            }).collect();
            self.bins = merged;
            self.bin_ns *= 2;
            i = (t_ns / self.bin_ns) as usize;
        }
        if self.bins.len() <= i {
            self.bins.resize(i + 1, Bin::default());
        }
        &mut self.bins[i]
    }

    /// The end of the last bin, s after the first frame's send.
    pub fn end_s(&self) -> f64 {
        self.bins.len() as f64 * self.bin_ns as f64 / 1e9
    }

    /// The middle of bin `i`, s after the first frame's send.
    pub fn centre_s(&self, i: usize) -> f64 {
        (i as f64 + 0.5) * self.bin_ns as f64 / 1e9
    }
}

/// Reads `path` row by row. `bin_ns` is the first bin width (it doubles
/// while the run outlasts [`MAX_BINS`] bins); `stretches_ns` where the
/// run's stretches under one condition begin. A row that does not parse is
/// an error naming the file and the line.
pub fn summarize(path: &Path, bin_ns: u64, stretches_ns: &[u64]) -> Result<TraceSummary, HtmlError> {
    let file = crate::load::open_regular(path).map_err(|e| HtmlError::read(path, e))?;
    let mut lines = std::io::BufReader::with_capacity(1 << 16, file).lines();
    let header = lines.next().transpose().map_err(|e| HtmlError::read(path, e))?.unwrap_or_default();
    let cols = Header::parse(&header);
    if READ.iter().any(|c| cols.get(*c).is_none()) {
        return Err(HtmlError::malformed(path, "line 1: not a trace header (send_ns, fate, delay_ns and recv_ns expected)"));
    }
    let mut s = TraceSummary::with_stretches(bin_ns, stretches_ns);
    let mut t0: Option<u64> = None;
    for (n, line) in lines.enumerate() {
        let line = line.map_err(|e| HtmlError::read(path, e))?;
        if line.is_empty() {
            continue;
        }
        let row = Row::parse(&line, &cols).map_err(|what| HtmlError::malformed(path, format!("line {}: {what}", n + 2)))?;
        let t = row.ingress_ns.saturating_sub(*t0.get_or_insert(row.ingress_ns));
        s.record(t, &row);
    }
    s.close_run();
    Ok(s)
}

impl TraceSummary {
    /// A frame of a simulated run (`scenario check`, a preview): at `t_ns`
    /// after the first, dropped or delivered after `drawn_ns`; nobody
    /// received it. Call [`TraceSummary::close_run`] after the last.
    pub fn record_simulated(&mut self, t_ns: u64, drawn_ns: Option<u64>) {
        let row = Row {
            send_ns: t_ns,
            ingress_ns: t_ns,
            dropped: drawn_ns.is_none(),
            delivered: drawn_ns.is_some(),
            delay_ns: drawn_ns,
            release: None,
            recv_ns: None,
        };
        self.record(t_ns, &row);
    }

    /// Counts the loss run still open at the end.
    pub fn close_run(&mut self) {
        if self.open_run > 0 {
            *self.loss_runs.entry(self.open_run).or_default() += 1;
            self.open_run = 0;
        }
    }

    fn record(&mut self, t_ns: u64, row: &Row) {
        self.rows += 1;
        if row.dropped {
            self.open_run += 1;
        } else {
            self.close_run();
        }
        self.add(t_ns, row);
    }

    fn add(&mut self, t_ns: u64, row: &Row) {
        let (mut drawn, mut seen) = (None, None);
        let b = self.bin(t_ns);
        b.frames += 1;
        if row.dropped {
            b.dropped += 1;
        }
        if let Some(d) = row.delay_ns.filter(|_| row.delivered) {
            b.delivered += 1;
            b.drawn_sum_ns += u128::from(d);
            drawn = Some(d);
            if let Some((sched, actual)) = row.release {
                let late = actual.saturating_sub(sched);
                b.released += 1;
                b.late_sum_ns += u128::from(late);
                b.late_max_ns = b.late_max_ns.max(late);
            }
            if let Some(r) = row.recv_ns {
                let v = r.saturating_sub(row.send_ns);
                let added = v.saturating_sub(d);
                b.received += 1;
                b.seen_sum_ns += u128::from(v);
                b.seen_max_ns = b.seen_max_ns.max(v);
                b.added_sum_ns += u128::from(added);
                b.added_max_ns = b.added_max_ns.max(added);
                seen = Some(v);
            }
        }
        self.delays.record(drawn, seen);
        let k = self.stretch_starts_ns.partition_point(|s| *s <= t_ns).saturating_sub(1);
        if let Some(st) = self.stretches.get_mut(k) {
            st.record(drawn, seen);
        }
    }
}

/// The cells of one row that the summaries use.
struct Row {
    send_ns: u64,
    ingress_ns: u64,
    dropped: bool,
    delivered: bool,
    delay_ns: Option<u64>,
    /// Scheduled and actual release, of a released frame.
    release: Option<(u64, u64)>,
    recv_ns: Option<u64>,
}

impl Row {
    fn parse(line: &str, h: &Header) -> Result<Row, String> {
        let cells: Vec<&str> = line.split(',').collect();
        let cell = |c: Column| h.get(c).and_then(|i| cells.get(i).copied()).ok_or_else(|| format!("no {c} column ({} cells)", cells.len()));
        let number = |c: Column| -> Result<Option<u64>, String> {
            let v = cell(c)?;
            if v.is_empty() {
                return Ok(None);
            }
            v.parse().map(Some).map_err(|_| format!("{c} {v:?} is not a count of ns"))
        };
        let fate = cell(Column::Fate)?;
        if !matches!(fate, "delivered" | "dropped" | "held") {
            return Err(format!("fate {fate:?} (delivered, dropped or held expected)"));
        }
        Ok(Row {
            send_ns: number(Column::SendNs)?.ok_or("send_ns is empty")?,
            ingress_ns: number(Column::IngressNs)?.ok_or("ingress_ns is empty")?,
            dropped: fate == "dropped",
            delivered: fate == "delivered",
            delay_ns: number(Column::DelayNs)?,
            release: number(Column::ReleaseSchedNs)?.zip(number(Column::ReleaseNs)?),
            recv_ns: number(Column::RecvNs)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let p = std::env::temp_dir().join(format!("netfi-html-trace-{}-{name}.csv", std::process::id()));
        std::fs::write(&p, text).unwrap();
        p
    }

    const HEADER: &str = "ingress_index,sequence,console_index,send_ns,ingress_ns,fate,reason,phase,stage,delay_ns,release_sched_ns,release_ns,recv_ns\n";

    #[test]
    fn bins_loss_runs_and_delays() {
        let mut text = HEADER.to_string();
        // 10 frames 1 ms apart: dropped 2, 3, 4 and 7 (runs of 3 and 1).
        for i in 0..10u64 {
            let send = 1_000_000 + i * 1_000_000;
            if [2, 3, 4, 7].contains(&i) {
                text += &format!("{i},{i},{i},{send},{send},dropped,ge_lomax,1,1,,,,\n");
            } else {
                text += &format!("{i},{i},{i},{send},{send},delivered,,,,5000000,{},{},{}\n", send + 5_000_000, send + 5_000_000, send + 5_000_100);
            }
        }
        let p = write("ok", &text);
        let s = summarize(&p, 5_000_000, &[]).unwrap();
        std::fs::remove_file(&p).ok();
        assert_eq!(s.rows, 10);
        assert_eq!(s.loss_runs, BTreeMap::from([(1, 1), (3, 1)]));
        assert_eq!(s.bins.len(), 2);
        assert_eq!((s.bins[0].frames, s.bins[0].dropped), (5, 3));
        assert_eq!((s.bins[1].frames, s.bins[1].dropped), (5, 1));
        assert_eq!(s.bins[1].seen_max_ns, 5_000_100);
        assert_eq!((s.bins[1].added_max_ns, s.bins[1].released), (100, 4));
        assert_eq!(s.delays.drawn_ns.len(), 6);
        assert_eq!(s.delays.seen_ns.len(), 6);
    }

    #[test]
    fn long_runs_merge_bins_and_keep_every_frame() {
        let mut text = HEADER.to_string();
        for i in 0..3000u64 {
            text += &format!("{i},{i},{i},0,{},dropped,x,1,1,,,,\n", i * 1_000_000);
        }
        let p = write("long", &text);
        let s = summarize(&p, 1_000_000, &[]).unwrap();
        std::fs::remove_file(&p).ok();
        assert!(s.bins.len() <= MAX_BINS);
        assert_eq!(s.bin_ns, 16_000_000);
        assert_eq!(s.bins.iter().map(|b| b.frames).sum::<u64>(), 3000);
        assert_eq!(s.loss_runs, BTreeMap::from([(3000, 1)]));
    }

    #[test]
    fn each_stretch_keeps_its_own_delays_on_the_ingress_clock() {
        let mut text = HEADER.to_string();
        // Sent long before they entered: the time is the ingress's. Frames
        // 0–4 delayed 1 ms, 5–9 delayed 9 ms; a stretch begins at 5 ms.
        for i in 0..10u64 {
            let t = 1_000_000_000 + i * 1_000_000;
            let d = if i < 5 { 1_000_000 } else { 9_000_000 };
            text += &format!("{i},{i},{i},0,{t},delivered,,,,{d},{},{},\n", t + d, t + d);
        }
        let p = write("stretches", &text);
        let s = summarize(&p, 1_000_000, &[0, 5_000_000]).unwrap();
        std::fs::remove_file(&p).ok();
        assert_eq!(s.bins.len(), 10, "a bin a millisecond from the first ingress");
        assert_eq!(s.stretches.len(), 2);
        assert_eq!((s.stretches[0].drawn_ns.len(), s.stretches[0].drawn_ns.max() / 1000), (5, 1000));
        // The histogram keeps 3 significant digits: 9 ms within 0.1%.
        let second = &s.stretches[1].drawn_ns;
        assert_eq!(second.len(), 5);
        assert!((8_990..=9_000).contains(&(second.min() / 1000)), "{}", second.min());
    }

    #[test]
    fn a_bad_row_names_file_and_line() {
        let p = write("bad", &format!("{HEADER}0,0,0,12,0,delivered,,,,x,,,\n"));
        let e = summarize(&p, 1, &[]).unwrap_err().to_string();
        std::fs::remove_file(&p).ok();
        assert!(e.contains(&p.display().to_string()) && e.contains("line 2") && e.contains("delay_ns"), "{e}");
    }
}
