//! The product run: `netfi run Normal` as shipped (console and simulator
//! processes), for its own report of the same quantities. `netfi_run` is
//! also what the throughput search runs.

use crate::args::Settings;
use crate::host::HostTimer;
use crate::{check_interrupted, Results, NETFI};
use anyhow::{Context, Result};
use netfi::metrics::{fmt_ns, Summary};
use netfi::service::report::RunReport;
use netfi::service::signals::stop_requested;
use serde_json::{json, Value};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Runs `netfi run scenario` at `rate_hz` for `seconds` (seed 1, writing
/// to `dir`, with `extra` flags) and returns its report.
pub fn netfi_run(dir: &Path, scenario: &str, rate_hz: f64, seconds: f64, extra: &[&str]) -> Result<RunReport> {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir)?;
    let log = std::fs::File::create(dir.join("run.log"))?;
    let mut child = Command::new(NETFI)
        .args(["run", scenario, "--rate-hz", &rate_hz.to_string(), "--duration-s", &seconds.to_string(), "--seed", "1", "--out"])
        .arg(dir)
        .args(extra)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("running {NETFI} run"))?;
    // Polled rather than waited for, so that a stop of the benchmark alone
    // (SIGTERM, or Ctrl-C outside a terminal) reaches the run too.
    let mut signalled = false;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if stop_requested() && !signalled {
            signalled = true;
            // SAFETY: signalling our own child by its pid.
            unsafe {
                libc::kill(child.id() as libc::pid_t, libc::SIGINT);
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    check_interrupted()?;
    let path = dir.join("report.json");
    let report: RunReport = serde_json::from_slice(&std::fs::read(&path).with_context(|| format!("reading {} (netfi run: {status})", path.display()))?)
        .with_context(|| format!("parsing {}", path.display()))?;
    for big in ["trace.csv", "received.csv"] {
        let _ = std::fs::remove_file(dir.join(big));
    }
    Ok(report)
}

/// The percentiles of `x` as JSON (null where the run had none).
fn percentiles(x: &Option<Summary>) -> Option<Value> {
    x.map(|p| json!({"p50": p.p50, "p90": p.p90, "p99": p.p99, "p999": p.p999, "p9999": p.p9999, "max": p.max}))
}

/// The product run of repetition `rep`: `netfi run Normal` at 1 kHz.
pub fn product_part(s: &Settings, rep: usize, res: &mut Results) -> Result<()> {
    let dir = s.out_dir.join("runs").join(format!("product-normal-1k-r{rep}"));
    let host = HostTimer::start(s.quiet);
    let r = netfi_run(&dir, "Normal", 1000.0, s.interval_s, &[])?;
    let host = host.stop();
    let o = &r.overhead_ns;
    println!(
        "  rep {rep} netfi run Normal 1k: end-to-end extra p50 {} p99 {}; direct hop p50 {} p99 {}; balanced {}",
        o.end_to_end_extra.map_or("?".into(), |x| fmt_ns(x.p50)),
        o.end_to_end_extra.map_or("?".into(), |x| fmt_ns(x.p99)),
        o.direct_hop.map_or("?".into(), |x| fmt_ns(x.p50)),
        o.direct_hop.map_or("?".into(), |x| fmt_ns(x.p99)),
        r.frames.balanced
    );
    res.products.push(json!({
        "repetition": rep,
        "scenario": "Normal",
        "rate_hz": 1000.0,
        "host": host,
        "balanced": r.frames.balanced,
        "end_to_end_extra_ns": percentiles(&o.end_to_end_extra),
        "direct_hop_ns": percentiles(&o.direct_hop),
        "added_over_direct_ns": o.added_over_direct,
        "ingress_wait_ns": percentiles(&o.ingress_wait),
        "decision_ns": percentiles(&o.decision),
        "release_lateness_ns": percentiles(&o.release_lateness),
        "steal_fraction": r.steal.fraction,
        "out_dir": dir,
    }));
    Ok(())
}
