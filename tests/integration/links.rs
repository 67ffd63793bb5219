//! The link stages (`rate`, `trace`) and `replay` through the injector in
//! simulated time, checked exactly (docs/spec.md §3.12–3.14).
//!
//! The shared Mahimahi traces are looked for at `../shared/data/traces/`
//! beside the repository; the tests that use them skip, saying so, when it
//! is absent (fail, where `NETFI_REQUIRE_DATA` is set:
//! [`crate::common::data`]).

use crate::common::netfi::{netfi, Outcome};
use crate::common::data;
use crate::common::machine;
use crate::common::scratch::Scratch;
use netfi::injector::{Fate, Injector};
use netfi::model::Schedule;
use netfi::scenario::{parse_str, Scenario};
use std::path::Path;

fn injector(text: &str) -> Injector<()> {
    let spec = parse_str(text, "test.toml", "test").unwrap_or_else(|e| panic!("{e}"));
    Injector::new(Scenario::new(&spec, 1).unwrap(), 1 << 20)
}

#[test]
fn a_saturated_rate_link_delivers_its_rate() {
    let _machine = machine::not_beside_a_run();
    // 10 Mbit/s, offered 124-byte frames every 50 µs (19.8 Mbit/s) for 10 s.
    let rate = 10_000_000u64;
    let mut inj = injector(&format!("[[stage]]\nmodel = \"rate\"\nrate_bit_s = {rate}\n"));
    let (from_ns, to_ns) = (1_000_000_000u64, 10_000_000_000u64);
    let mut bytes_in_window = 0u64;
    let count = |r: netfi::scheduler::Released<()>, bytes: &mut u64| {
        if r.release_ns > from_ns && r.release_ns <= to_ns {
            *bytes += 124;
        }
    };
    for i in 0..(to_ns / 50_000) {
        let t = i * 50_000;
        while let Some(r) = inj.pop_due(t) {
            count(r, &mut bytes_in_window);
        }
        inj.ingress(t, ());
    }
    while let Some(r) = inj.pop_due(u64::MAX) {
        count(r, &mut bytes_in_window);
    }
    let carried = bytes_in_window as f64 * 8.0 / ((to_ns - from_ns) as f64 / 1e9);
    let error = (carried - rate as f64).abs() / rate as f64;
    // Exact time: the only error is the frame cut at each end of the window.
    assert!(error < 0.005, "carried {carried} bit/s of {rate}: error {error}");
    assert!(error < 2.0 * 124.0 * 8.0 / 9.0 / rate as f64 + 1e-12, "carried {carried} bit/s of {rate}");
    let c = inj.counts();
    assert!(c.dropped_by_stage > 0 && c.balanced(), "{c:?}");
    assert_eq!(inj.drops_by_reason(), vec![("link_queue", c.dropped_by_stage)]);
}

/// Lindley's recursion in exact integers: the work ahead of each frame at
/// its arrival, in bit·ns per s units (bits × 10^9), and the delay it gets:
/// that backlog plus its own bits, over the rate, rounded up to the ns.
fn reference_delays(arrivals_ns: &[u64], bits: u128, rate: u128) -> Vec<u64> {
    let mut work: u128 = 0;
    let mut last = arrivals_ns[0];
    arrivals_ns
        .iter()
        .map(|&a| {
            work = work.saturating_sub(rate * u128::from(a - last));
            last = a;
            let delay = (work + bits * 1_000_000_000).div_ceil(rate);
            work += bits * 1_000_000_000;
            delay as u64
        })
        .collect()
}

#[test]
fn with_deterministic_arrivals_the_queueing_delay_is_the_backlog_over_the_rate() {
    let _machine = machine::not_beside_a_run();
    // Bursts of five frames every 2 ms, at rates that divide evenly and not.
    let arrivals: Vec<u64> = (0..2_000u64).map(|i| 3_000 + (i / 5) * 2_000_000).collect();
    for rate in [1_000_000u64, 3_000_000, 8_000_000, 2_999_999] {
        let mut inj = injector(&format!("[[stage]]\nmodel = \"rate\"\nrate_bit_s = {rate}\nqueue_packets = 100000\n"));
        let got: Vec<u64> = arrivals
            .iter()
            .map(|&t| match inj.ingress(t, ()).fate {
                Fate::Scheduled { delay_ns, .. } => delay_ns,
                f => panic!("{f:?}"),
            })
            .collect();
        let want = reference_delays(&arrivals, 124 * 8, u128::from(rate));
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(g, w, "rate {rate}: frame {k}");
        }
        // At 1 Mbit/s the link is behind: the last burst waits for seconds.
        if rate == 1_000_000 {
            assert!(want[want.len() - 1] > 1_000_000_000);
        }
    }
}

/// Bytes the link delivered in each second after the trace's start, against
/// what its opportunities allow, for payloads of `payload` bytes offered
/// every `spacing_ns` (faster than the link) for `seconds`.
fn per_second_against_trace(schedule: &Schedule, file: &Path, payload: u64, spacing_ns: u64, seconds: u64) -> Vec<(i64, u64)> {
    let text = format!(
        "[[stage]]\nmodel = \"trace\"\nfile = \"{}\"\npayload_bytes = {payload}\nqueue_packets = 100000\n",
        file.file_name().unwrap().to_str().unwrap()
    );
    let files = netfi::load::DirFiles::new(file.parent().unwrap());
    let spec = netfi::scenario::parse_str_with(&text, "test.toml", "test", &files).unwrap_or_else(|e| panic!("{e}"));
    let mut inj: Injector<()> = Injector::new(Scenario::new(&spec, 1).unwrap(), 1 << 20);
    let base = 5_000_000u64;
    let mut delivered = vec![0u64; seconds as usize + 1];
    let mut record = |r: netfi::scheduler::Released<()>| {
        let s = ((r.release_ns - base) / 1_000_000_000) as usize;
        if s < delivered.len() {
            delivered[s] += payload;
        }
    };
    for i in 0..(seconds * 1_000_000_000 / spacing_ns) {
        let t = base + i * spacing_ns;
        while let Some(r) = inj.pop_due(t) {
            record(r);
        }
        inj.ingress(t, ());
    }
    while let Some(r) = inj.pop_due(u64::MAX) {
        record(r);
    }
    // Opportunities in [base + s, base + s + 1 s): the trace's time 0 is the
    // first frame's arrival.
    let mut allowed = vec![0u64; seconds as usize];
    for k in 0.. {
        let ms = schedule.at_ms(k);
        if ms >= seconds * 1_000 {
            break;
        }
        allowed[(ms / 1_000) as usize] += netfi::model::linktrace::MM_OPPORTUNITY_BYTES;
    }
    (0..seconds as usize).map(|s| (delivered[s] as i64 - allowed[s] as i64, allowed[s])).collect()
}

#[test]
fn a_synthetic_trace_link_delivers_per_second_what_the_trace_allows() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("links-synthetic");
    // A capacity that changes every 100 ms: 0 to 3 opportunities per ms
    // over a 700 ms period, with silent stretches.
    let mut lines = Vec::new();
    for ms in 1..=700u64 {
        for _ in 0..((ms / 100) % 4) {
            lines.push(ms.to_string());
        }
    }
    lines.push("700".into());
    let text = lines.join("\n") + "\n";
    let file = dir.0.join("steps.up");
    std::fs::write(&file, &text).unwrap();
    let schedule = Schedule::parse(&text).unwrap();
    for (payload, spacing_ns) in [(124u64, 20_000u64), (1500, 200_000)] {
        for (s, (diff, allowed)) in per_second_against_trace(&schedule, &file, payload, spacing_ns, 6).into_iter().enumerate() {
            assert!(diff.unsigned_abs() <= 1500, "payload {payload}, second {s}: {diff} bytes off the {allowed} allowed");
        }
    }
}

#[test]
fn a_cellular_trace_link_delivers_per_second_what_the_trace_allows() {
    let _machine = machine::not_beside_a_run();
    let Some(file) = data::trace("TMobile-LTE-short.up") else { return };
    let schedule = Schedule::parse(&std::fs::read_to_string(&file).unwrap()).unwrap();
    // 1500-byte payloads every 40 µs: 300 Mbit/s, beyond the trace's peaks.
    for (s, (diff, allowed)) in per_second_against_trace(&schedule, &file, 1500, 40_000, 8).into_iter().enumerate() {
        assert!(diff.unsigned_abs() <= 1500, "second {s}: {diff} bytes off the {allowed} allowed");
    }
}

#[test]
fn replaying_a_trace_csv_reproduces_its_fates_exactly() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("links-replay");
    // A recorded run: losses, a reordering jitter, a bottleneck.
    let recorded = "[[stage]]\nmodel = \"bernoulli\"\np = 0.1\n[[stage]]\nmodel = \"jitter\"\nmean_ms = 20\nsd_ms = 5\ndist = \"normal\"\n[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1e6\nqueue_packets = 20\n";
    let arrivals: Vec<u64> = (0..20_000u64).map(|i| 1_000 + i * 1_000_000 + (i % 7) * 13_000).collect();
    let mut inj = injector(recorded);
    let mut rows = Vec::new();
    let mut fates = Vec::new();
    for &t in &arrivals {
        let e = inj.ingress(t, ());
        let (dropped, release_sched_ns) = match e.fate {
            Fate::Scheduled { release_ns, .. } => (None, release_ns),
            Fate::Dropped(c) => (Some(c), 0),
        };
        rows.push(netfi::trace::Row { present: true, ingress_ns: t, dropped, release_sched_ns, ..Default::default() });
        fates.push(e.fate);
    }
    assert!(fates.iter().any(|f| matches!(f, Fate::Dropped(_))));
    netfi::trace::write_csv(&dir.0.join("trace.csv"), &rows, &[]).unwrap();
    let scenario = dir.0.join("again.toml");
    std::fs::write(&scenario, "[[stage]]\nmodel = \"replay\"\nfile = \"trace.csv\"\n").unwrap();
    let spec = netfi::load::parse_file(&scenario).unwrap_or_else(|e| panic!("{e}"));
    let mut again: Injector<()> = Injector::new(Scenario::new(&spec, 99).unwrap(), 1 << 20);
    for (k, (&t, want)) in arrivals.iter().zip(&fates).enumerate() {
        let got = again.ingress(t, ()).fate;
        match (want, got) {
            (Fate::Scheduled { release_ns: a, .. }, Fate::Scheduled { release_ns: b, .. }) => assert_eq!(a, &b, "frame {k}"),
            (Fate::Dropped(_), Fate::Dropped(c)) => assert_eq!(c.reason(), "replay", "frame {k}"),
            _ => panic!("frame {k}: recorded {want:?}, replayed {got:?}"),
        }
    }
}

#[test]
fn a_delay_capture_replays_the_delays_it_carries() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("links-capture");
    let path = dir.0.join("trial.bin");
    let frame = netfi::check::synthetic_frame();
    let mut w = netfi::capture::CaptureWriter::create(&path).unwrap();
    let delays = [0.25f32, 0.3125, 0.0, 1.5];
    for (i, d) in delays.iter().enumerate() {
        w.write_delay_record(i as u64 * 1_000_000, *d, &frame).unwrap();
    }
    w.finish().unwrap();
    assert_eq!(netfi::capture::load(&path).unwrap().layout, netfi::capture::RecordLayout::Delay);
    let scenario = dir.0.join("trial.toml");
    std::fs::write(&scenario, "[[stage]]\nmodel = \"replay\"\nfile = \"trial.bin\"\n").unwrap();
    let spec = netfi::load::parse_file(&scenario).unwrap_or_else(|e| panic!("{e}"));
    let mut inj: Injector<()> = Injector::new(Scenario::new(&spec, 1).unwrap(), 64);
    for (i, d) in delays.iter().chain(&delays).enumerate() {
        match inj.ingress(i as u64 * 1_000_000, ()).fate {
            Fate::Scheduled { delay_ns, .. } => assert_eq!(delay_ns, (f64::from(*d) * 1e9).round() as u64, "frame {i}"),
            f => panic!("{f:?}"),
        }
    }
    // A capture without delays is refused, saying why.
    let plain = dir.0.join("plain.bin");
    let mut w = netfi::capture::CaptureWriter::create(&plain).unwrap();
    w.write_raw(0, 0, &frame).unwrap();
    w.finish().unwrap();
    std::fs::write(&scenario, "[[stage]]\nmodel = \"replay\"\nfile = \"plain.bin\"\n").unwrap();
    let e = netfi::load::parse_file(&scenario).unwrap_err();
    assert!(e.to_string().contains("records no delays"), "{e}");
}


#[test]
fn scenario_check_reports_the_link() {
    let _machine = machine::not_beside_a_run();
    let v = netfi().args(["scenario", "check", "config/scenarios/rate_bottleneck.toml", "--frames", "20000", "--json"]).json();
    let link = &v["links"][0];
    assert_eq!(link["model"], "rate");
    assert_eq!(link["capacity_bit_s"].as_f64(), Some(1e6));
    // Offered 1.33 Mbit/s on the wire: the link is busy from the first
    // frame to the last departure, and drops what its 50 packets cannot hold.
    assert!(link["utilisation"].as_f64().unwrap() > 0.999, "{link}");
    assert_eq!(link["queue_packets_max"], 50);
    let dropped = v["dropped"]["link_queue"].as_u64().unwrap();
    assert_eq!(link["frames_dropped"].as_u64(), Some(dropped));
    assert_eq!(v["delivered"].as_u64().unwrap() + dropped, 20_000);
    // 20 s of frames: one occupancy entry per second.
    assert_eq!(link["occupancy"].as_array().unwrap().len(), 20);
    // Full queue: 50 packets of 166 bytes at 1 Mbit/s, 66.4 ms.
    let p99 = link["delay_ms"]["p99"].as_f64().unwrap();
    assert!((p99 - 50.0 * 1.328).abs() < 0.1, "{p99}");
    let table = netfi().args(["scenario", "check", "config/scenarios/rate_bottleneck.toml", "--frames", "2000"]).output().unwrap();
    let table = String::from_utf8_lossy(&table.stdout);
    assert!(table.contains("utilisation") && table.contains("queue over time"), "{table}");
}

#[test]
fn show_and_export_speak_of_the_link_stages() {
    let _machine = machine::not_beside_a_run();
    let out = netfi().args(["scenario", "show", "config/scenarios/rate_bottleneck.toml"]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("model = \"rate\"") && text.contains("# phase 1 stage `rate#0`: rate 1000000 bit/s"), "{text}");
    let out = netfi().args(["export", "netem", "config/scenarios/rate_bottleneck.toml"]).output().unwrap();
    let script = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(script.contains("netem limit 50 rate 1000000bit\n"), "{script}");

    let dir = Scratch::new("links-cli");
    std::fs::write(dir.0.join("one.up"), "1\n").unwrap();
    std::fs::write(dir.0.join("bad.up"), "1\n2\nten\n").unwrap();
    let scenario = dir.0.join("t.toml");
    std::fs::write(&scenario, "[[stage]]\nmodel = \"trace\"\nfile = \"one.up\"\n").unwrap();
    let path = scenario.to_str().unwrap();
    let show = String::from_utf8_lossy(&netfi().args(["scenario", "show", path]).output().unwrap().stdout).into_owned();
    assert!(show.contains("trace of 1 opportunities of 1504 bytes every 1 ms (mean 12.032 Mbit/s)"), "{show}");
    let out = netfi().args(["export", "netem", path]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot follow a link trace"));
    std::fs::write(&scenario, "name = \"x\"\n\n[[stage]]\nmodel = \"trace\"\nfile = \"bad.up\"\n").unwrap();
    let out = netfi().args(["scenario", "check", path]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("t.toml:5") && err.contains("`bad.up` line 3: not a time") && !err.contains("ten"), "{err}");
}

#[test]
fn shipped_scenarios_that_read_files_parse_build_run_and_print_back() {
    let _machine = machine::not_beside_a_run();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenarios/files");
    let files = netfi::load::DirFiles::new(&dir);
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        // (`../../../../shared/data/` from this folder is `data::dir()`.)
        if text.contains("shared/data/") && data::or_skip("traces", &format!("the shared Mahimahi traces {} reads", path.display())).is_none() {
            continue;
        }
        let s = netfi::load::parse_file(&path).unwrap_or_else(|e| panic!("{e}"));
        let sc = Scenario::new(&s, s.seed.unwrap_or(1)).unwrap_or_else(|e| panic!("{e}"));
        let r = netfi::check::run(sc, &netfi::check::Arrivals::Rate { frames: 20_000, rate_hz: 1000.0 }, 1 << 16, |_| {});
        assert_eq!(r.frames, r.delivered + r.dropped.values().sum::<u64>(), "{}", path.display());
        assert!(!r.links.is_empty(), "{}", path.display());
        let again = netfi::scenario::parse_str_with(&s.to_toml(), "again", "again", &files).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(again.phases, s.phases, "{}", path.display());
        n += 1;
    }
    assert!(n >= 1, "found no scenario in {}", dir.display());
}

/// mm-link's `LinkQueue` (Mahimahi, `src/frontend/link_queue.cc`) as it is
/// written, with a drop-tail packet limit as its `DroppingPacketQueue`: time
/// in whole ms, opportunities spent up to `now` before a packet is queued.
/// Returns each packet's departure ms, or `None` if dropped.
fn mm_link(schedule: &[u64], arrivals: &[(u64, i64)], limit: usize) -> Vec<Option<u64>> {
    let period = *schedule.last().unwrap();
    let (mut next, mut base) = (0usize, 0u64);
    let mut queue: std::collections::VecDeque<(usize, i64)> = Default::default();
    let mut in_transit: Option<(usize, i64)> = None;
    let mut out = vec![None; arrivals.len()];
    let mut rationalize = |now: u64, queue: &mut std::collections::VecDeque<(usize, i64)>, out: &mut Vec<Option<u64>>| {
        while schedule[next] + base <= now {
            let this = schedule[next] + base;
            let mut left: i64 = 1504;
            next = (next + 1) % schedule.len();
            if next == 0 {
                base += period;
            }
            while left > 0 {
                if in_transit.is_none() {
                    in_transit = queue.pop_front();
                    if in_transit.is_none() {
                        break;
                    }
                }
                let p = in_transit.as_mut().unwrap();
                p.1 -= left;
                left = 0;
                if p.1 <= 0 {
                    left = -p.1;
                    out[p.0] = Some(this);
                    in_transit = None;
                }
            }
        }
    };
    for (id, &(ms, bytes)) in arrivals.iter().enumerate() {
        rationalize(ms, &mut queue, &mut out);
        if queue.len() < limit {
            queue.push_back((id, bytes));
        }
    }
    // Long enough for the queue to drain (the trace repeats for ever).
    rationalize(arrivals.last().unwrap().0 + 1_000_000, &mut queue, &mut out);
    out
}

#[test]
fn a_trace_link_departs_every_packet_when_mm_link_does() {
    use netfi::model::{LinkTrace, LinkTraceParams, Verdict};
    let _machine = machine::not_beside_a_run();
    let trace = [2u64, 2, 3, 7, 7, 7, 8, 12, 15, 15];
    let schedule = Schedule::from_ms(&trace).unwrap();
    // Bursts of packets of assorted sizes (up to one opportunity, as mm-link
    // requires) at whole ms, some during silences of the trace.
    let mut arrivals = vec![(0u64, 1000i64)];
    let mut x = 12345u64;
    for ms in 0..400u64 {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        for j in 0..(x >> 61) {
            arrivals.push((ms, 40 + ((x >> (20 + 3 * j)) % 1465) as i64));
        }
    }
    for limit in [usize::MAX, 6] {
        let want = mm_link(&trace, &arrivals, limit);
        let mut p = LinkTraceParams::new("t", schedule.clone());
        p.mtu_bytes = 1504;
        p.queue_packets = Some(if limit == usize::MAX { 1 << 20 } else { limit as u64 });
        let mut link = LinkTrace::new(&p).unwrap();
        // The trace's time 0 is the first arrival: 0 ms here, as for mm-link.
        for (k, &(ms, bytes)) in arrivals.iter().enumerate() {
            let got = match link.decide_len(ms * 1_000_000, bytes as u64) {
                Verdict::Pass { delay_ns } => Some((ms * 1_000_000 + delay_ns) / 1_000_000),
                Verdict::Drop => None,
                v => panic!("{v:?}"),
            };
            assert_eq!(got, want[k], "limit {limit}: packet {k} of {bytes} bytes at {ms} ms");
        }
        assert!(limit == usize::MAX || want.iter().any(Option::is_none), "the limit must bite");
    }
}

/// What a link's queue does at a phase boundary and at a live switch
/// (docs/spec.md §3.12, "Phases and live switches"): each phase has its own
/// link, which starts empty; the old phase's packets keep their departure
/// times; an ordered (`fifo`) release queue still holds a frame behind the
/// one before it, a `reorder` queue lets it overtake.
#[test]
fn a_link_queue_starts_empty_in_each_phase_and_after_a_switch() {
    use netfi::scheduler::QueueOrder;
    let _machine = machine::not_beside_a_run();
    // 1 Mbit/s, 124 + 42 wire bytes a frame: 1.328 ms each. Frames every
    // 0.5 ms keep it busy from the first: frame k leaves at (k + 1)·1.328 ms.
    let link = "model = \"rate\"\nrate_bit_s = 1_000_000\noverhead_bytes = 42\nqueue_packets = 5000\n";
    let serialization_ns = 1_328_000u64;
    let backlogged_ns = |k: u64| (k + 1) * serialization_ns - k * 500_000;
    let two_phases = format!("[[phase]]\n[[phase.stage]]\n{link}[[phase]]\nstart_s = 1\n[[phase.stage]]\n{link}");
    let one_phase = format!("[[stage]]\n{link}");
    let build = |text: &str, order| {
        let spec = parse_str(text, "test.toml", "test").unwrap_or_else(|e| panic!("{e}"));
        let mut sc = Scenario::new(&spec, 1).unwrap();
        sc.reserve_phases(4);
        (Injector::<()>::try_with_order(sc, 1 << 16, order).unwrap(), spec)
    };
    let release = |inj: &mut Injector<()>, t: u64| match inj.ingress(t, ()).fate {
        Fate::Scheduled { release_ns, .. } => release_ns,
        f => panic!("{f:?}"),
    };
    for order in [QueueOrder::Reorder, QueueOrder::Fifo] {
        // A phase boundary at 1 s, and a live switch (to the same scenario) at 1 s.
        for switch in [false, true] {
            let (mut inj, spec) = build(if switch { &one_phase } else { &two_phases }, order);
            let mut sampler = netfi::check::LinkSampler::new(inj.scenario(), 8);
            let mut last = 0;
            for k in 0..2000u64 {
                last = release(&mut inj, k * 500_000);
                sampler.sample(inj.scenario(), k * 500_000);
                assert_eq!(last - k * 500_000, backlogged_ns(k), "frame {k}");
            }
            if switch {
                let timeline = netfi::scenario::Timeline::new(&spec, 0).unwrap();
                inj.switch(1_000_000_000, None, timeline).unwrap();
            }
            // The old link still has 1.66 s of backlog; the new one is empty.
            let first_new = release(&mut inj, 1_000_000_000);
            sampler.sample(inj.scenario(), 1_000_000_000);
            let second_new = release(&mut inj, 1_000_500_000);
            sampler.sample(inj.scenario(), 1_000_500_000);
            match order {
                QueueOrder::Reorder => {
                    assert_eq!(first_new, 1_000_000_000 + serialization_ns, "switch {switch}");
                    assert_eq!(second_new, 1_000_000_000 + 2 * serialization_ns, "switch {switch}");
                }
                QueueOrder::Fifo => assert_eq!((first_new, second_new), (last, last), "switch {switch}"),
            }
            // Each link reports the frames that reached it; the old one's
            // queue is not sampled after its phase (its series ends in second
            // 0), the new one's starts in second 1 with its own frames. A
            // link switched in live has no series (the sampler follows the
            // links the run started with).
            let links = sampler.reports(inj.scenario());
            assert_eq!(links.iter().map(|l| (l.phase, l.frames)).collect::<Vec<_>>(), [(1, 2000), (2, 2)], "switch {switch}");
            assert_eq!(links[0].occupancy.iter().map(|o| o.second).collect::<Vec<_>>(), [0], "switch {switch}");
            let new_series: Vec<_> = links[1].occupancy.iter().map(|o| (o.second, o.packets_max)).collect();
            assert_eq!(new_series, if switch { vec![] } else { vec![(1, 2)] }, "switch {switch}");
        }
    }
}

/// The delivered frames' `delay_ns` of a `scenario check --trace` file, in
/// file order.
fn trace_delays(path: &Path) -> Vec<u64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let cols: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at = |name: &str| cols.iter().position(|c| *c == name).unwrap();
    let (fate, delay) = (at("fate"), at("delay_ns"));
    lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| c[fate] == "delivered")
        .map(|c| c[delay].parse().unwrap())
        .collect()
}

/// The value of rank `max(1, ⌈q·n⌉)` of `values`, sorted.
fn nearest_rank(sorted: &[u64], q: f64) -> u64 {
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

/// A trace link whose frames wait years (one opportunity every 41.7 days,
/// 2 000 frames at 1 kHz): every figure is the exact one or says how close
/// it is. The check's p50 and p99 are the trace's own delays at their
/// ranks (they were clamped to 86 449 101.7 ms, a day, before), and the
/// link's time-at-stage percentiles lie within their stated precision of
/// them (clamped to 4.4·10⁶ ms, an hour, before).
#[test]
fn a_trace_link_whose_frames_wait_years_reports_exact_delays() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("links-slow");
    std::fs::write(dir.0.join("slow.up"), "5\n3600000000\n").unwrap();
    std::fs::write(dir.0.join("slow.toml"), "[[stage]]\nmodel = \"trace\"\nfile = \"slow.up\"\n").unwrap();
    let csv = dir.0.join("trace.csv");
    let v = netfi().args(["scenario", "check", dir.0.join("slow.toml").to_str().unwrap(), "--frames", "2000", "--seed", "1", "--json", "--trace", csv.to_str().unwrap()]).json();
    let mut delays = trace_delays(&csv);
    delays.sort_unstable();
    let year_ns = 31_557_600_000_000_000u64;
    assert!(delays.len() > 900 && delays[delays.len() / 2] > year_ns, "{} delays, median {}", delays.len(), delays[delays.len() / 2]);
    let ms = |ns: u64| ns as f64 / 1e6;
    let d = &v["delay_ms"];
    assert_eq!(d["p50"].as_f64(), Some(ms(nearest_rank(&delays, 0.5))), "{d}");
    assert_eq!(d["p99"].as_f64(), Some(ms(nearest_rank(&delays, 0.99))), "{d}");
    assert_eq!(d["max"].as_f64(), Some(ms(delays[delays.len() - 1])), "{d}");
    assert!(d.get("error_fraction_max").is_none(), "exact figures carry no error bound: {d}");
    let link = &v["links"][0]["delay_ms"];
    let bound = link["error_fraction_max"].as_f64().unwrap();
    assert_eq!(bound, 1.0 / 1024.0);
    for (key, q) in [("p50", 0.5), ("p90", 0.9), ("p99", 0.99)] {
        let exact = ms(nearest_rank(&delays, q));
        let got = link[key].as_f64().unwrap();
        assert!(got >= exact && got <= exact * (1.0 + bound), "link {key} {got} ms, exact {exact} ms");
    }
    let table = netfi().args(["scenario", "check", dir.0.join("slow.toml").to_str().unwrap(), "--frames", "2000", "--seed", "1"]).output().unwrap();
    let table = String::from_utf8_lossy(&table.stdout);
    assert!(table.contains("(each at most 0.098 % high)"), "{table}");
}

/// Each link section agrees with the frames' fates: a frame the link
/// admitted and something later dropped (a later stage, the release queue
/// full, for an original or a copy) is counted as dropped after the link,
/// and what the link passed on is what the rest of the pipeline got.
#[test]
fn a_link_section_agrees_with_the_frames_fates() {
    use netfi::check::{run, Arrivals};
    let _machine = machine::not_beside_a_run();
    let check = |text: &str, capacity: usize| {
        let spec = parse_str(text, "test.toml", "test").unwrap_or_else(|e| panic!("{e}"));
        run(Scenario::new(&spec, 3).unwrap(), &Arrivals::Rate { frames: 20_000, rate_hz: 1000.0 }, capacity, |_| {})
    };
    let fast = "[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1e9\n";
    // The release queue holds 16 frames and a 50 ms delay holds 50: most
    // frames pass the link and are refused by the queue.
    let r = check(&format!("{fast}[[stage]]\nmodel = \"delay\"\nmin_ms = 50\n"), 16);
    let (link, full) = (&r.links[0], r.dropped["queue_full"]);
    assert!(full > 10_000, "{:?}", r.dropped);
    assert_eq!((link.frames, link.frames_dropped, link.frames_dropped_after), (20_000, 0, full));
    assert_eq!(link.frames - link.frames_dropped_after, r.delivered);
    assert!(link.frames_text().contains(&format!("{full} dropped after the link")), "{}", link.frames_text());
    // A loss stage after the link.
    let r = check(&format!("{fast}[[stage]]\nmodel = \"bernoulli\"\np = 0.3\n"), 1 << 16);
    assert_eq!(r.links[0].frames_dropped_after, r.dropped["bernoulli"]);
    assert_eq!(r.links[0].frames - r.links[0].frames_dropped_after, r.delivered);
    // Copies made before the link cross it too; those the queue refuses
    // are dropped after it, as are originals.
    let r = check(&format!("[[stage]]\nmodel = \"duplicate\"\np = 0.5\n{fast}[[stage]]\nmodel = \"delay\"\nmin_ms = 50\n"), 16);
    let link = &r.links[0];
    assert_eq!(link.frames, 20_000 + r.duplicated);
    assert_eq!(link.frames_dropped_after, r.dropped["queue_full"]);
    assert_eq!(link.frames - link.frames_dropped_after, r.delivered);
    // Copies made after the link: the original crossed it once and went
    // on (the copy refused by the queue is not the link's frame), unless
    // the original itself was refused.
    let r = check(&format!("{fast}[[stage]]\nmodel = \"duplicate\"\np = 1\n[[stage]]\nmodel = \"delay\"\nmin_ms = 50\n"), 16);
    let link = &r.links[0];
    assert_eq!(link.frames, 20_000);
    assert!(link.frames_dropped_after <= r.dropped["queue_full"] && link.frames_dropped_after > 0, "{link:?} {:?}", r.dropped);
}

/// A replay stage names the recording it replays and the layout it read
/// it in, in `scenario check`'s JSON and table: a delay capture written in
/// batches of 1 000 records (as the study's tool writes them), and a
/// `trace.csv`.
#[test]
fn a_replay_stage_names_the_layout_it_read() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("links-layout");
    let frame = netfi::check::synthetic_frame();
    let mut w = netfi::capture::CaptureWriter::create(dir.0.join("trial.bin")).unwrap();
    let delays: Vec<f32> = (0..2_500u32).map(|i| 0.2 + (i % 97) as f32 * 1e-3).collect();
    for (i, d) in delays.iter().enumerate() {
        if i > 0 && i % 1_000 == 0 {
            w.end_frame().unwrap();
        }
        w.write_delay_record(i as u64 * 1_000_000, *d, &frame).unwrap();
    }
    w.finish().unwrap();
    std::fs::write(dir.0.join("trial.toml"), "[[stage]]\nmodel = \"replay\"\nfile = \"trial.bin\"\n").unwrap();
    let scenario = dir.0.join("trial.toml");
    let v = netfi().args(["scenario", "check", scenario.to_str().unwrap(), "--frames", "5000", "--json"]).json();
    let rec = &v["stages"][0]["recording"];
    assert_eq!(rec["kind"], "delay capture");
    assert_eq!(rec["layout"], "time | length | delay (s) | frame");
    assert_eq!((rec["file"].as_str(), rec["fates"].as_u64(), rec["wraps"].as_u64()), (Some("trial.bin"), Some(2_500), Some(1)));
    // Every recorded delay, in order, twice (started again once): the
    // exact median of them.
    let mut ns: Vec<u64> = delays.iter().map(|d| (f64::from(*d) * 1e9).round() as u64).collect();
    ns.sort_unstable();
    assert_eq!(v["delay_ms"]["p50"].as_f64(), Some(nearest_rank(&ns, 0.5) as f64 / 1e6));
    let table = netfi().args(["scenario", "check", scenario.to_str().unwrap(), "--frames", "100"]).output().unwrap();
    let table = String::from_utf8_lossy(&table.stdout);
    assert!(table.contains("replays `trial.bin`: delay capture (time | length | delay (s) | frame), 2500 fates"), "{table}");
    // A trace.csv names its columns.
    netfi::trace::write_csv(&dir.0.join("trace.csv"), &[netfi::trace::Row { present: true, release_sched_ns: 5, ..Default::default() }], &[]).unwrap();
    std::fs::write(&scenario, "[[stage]]\nmodel = \"replay\"\nfile = \"trace.csv\"\n").unwrap();
    let out = netfi().args(["scenario", "check", scenario.to_str().unwrap(), "--frames", "10", "--json"]).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    assert_eq!(v["stages"][0]["recording"]["layout"], "columns fate, reason, delay_ns");
}
