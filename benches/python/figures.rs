//! From the Python programs' per-frame records to percentiles: per part,
//! over the quiet windows and over all of them, each with the host's state
//! over the windows it used; the differences through the emulator − direct.

use crate::common::table::ns;
use crate::parts::Part;
use crate::windows::{self, Window};
use netfi::metrics::{difference, fmt_ns, LatencyHistogram, Summary};
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The percentiles every table shows.
pub const KEYS: [&str; 5] = ["p50", "p90", "p99", "p999", "max"];

/// The distributions, in the order of the tables.
pub const DISTS: [(&str, &str); 10] = [
    ("send_late", "console's send lateness (sent − the slot's time)"),
    ("oneway_direct", "one-way, direct (console → robot)"),
    ("oneway_chain", "one-way, through the emulator"),
    ("hop1", "· console → taken by the emulator"),
    ("inside", "· inside the emulator (taken → released)"),
    ("hop2", "· released → robot"),
    ("rtt_direct", "round trip, direct both ways"),
    ("rtt_chain", "round trip, through the emulator both ways"),
    ("share", "**emulator's share of the round trip** (inside, both ways)"),
    ("share_back", "· of which the feedback's (taken → released)"),
];

/// Which windows a figure is taken over.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Selection {
    /// Steal at most `--quiet-steal`.
    Quiet,
    /// Quiet, and other processes under `--quiet-others`.
    Calm,
    All,
}

impl Selection {
    pub const ALL: [Selection; 3] = [Selection::Quiet, Selection::Calm, Selection::All];

    fn takes(self, w: &Window) -> bool {
        match self {
            Selection::Quiet => w.quiet,
            Selection::Calm => w.calm,
            Selection::All => true,
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Selection::Quiet => "quiet windows (low steal)",
            Selection::Calm => "calm windows (low steal, other processes nearly idle)",
            Selection::All => "all windows",
        }
    }
}

/// The figures of one part over one selection of windows.
#[derive(Debug, Serialize)]
pub struct Figures {
    pub selection: Selection,
    pub windows_used: usize,
    pub windows_total: usize,
    /// Steal over the windows used: the largest window's fraction, the mean
    /// fraction, and milliseconds in all.
    pub steal_max: f64,
    pub steal_mean: f64,
    pub steal_ms: u64,
    /// Cores other processes kept busy: mean and largest over those windows.
    pub others_mean: f64,
    pub others_max: f64,
    pub dists: BTreeMap<String, Summary>,
    /// Through the emulator − direct, percentile by percentile.
    pub oneway_added_ns: BTreeMap<String, i64>,
    pub rtt_added_ns: BTreeMap<String, i64>,
    /// Through the emulator / direct at p50 and p99.
    pub oneway_ratio: BTreeMap<String, f64>,
    pub rtt_ratio: BTreeMap<String, f64>,
}

#[derive(Default)]
struct Hists(BTreeMap<&'static str, LatencyHistogram>);

impl Hists {
    fn add(&mut self, key: &'static str, ns: i64) {
        self.0.entry(key).or_default().record_signed(ns);
    }
}

impl Figures {
    /// The figures of `p` over the windows `sel` takes, after the warm-up.
    pub fn of(p: &Part, sel: Selection) -> Figures {
        let c = &p.console_summary;
        let warm = c["warm_slots"].as_i64().unwrap_or(0);
        let (t0, half) = (c["t0_ns"].as_i64().unwrap_or(0), c["half_period_ns"].as_f64().unwrap_or(0.0));
        let keep = |send_ns: i64, slot: i64| slot >= warm && (sel == Selection::All || windows::find(&p.windows, send_ns as u64).is_some_and(|i| sel.takes(&p.windows[i])));
        let mut h = Hists::default();
        for r in p.robot.iter().filter(|r| keep(r[2], r[1])) {
            let [route, slot, send, recv, ingress, release, injected, _] = *r;
            h.add("send_late", send - t0 - (slot as f64 * half) as i64);
            if route == 1 {
                h.add("oneway_direct", recv - send);
                continue;
            }
            h.add("oneway_chain", recv - send - injected);
            if ingress > 0 {
                h.add("hop1", ingress - send);
                h.add("inside", release - ingress - injected);
                h.add("hop2", recv - release);
            }
        }
        for c in p.console.iter().filter(|c| keep(c[2], c[1])) {
            let [route, _, send, recv, c_in, c_rel, c_inj, _, f_in, f_rel, f_inj, _] = *c;
            if route == 1 {
                h.add("rtt_direct", recv - send);
                continue;
            }
            h.add("rtt_chain", recv - send - c_inj - f_inj);
            if c_in > 0 && f_in > 0 {
                h.add("share", (c_rel - c_in - c_inj) + (f_rel - f_in - f_inj));
                h.add("share_back", f_rel - f_in - f_inj);
            }
        }
        let used: Vec<&Window> = p.windows.iter().filter(|w| sel.takes(w)).collect();
        Figures::from_hists(h, &used, p.windows.len(), sel)
    }

    fn from_hists(h: Hists, used: &[&Window], total: usize, selection: Selection) -> Figures {
        let dists: BTreeMap<String, Summary> = h.0.iter().map(|(k, v)| (k.to_string(), v.summary())).collect();
        let pair = |a: &str, b: &str| match (dists.get(a), dists.get(b)) {
            (Some(a), Some(b)) => (difference(a, b, &KEYS), ratios(a, b)),
            _ => Default::default(),
        };
        let (oneway_added_ns, oneway_ratio) = pair("oneway_chain", "oneway_direct");
        let (rtt_added_ns, rtt_ratio) = pair("rtt_chain", "rtt_direct");
        let n = used.len().max(1) as f64;
        Figures {
            selection,
            windows_used: used.len(),
            windows_total: total,
            steal_max: used.iter().map(|w| w.steal_fraction).fold(0.0, f64::max),
            steal_mean: used.iter().map(|w| w.steal_fraction).fold(0.0, |a, b| a + b) / n,
            steal_ms: used.iter().map(|w| w.steal_ms).sum(),
            others_mean: used.iter().map(|w| w.others_busy_cores).fold(0.0, |a, b| a + b) / n,
            others_max: used.iter().map(|w| w.others_busy_cores).fold(0.0, f64::max),
            dists,
            oneway_added_ns,
            rtt_added_ns,
            oneway_ratio,
            rtt_ratio,
        }
    }

    /// The host line of this selection.
    pub fn host_line(&self) -> String {
        format!(
            "{}: {} of {}; steal {:.2}% on average, {:.2}% in the worst window ({} ms in all); other processes kept {:.2} cores busy on average, {:.2} at most",
            self.selection.describe(),
            self.windows_used,
            self.windows_total,
            self.steal_mean * 100.0,
            self.steal_max * 100.0,
            self.steal_ms,
            self.others_mean,
            self.others_max
        )
    }

    /// This selection's table.
    pub fn write_md(&self, md: &mut String) {
        let _ = writeln!(md, "\n*{}*\n", self.host_line());
        if self.windows_used == 0 {
            return;
        }
        let _ = writeln!(md, "| | p50 | p90 | p99 | p99.9 | max | frames |\n|---|---|---|---|---|---|---|");
        for (k, label) in DISTS {
            if let Some(d) = self.dists.get(k) {
                let cells: Vec<String> = KEYS.iter().map(|key| fmt_ns(d.get(key).unwrap_or(0))).collect();
                let _ = writeln!(md, "| {label} | {} | {} |", cells.join(" | "), d.count);
            }
        }
        for (label, added, ratio) in [("one-way", &self.oneway_added_ns, &self.oneway_ratio), ("round trip", &self.rtt_added_ns, &self.rtt_ratio)] {
            if !added.is_empty() {
                let cells: Vec<String> = KEYS.iter().map(|k| ns(added[*k])).collect();
                let _ = writeln!(md, "| **{label}: through − direct** | {} | |", cells.join(" | "));
                let _ = writeln!(md, "| {label}: through / direct | {:.2}× | | {:.2}× | | | |", ratio["p50"], ratio["p99"]);
            }
        }
    }
}

fn ratios(a: &Summary, b: &Summary) -> BTreeMap<String, f64> {
    ["p50", "p99"].iter().map(|k| (k.to_string(), a.get(k).unwrap_or(0) as f64 / b.get(k).unwrap_or(0).max(1) as f64)).collect()
}

/// The emulator's own measurements over the whole part (its report):
/// rows of (label, summary).
pub fn emulator_rows(emulator: &Value) -> Vec<(String, Summary)> {
    let mut rows = Vec::new();
    let mut put = |label: &str, v: &Value| {
        if let Ok(s) = serde_json::from_value::<Summary>(v.clone()) {
            rows.push((label.to_string(), s));
        }
    };
    put("forward: decision (taken → fate)", &emulator["decision_ns"]);
    put("forward: release lateness (actual − scheduled)", &emulator["release_lateness_ns"]);
    put("feedback: decision", &emulator["feedback"]["decision_ns"]);
    put("feedback: release lateness", &emulator["feedback"]["release_lateness_ns"]);
    rows
}
