//! `netfi scenario …`

use crate::cli::{CheckArgs, ScenarioCmd};
use anyhow::{bail, Context, Result};
use netfi::check::{self, Arrivals, CheckReport, StageReport};
use netfi::load;
use netfi::scenario::{self, Scenario, PRESET_NAMES};

use netfi::service::run::{fresh_seed, DEFAULT_QUEUE_CAPACITY};

pub fn run(cmd: ScenarioCmd) -> Result<()> {
    match cmd {
        ScenarioCmd::Check(args) => check_cmd(args),
        ScenarioCmd::List => {
            for name in PRESET_NAMES {
                println!("{name:10} {}", scenario::preset_label(name).unwrap_or(""));
            }
            Ok(())
        }
        ScenarioCmd::Show { scenario } => {
            let spec = load::resolve(&scenario)?;
            print!("{}", spec.to_toml());
            for line in file_stage_notes(&Scenario::new(&spec, 0)?) {
                println!("# {line}");
            }
            Ok(())
        }
    }
}


fn check_cmd(args: CheckArgs) -> Result<()> {
    let spec = load::resolve(&args.scenario)?;
    let seed = args.seed.or(spec.seed).unwrap_or_else(fresh_seed);
    let queue_capacity = args.queue_capacity.or(spec.queue_capacity).unwrap_or(DEFAULT_QUEUE_CAPACITY);
    // Refused here with the scheduler's own message, before the checker's
    // queue is built.
    netfi::scheduler::ReleaseQueue::<()>::check_capacity(netfi::scheduler::QueueOrder::Reorder, queue_capacity)?;
    let mut capture_note = None;
    let arrivals = match &args.capture {
        Some(path) => {
            let limits = args.capture_max_records.map_or_else(netfi::capture::CaptureLimits::default, netfi::capture::CaptureLimits::records);
            let cap = netfi::capture::load_with(path, limits).with_context(|| format!("reading capture {}", path.display()))?;
            eprintln!("capture {}: {} records, layout `{}`", path.display(), cap.records.len(), cap.layout.describe());
            let note = cap.note();
            for w in note.unverified_warning().into_iter().chain(cap.stats.warnings()) {
                eprintln!("WARNING: {w}");
            }
            capture_note = Some(note);
            let t0 = cap.records.first().map_or(0, |r| r.time_ns);
            let mut times: Vec<u64> = cap.records.iter().map(|r| r.time_ns.saturating_sub(t0)).collect();
            // Wall-clock captures can step backwards; the injector's clock cannot.
            for i in 1..times.len() {
                times[i] = times[i].max(times[i - 1]);
            }
            Arrivals::Times(times)
        }
        None => {
            Arrivals::at_rate(args.frames, args.rate_hz).map_err(|e| anyhow::anyhow!("--rate-hz, --frames: {e}"))?
        }
    };
    if arrivals.is_empty() {
        bail!("nothing to check: 0 frames");
    }
    eprintln!("scenario {} seed {seed}", spec.name);
    let scenario = Scenario::new(&spec, seed)?;
    let bar = indicatif::ProgressBar::new(arrivals.len());
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames ({per_sec}, eta {eta})")
            .expect("static template"),
    );
    if arrivals.len() < 2_000_000 {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let mut trace = args.trace.as_deref().map(TraceOut::create).transpose()?;
    let report = check::run_observed(scenario, &arrivals, queue_capacity, |done| bar.set_position(done), |i, t, e| {
        if let Some(w) = trace.as_mut() {
            w.row(i, t, e);
        }
    });
    bar.finish_and_clear();
    if let Some(w) = trace {
        w.finish()?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&CheckJson { report: &report, capture: capture_note })?);
    } else {
        print_table(&report);
    }
    Ok(())
}

/// `scenario check --json`: the report, and the capture the arrivals came
/// from (what of it is unverified), when there is one.
#[derive(serde::Serialize)]
struct CheckJson<'a> {
    #[serde(flatten)]
    report: &'a CheckReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    capture: Option<netfi::capture::CaptureNote>,
}

/// What the link and replay stages hold, for `scenario show` (comments
/// after the TOML: the files they read are not printed).
fn file_stage_notes(scenario: &Scenario) -> Vec<String> {
    use netfi::model::AnyModel;
    let mut out = Vec::new();
    for (pi, phase) in scenario.phases().iter().enumerate() {
        for st in phase.stages() {
            let at = format!("phase {} stage `{}`", pi + 1, st.label());
            let queue = |p: &netfi::model::backlog::Packets| {
                let limit = match p.limit {
                    netfi::model::backlog::QueueLimit::Packets(n) => format!("{n} packets"),
                    netfi::model::backlog::QueueLimit::Bytes(b) => format!("{b} bytes"),
                };
                format!("{}-byte payloads in {} packet(s) (MTU {}, +{} bytes each), queue {limit}", p.payload_bytes, p.count(p.payload_bytes), p.mtu_bytes, p.overhead_bytes)
            };
            match st.model() {
                AnyModel::Rate(m) => out.push(format!("{at}: rate {} bit/s, {}", m.rate_bit_s(), queue(m.packets()))),
                AnyModel::LinkTrace(m) => out.push(format!(
                    "{at}: trace of {} opportunities of {} bytes every {} ms (mean {:.3} Mbit/s), repeated; {}",
                    m.schedule().len(),
                    m.opportunity_bytes(),
                    m.schedule().period_ms(),
                    m.schedule().mean_rate_bit_s(m.opportunity_bytes()) / 1e6,
                    queue(m.packets())
                )),
                AnyModel::Replay(m) => {
                    let r = m.recording();
                    out.push(format!(
                        "{at}: replay of {} recorded fates ({}, read as {}): loss {:.5}, mean delay {:.3} ms, repeated",
                        r.len(),
                        r.kind().name(),
                        r.kind().layout(),
                        r.loss_rate(),
                        r.mean_delay_ms()
                    ))
                }
                _ => {}
            }
        }
    }
    out
}

fn print_links(r: &CheckReport) {
    for l in &r.links {
        println!("link              phase {} `{}` ({})", l.phase, l.label, l.model);
        println!(
            "  carried         {:.3} Mbit/s of {:.3} Mbit/s capacity, utilisation {:.4}",
            l.carried_bit_s / 1e6,
            l.capacity_bit_s / 1e6,
            l.utilisation
        );
        println!("  frames          {} admitted ({} packets), {} dropped by link_queue ({} packets)", l.frames, l.packets, l.frames_dropped, l.packets_dropped);
        if l.frames_dropped_after > 0 {
            println!(
                "                  of the admitted, {} dropped after the link (later stage or queue_full), {} passed on",
                l.frames_dropped_after,
                l.frames - l.frames_dropped_after
            );
        }
        println!(
            "  time at link ms p50 {:.3}  p90 {:.3}  p99 {:.3}  max {:.3}  (each at most {} high)",
            l.delay_ms.p50,
            l.delay_ms.p90,
            l.delay_ms.p99,
            l.delay_ms.max,
            netfi::metrics::fmt_fraction(l.delay_ms.error_fraction_max.unwrap_or(netfi::metrics::ERROR_FRACTION_MAX))
        );
        println!("  queue max       {} packets, {} bytes", l.queue_packets_max, l.queue_bytes_max);
        // Occupancy over time: ten evenly spaced seconds (all of them in --json).
        let step = (l.occupancy.len() / 10).max(1);
        let shown: Vec<String> = l.occupancy.iter().step_by(step).map(|o| format!("{}s:{}", o.second, o.packets_max)).collect();
        println!("  queue over time {} (second:packets max)", shown.join(" "));
    }
}

fn print_table(r: &CheckReport) {
    print_outcome(r);
    print_links(r);
    if !r.stages.is_empty() {
        println!("stages:");
        println!("  {:>5}  {:<16} {:>12} {:>12} {:>9} {:>9}", "phase", "label", "reached", "dropped", "loss", "model");
        for s in &r.stages {
            print_stage(s);
        }
    }
}

/// The whole run: frames, fates, loss, delay, order, outages, corruption,
/// the queue.
fn print_outcome(r: &CheckReport) {
    println!("scenario          {}", r.scenario);
    println!("seed              {}", r.seed);
    println!("frames            {} at {:.1} Hz", r.frames, r.rate_hz);
    println!("delivered         {}", r.delivered);
    if r.duplicated > 0 {
        println!("duplicated        {} copies (delivered and dropped count them)", r.duplicated);
    }
    for (reason, n) in &r.dropped {
        println!("dropped           {n} by {reason}");
    }
    let bound = |x: f64| netfi::metrics::fmt_rate(x, 5);
    println!("loss rate         {:.5}  95% CI [{}, {}]", r.loss_rate, bound(r.loss_rate_ci95[0]), bound(r.loss_rate_ci95[1]));
    if let Some(u) = r.loss_rate_unseen_model.filter(|u| *u >= 0.000005) {
        println!("                  (the upper end adds the {u:.5} the models lose in bursts longer than a run this long likely meets)");
    }
    println!("mean loss run     {:.3} frames", r.loss_run_mean);
    let d = &r.delay_ms;
    let precision = d.error_fraction_max.map(|_| format!("  ({})", d.precision())).unwrap_or_default();
    println!("delay ms          mean {:.3}  p50 {:.3}  p99 {:.3}  max {:.3}{precision}", d.mean, d.p50, d.p99, d.max);
    println!("reordered         {:.5} of delivered", r.reordered_fraction);
    println!("outages           {} windows, mean {:.1} ms", r.outages.count, r.outages.mean_ms);
    if let Some(c) = &r.corruption {
        println!(
            "corrupted         {} delivered: {} caught by the checksum, {} passed it",
            c.corrupted, c.caught, c.passed
        );
    }
    println!("queue             depth max {} of {}", r.queue_depth_max, r.queue_capacity);
}

/// The model column of a stage's row: its long-run figure.
fn model_column(s: &StageReport) -> String {
    match (s.loss_rate_model, s.delay_ms_model) {
        _ if s.corrupt_rate_model.is_some() => format!("{:.5} bad", s.corrupt_rate_model.unwrap_or(0.0)),
        _ if s.duplicate_rate_model.is_some() => format!("{:.5} dup", s.duplicate_rate_model.unwrap_or(0.0)),
        (_, Some(d)) => format!("{d:.3} ms"),
        (Some(l), None) => format!("{l:.5}"),
        (None, None) => "-".into(),
    }
}

/// A stage's row, and the lines under it that only some models have.
fn print_stage(s: &StageReport) {
    println!("  {:>5}  {:<16} {:>12} {:>12} {:>9.5} {:>9}", s.phase, s.label, s.reached, s.dropped, s.loss_rate, model_column(s));
    let per_reached = |n: u64| if s.reached > 0 { n as f64 / s.reached as f64 } else { 0.0 };
    let note = |text: String| println!("  {:>5}  {:<16} {text}", "", "");
    if let Some(n) = s.corrupted {
        // Per byte (`ber_per_byte`), several flips in a frame can cancel in
        // the checksum: what it catches is measured above.
        let caught = s
            .caught_fraction_model
            .map_or("checksum's catch measured above (several flips a frame)".to_string(), |c| format!("checksum catches {c:.5} of them"));
        note(format!("corrupted {n} ({:.5} per frame reaching it); model: {caught}", per_reached(n)));
    }
    if let Some(f) = s.early_fraction_model {
        note(format!("model: {f:.5} of frames sent at once"));
    }
    if let Some(sl) = &s.slots {
        let most = sl.frames_per_slot_max.map_or("any".to_string(), |n| n.to_string());
        note(format!("slots {} (model spacing {:.3} ms, at most {most} frames each)", sl.opened, sl.spacing_ms_mean_model));
    }
    if let Some(n) = s.duplicated {
        note(format!("copies {n} ({:.5} per frame reaching it)", per_reached(n)));
    }
    if let Some(p99) = s.delay_ms_p99_model {
        note(format!("model delay p99 {p99:.3} ms"));
    }
    if let Some(c) = &s.correlation_model {
        note(format!("model lag-1 correlation {:.4} (normal scores), {:.4} (ranks)", c.normal_scores_lag1, c.rank_lag1));
    }
    if let Some(rec) = &s.recording {
        note(rec.text());
    }
}

/// `scenario check --trace FILE`: every frame's fate as a run's trace row.
struct TraceOut {
    w: std::io::BufWriter<netfi::durable::PartialFile>,
    path: std::path::PathBuf,
    failed: Option<std::io::Error>,
}

impl TraceOut {
    fn create(path: &std::path::Path) -> Result<TraceOut> {
        use std::io::Write;
        // `NAME.partial` until whole (netfi::durable).
        let file = netfi::durable::PartialFile::create(path)?;
        let mut w = std::io::BufWriter::with_capacity(1 << 16, file);
        writeln!(w, "{}", netfi::trace::CSV_HEADER).with_context(|| format!("writing {}", path.display()))?;
        Ok(TraceOut { w, path: path.to_path_buf(), failed: None })
    }

    /// The frame `i` that arrived at `t_ns` and was decided `e`; in
    /// simulated time a scheduled frame leaves exactly when scheduled.
    fn row(&mut self, i: u64, t_ns: u64, e: &netfi::injector::Entered) {
        use netfi::injector::Fate;
        if self.failed.is_some() {
            return;
        }
        let (dropped, release_sched_ns) = match e.fate {
            Fate::Scheduled { release_ns, .. } => (None, release_ns),
            Fate::Dropped(c) => (Some(c), 0),
        };
        let row = netfi::trace::Row {
            present: true,
            console_index: i,
            send_ns: t_ns,
            ingress_ns: t_ns,
            dropped,
            release_sched_ns,
            release_ns: dropped.is_none().then_some(release_sched_ns),
            corrupted: e.corrupted,
            ..Default::default()
        };
        if let Err(err) = netfi::trace::format_row(&mut self.w, i, &row, None, None) {
            self.failed = Some(err);
        }
    }

    fn finish(mut self) -> Result<()> {
        use std::io::Write;
        let flushed = self.w.flush();
        match self.failed.take().map_or(flushed, Err) {
            Ok(()) => {}
            Err(e) => return Err(anyhow::Error::new(e).context(format!("writing {}", netfi::durable::partial_path(&self.path).display()))),
        }
        let file = self.w.into_inner().map_err(|e| anyhow::Error::new(e.into_error()).context(format!("writing {}", self.path.display())))?;
        file.commit()?;
        Ok(())
    }
}
