//! Headline figures: per transport and rate, the median over repetitions
//! of each percentile, the spread, and the bars of `docs/performance.md`
//! (reported, never asserted).

use crate::args::Settings;
use crate::chain::ChainResult;
use crate::floor::FloorResult;
use crate::{Results, Transport};
use netfi::metrics::{fmt_ns, Summary};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The percentiles and the maximum every table shows.
pub const KEYS: [&str; 6] = ["p50", "p90", "p99", "p999", "p9999", "max"];

/// Figures by transport (or scenario), then by rate in Hz.
pub type ByRate = BTreeMap<String, BTreeMap<String, Value>>;
/// One value per key of [`KEYS`].
pub type Map = BTreeMap<String, i64>;
/// `[min, max]` per key of [`KEYS`].
pub type Spread = BTreeMap<String, [i64; 2]>;

fn median(mut v: Vec<i64>) -> i64 {
    v.sort_unstable();
    if v.is_empty() {
        0
    } else {
        v[v.len() / 2]
    }
}

fn summary_map(s: &Summary) -> Map {
    KEYS.iter().filter_map(|k| Some((k.to_string(), s.get(k)? as i64))).collect()
}

/// Per percentile: the median over repetitions, and [min, max].
pub fn combine(maps: &[Map]) -> (Map, Spread) {
    let mut mid = BTreeMap::new();
    let mut spread = BTreeMap::new();
    for k in KEYS {
        let v: Vec<i64> = maps.iter().filter_map(|m| m.get(k).copied()).collect();
        if v.is_empty() {
            continue;
        }
        spread.insert(k.to_string(), [*v.iter().min().expect("non-empty"), *v.iter().max().expect("non-empty")]);
        mid.insert(k.to_string(), median(v));
    }
    (mid, spread)
}

/// [`combine`] over the summaries `f` picks from each item.
fn over<T>(items: &[&T], f: impl Fn(&T) -> Option<&Summary>) -> (Map, Spread) {
    combine(&items.iter().filter_map(|x| f(x).map(summary_map)).collect::<Vec<_>>())
}

/// A signed duration in the unit that reads best.
pub fn ns(v: i64) -> String {
    if v < 0 {
        format!("−{}", fmt_ns(v.unsigned_abs()))
    } else {
        fmt_ns(v as u64)
    }
}

/// One row of a percentile table.
pub fn row(label: &str, m: &Map) -> String {
    let cell = |k: &str| m.get(k).map_or("–".to_string(), |v| ns(*v));
    format!("| {label} | {} | {} | {} | {} | {} | {} |", cell("p50"), cell("p90"), cell("p99"), cell("p999"), cell("p9999"), cell("max"))
}

/// `1k`, `100k`, or the rate itself.
pub fn rate_label(rate_hz: f64) -> String {
    if rate_hz >= 1000.0 && (rate_hz / 1000.0).fract() == 0.0 {
        format!("{}k", rate_hz / 1000.0)
    } else {
        format!("{rate_hz}")
    }
}

/// Everything the report shows beyond the intervals themselves.
#[derive(Debug, Default)]
pub struct Figures {
    pub added: ByRate,
    pub added_spread: ByRate,
    pub chain: ByRate,
    pub direct: ByRate,
    pub floor: ByRate,
    pub lateness: ByRate,
    /// The latency and delay sections of `overhead.md`.
    pub md_latency: String,
    pub md_delay: String,
    pub bars: Vec<Value>,
    /// sockperf per variant (`as_configured`, `halt_polling_on`).
    pub sockperf: BTreeMap<String, Value>,
}

impl Figures {
    pub fn of(s: &Settings, res: &Results) -> Figures {
        let mut f = Figures::default();
        for t in Transport::ALL {
            for &rate in &s.rates_hz {
                f.latency(res, t, rate);
            }
        }
        f.delay(res);
        f.bars(s, res);
        f.sockperf(res);
        f
    }

    /// The Normal chain intervals of transport `t` at `rate`, and their
    /// floors.
    fn latency(&mut self, res: &Results, t: Transport, rate: f64) {
        let cs: Vec<&ChainResult> = res.chains.iter().filter(|c| c.transport == t && c.rate_hz == rate && c.scenario == "Normal").collect();
        let fs: Vec<&FloorResult> = res.floors.iter().filter(|f| f.transport == t && f.rate_hz == rate).collect();
        if cs.is_empty() {
            return;
        }
        let (key, name) = (format!("{}", rate as u64), t.name().to_string());
        let cell = Cell::of(&cs, &fs);
        let put = |m: &mut ByRate, v: Value| {
            m.entry(name.clone()).or_default().insert(key.clone(), v);
        };
        put(&mut self.added, json!(cell.added.0));
        put(&mut self.added_spread, json!(cell.added.1));
        put(&mut self.chain, json!({"median": cell.chain.0, "spread": cell.chain.1}));
        put(&mut self.direct, json!(cell.direct));
        put(&mut self.floor, json!(cell.floor));
        put(&mut self.lateness, json!({"median": cell.lateness.0, "spread": cell.lateness.1}));
        cell.write(&mut self.md_latency, t, rate, &cs, &fs);
    }

    /// The delay intervals (every chain interval not of Normal).
    fn delay(&mut self, res: &Results) {
        let delays: Vec<&ChainResult> = res.chains.iter().filter(|c| c.scenario != "Normal").collect();
        if delays.is_empty() {
            return;
        }
        let (la, la_spread) = over(&delays, |c| Some(&c.emulator.release_lateness_ns));
        let (ex, _) = over(&delays, |c| Some(&c.chain_ns));
        let (de, _) = over(&delays, |c| Some(&c.emulator.decision_ns));
        self.lateness.entry("iceoryx2 PLM-2 + DLM-2".into()).or_default().insert("1000".into(), json!({"median": la, "spread": la_spread}));
        let steal_max = delays.iter().map(|c| c.host.steal_fraction).fold(0.0, f64::max);
        let bg_max = delays.iter().map(|c| c.host.others_busy_cores).fold(0.0, f64::max);
        let md = &mut self.md_delay;
        let _ = writeln!(
            md,
            "\n**iceoryx2, PLM-2 then DLM-2, 1 k frames/s** ({} repetition(s); steal up to {:.2}%; other processes kept up to {:.2} cores busy during an interval)\n",
            delays.len(),
            steal_max * 100.0,
            bg_max
        );
        let _ = writeln!(md, "| | p50 | p90 | p99 | p99.9 | p99.99 | max |\n|---|---|---|---|---|---|---|");
        let _ = writeln!(md, "{}", row("release lateness (actual − scheduled)", &la));
        let _ = writeln!(md, "{}", row("decision (taken → fate)", &de));
        let _ = writeln!(md, "{}", row("end to end beyond the injected delay", &ex));
    }

    /// The bars of docs/performance.md but sockperf's.
    fn bars(&mut self, s: &Settings, res: &Results) {
        let get = |m: &ByRate, t: &str, r: &str, k: &str| m.get(t).and_then(|x| x.get(r)).and_then(|v| v.get(k)).and_then(Value::as_i64);
        let bars = &mut self.bars;
        if let Some(v) = get(&self.added, "iceoryx2", "1000", "p50") {
            bars.push(json!({"bar": "added latency p50 at 1 kHz (iceoryx2)", "value_ns": v, "limit_ns": 1000, "met": v <= 1000}));
        }
        if let Some(v) = get(&self.added, "iceoryx2", "1000", "p99") {
            bars.push(json!({"bar": "added latency p99 at 1 kHz (iceoryx2)", "value_ns": v, "limit_ns": 5000, "met": v <= 5000}));
        }
        for (t, by_rate) in &self.lateness {
            if let Some(v) = by_rate.get("1000").and_then(|x| x["median"]["p99"].as_i64()) {
                bars.push(json!({"bar": format!("release lateness p99 at 1 kHz ({t})"), "value_ns": v, "limit_ns": 5000, "met": v <= 5000}));
            }
        }
        for (k, v) in &res.throughput_fps {
            bars.push(json!({"bar": format!("throughput, {k}"), "value_fps": v, "limit_fps": 200_000, "met": *v >= 200_000.0}));
        }
        for (k, v) in &res.throughput {
            let c = &v["emulator_capacity"];
            if let (Some(cap), Some(bar)) = (c["capacity_fps"].as_f64(), c["bar_fps"].as_f64()) {
                bars.push(json!({"bar": format!("emulator capacity (busy time a frame), {k}"), "value_fps": cap, "limit_fps": bar as u64, "met": cap >= bar}));
            }
        }
        for (k, v) in &res.capacity {
            if let (Some(best), Some(bar)) = (v["best_fps"].as_f64(), v["bar_fps"].as_f64()) {
                bars.push(json!({"bar": format!("sustained {} s by the emulator alone (capacity part), {k}", v["trial_s"]), "value_fps": best, "limit_fps": bar as u64, "met": best >= bar}));
            }
        }
        for &rate in &s.rates_hz {
            let r = format!("{}", rate as u64);
            let ipc = self.chain.get("iceoryx2").and_then(|x| x.get(&r)).and_then(|v| v["median"]["p50"].as_i64());
            let udp = self.chain.get("udp").and_then(|x| x.get(&r)).and_then(|v| v["median"]["p50"].as_i64());
            if let (Some(i), Some(u)) = (ipc, udp) {
                let ratio = u as f64 / i.max(1) as f64;
                bars.push(json!({"bar": format!("chain p50, UDP over iceoryx2, at {} frames/s", rate_label(rate)), "value_ratio": ratio, "limit_ratio": 20, "met": ratio >= 20.0}));
            }
        }
    }

    /// sockperf: the median over repetitions of each percentile, and its bar.
    fn sockperf(&mut self, res: &Results) {
        for variant in ["as_configured", "halt_polling_on"] {
            let measured: Vec<&Value> = res.sockperfs.iter().filter(|v| v.get("skipped").is_none() && v["variant"] == variant).collect();
            if measured.is_empty() {
                continue;
            }
            let fig = |k: &str| {
                let maps: Vec<Map> = measured.iter().filter_map(|v| serde_json::from_value(v[k].clone()).ok()).collect();
                let (median, spread) = combine(&maps);
                json!({"median": median, "spread": spread})
            };
            let mut f = json!({"direct_ns": fig("direct_ns"), "through_netfi_ns": fig("through_netfi_ns"), "added_ns": fig("added_ns")});
            if let Some(v) = f["added_ns"]["median"]["p50"].as_i64() {
                let halt = measured[0]["guest_halt_poll_ns"].as_u64().map_or("unknown".to_string(), |n| format!("{n} ns"));
                self.bars.push(json!({"bar": format!("sockperf ping-pong through the UDP bridge, added latency p50 (raw, Normal; guest halt polling {halt})"), "value_ns": v, "limit_ns": 10_000, "met": v <= 10_000}));
            }
            f["guest_halt_poll_ns"] = measured[0]["guest_halt_poll_ns"].clone();
            f["repetitions"] = json!(measured.len());
            self.sockperf.insert(variant.to_string(), f);
        }
    }
}

/// The combined figures of one transport and rate.
struct Cell {
    added: (Map, Spread),
    chain: (Map, Spread),
    direct: Map,
    floor: Map,
    lateness: (Map, Spread),
    hop1: Map,
    inside: Map,
    hop2: Map,
}

impl Cell {
    fn of(cs: &[&ChainResult], fs: &[&FloorResult]) -> Cell {
        Cell {
            added: combine(&cs.iter().map(|c| c.added_ns.clone()).collect::<Vec<_>>()),
            chain: over(cs, |c| Some(&c.chain_ns)),
            direct: over(cs, |c| Some(&c.direct_ns)).0,
            floor: over(fs, |f| Some(&f.hop_ns)).0,
            lateness: over(cs, |c| Some(&c.emulator.release_lateness_ns)),
            hop1: over(cs, |c| c.hop1_ns.as_ref()).0,
            inside: over(cs, |c| c.inside_ns.as_ref()).0,
            hop2: over(cs, |c| c.hop2_ns.as_ref()).0,
        }
    }

    /// This cell's table of `overhead.md`.
    fn write(&self, md: &mut String, t: Transport, rate: f64, cs: &[&ChainResult], fs: &[&FloorResult]) {
        let steal_max = cs.iter().map(|c| c.host.steal_fraction).chain(fs.iter().map(|f| f.host.steal_fraction)).fold(0.0, f64::max);
        let bg_max = cs.iter().map(|c| c.host.others_busy_cores).chain(fs.iter().map(|f| f.host.others_busy_cores)).fold(0.0, f64::max);
        let _ = writeln!(
            md,
            "\n**{} at {} frames/s** ({} repetition(s); steal up to {:.2}%; other processes kept up to {:.2} cores busy during an interval)\n",
            t.name(),
            rate_label(rate),
            cs.len(),
            steal_max * 100.0,
            bg_max
        );
        let _ = writeln!(md, "| one-way latency | p50 | p90 | p99 | p99.9 | p99.99 | max |\n|---|---|---|---|---|---|---|");
        if !self.floor.is_empty() {
            let _ = writeln!(md, "{}", row("floor: one cross-core hop, no emulator", &self.floor));
        }
        let _ = writeln!(md, "{}", row("direct, alternating with the chain", &self.direct));
        let _ = writeln!(md, "{}", row("chain through the emulator", &self.chain.0));
        let _ = writeln!(md, "{}", row("**added = chain − direct**", &self.added.0));
        if !self.hop1.is_empty() {
            let _ = writeln!(md, "{}", row("chain: hop 1 (send → taken by the emulator)", &self.hop1));
            let _ = writeln!(md, "{}", row("chain: inside the emulator (taken → released)", &self.inside));
            let _ = writeln!(md, "{}", row("chain: hop 2 (released → received)", &self.hop2));
        }
        let _ = writeln!(md, "{}", row("emulator release lateness", &self.lateness.0));
        if cs.len() > 1 {
            let (a, ch) = (&self.added.1, &self.chain.1);
            let _ = writeln!(
                md,
                "\nSpread over repetitions (min – max): added p50 {} – {}, p99 {} – {}; chain p50 {} – {}.",
                ns(a["p50"][0]),
                ns(a["p50"][1]),
                ns(a["p99"][0]),
                ns(a["p99"][1]),
                ns(ch["p50"][0]),
                ns(ch["p50"][1])
            );
        }
    }
}
