//! The probe: a thread spinning on each core records the gaps between its
//! clock reads: what interrupts, the hypervisor and other tasks take from
//! any busy loop there, the emulator's included.

use crate::common::args::{check_interrupted, stopped, Placement};
use crate::common::host::{pin, HostTimer, HostWindow};
use anyhow::Result;
use netfi::clock::now_ns;
use netfi::metrics::{LatencyHistogram, Summary};
use serde::Serialize;

/// What a thread spinning on one core (with nothing else to do) loses to
/// the machine: the gaps between consecutive clock reads.
#[derive(Debug, Clone, Serialize)]
pub struct ProbeResult {
    pub repetition: usize,
    pub core: Option<usize>,
    pub seconds: f64,
    pub host: HostWindow,
    /// Lengths of the gaps longer than 2 µs.
    pub gaps_ns: Summary,
    /// Gaps longer than 10 µs, 100 µs and 1 ms, per second.
    pub gaps_over_10us_per_s: f64,
    pub gaps_over_100us_per_s: f64,
    pub gaps_over_1ms_per_s: f64,
    /// Share of the time spent in gaps longer than 10 µs.
    pub lost_fraction: f64,
}

/// One core's spin: its gaps over 2 µs, the time lost in gaps over 10 µs,
/// and the counts of gaps over 10 µs, 100 µs and 1 ms.
struct Spin {
    core: Option<usize>,
    gaps: LatencyHistogram,
    lost_ns: u64,
    over: [u64; 3],
}

/// Spins on `core` for `seconds`, reading the clock.
fn spin(core: Option<usize>, rt: Option<i32>, seconds: f64) -> Spin {
    pin(core, rt);
    let mut sp = Spin { core, gaps: LatencyHistogram::new(), lost_ns: 0, over: [0; 3] };
    let t0 = now_ns();
    let end = t0 + (seconds * 1e9) as u64;
    let mut prev = t0;
    loop {
        let t = now_ns();
        let gap = t - prev;
        prev = t;
        if gap > 2_000 {
            sp.gaps.record(gap);
            if gap > 10_000 {
                sp.lost_ns += gap;
                sp.over[0] += 1;
            }
            sp.over[1] += u64::from(gap > 100_000);
            sp.over[2] += u64::from(gap > 1_000_000);
        }
        if t >= end || (gap > 2_000 && stopped()) {
            break;
        }
    }
    sp
}

/// Spins one thread on the emulator's core and one on the driving core
/// for `seconds`, each reading the clock, and records every gap between
/// two reads longer than 2 µs: the interruptions (interrupts, the
/// hypervisor, other tasks) that any busy loop there suffers, the
/// emulator's and the benchmark's included.
pub fn probe_interval(p: &Placement, seconds: f64, rep: usize) -> Result<Vec<ProbeResult>> {
    check_interrupted()?;
    let host = HostTimer::start(p.quiet);
    let rt = p.rt_priority;
    let mut cores = vec![p.emulator_core];
    if p.bench_core != p.emulator_core {
        cores.push(p.bench_core);
    }
    let threads: Vec<_> = cores.iter().map(|&core| std::thread::spawn(move || spin(core, rt, seconds))).collect();
    let mut done = Vec::new();
    for t in threads {
        done.push(t.join().map_err(|_| anyhow::anyhow!("a probe thread panicked"))?);
    }
    check_interrupted()?;
    let host = host.stop();
    Ok(done
        .into_iter()
        .map(|sp| ProbeResult {
            repetition: rep,
            core: sp.core,
            seconds,
            host,
            gaps_ns: sp.gaps.summary(),
            gaps_over_10us_per_s: sp.over[0] as f64 / seconds,
            gaps_over_100us_per_s: sp.over[1] as f64 / seconds,
            gaps_over_1ms_per_s: sp.over[2] as f64 / seconds,
            lost_fraction: sp.lost_ns as f64 / (seconds * 1e9),
        })
        .collect())
}
