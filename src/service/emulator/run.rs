//! Running the lanes, whatever they carry: live control on lane 0, the
//! loop placed on its core, `emulator.ready`, the loop until its end, then
//! each lane's paths finished and its `emulator.json` written (and the
//! joint report of several lanes).

use crate::host::StealTimer;
use crate::service::control::{self, ControlHandle, ControlPort};
use crate::service::emulator::config::EmulatorConfig;
use crate::service::emulator::{lane::Lane, path::ForwardChannel};
use crate::service::emulator::{report, spin};
use crate::service::link::{Carried, Link};
use crate::service::schema::EmulatorReport;
use crate::service::signals;
use crate::service::emulator::path::PathError;
use crate::service::emulator::report::{write_json, WriteError};
use crate::transport::IpcNode;

/// Why the lanes did not run to their reports.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The reordering release queue.
    #[error(transparent)]
    Queue(#[from] crate::injector::BuildError),
    #[error(transparent)]
    Control(#[from] control::StartError),
    #[error(transparent)]
    Place(#[from] crate::host::placement::PlaceError),
    #[error("writing emulator.ready")]
    Ready(#[source] std::io::Error),
    /// A path's end: its trace, histograms or report.
    #[error(transparent)]
    Path(#[from] PathError),
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// What a kind of lane does once its report is written (its transport's
/// own report).
pub type After = Box<dyn FnOnce(&EmulatorReport) -> Result<(), WriteError>>;

/// Runs `lanes` (with the iceoryx2 nodes they were opened on, which must
/// outlive their ports) as `cfg` says. `before_finish` is asked, for each
/// lane after the loop and before its paths finish, what to do once its
/// report is written. Returns the lanes' reports.
pub fn run<F: ForwardChannel + 'static>(
    cfg: &EmulatorConfig,
    mut lanes: Vec<Lane<F>>,
    nodes: &[Option<&IpcNode>],
    mut before_finish: impl FnMut(usize, &Lane<F>) -> After,
) -> Result<Vec<EmulatorReport>, RunError> {
    let several = cfg.several();
    for l in lanes.iter_mut() {
        // One stream's wait for its release would hold up the others.
        if several {
            l.release_spin_ns = 0;
        }
        if cfg.reorder_queue {
            l.forward.link.reorder_queue()?;
        }
    }
    let mut control = start_control(cfg, &mut lanes[0].forward.link)?;
    let mut placement = place(cfg, &lanes, control.as_ref().map(|(_, h)| h))?;
    signals::install();
    // Ready only now, set up and placed: a console started on it is taken
    // in at once. Said before the set-up, frames queued at the ingress for
    // its length (0.1–0.3 s with a cleared core and a queue and trace sized
    // for 10⁵–10⁶ frames/s) and beyond the subscriber's buffer were lost.
    crate::durable::write_whole(&cfg.out_dir.join("emulator.ready"), b"").map_err(|e| RunError::Ready(std::io::Error::other(e)))?;
    let term = nodes.first().copied().flatten();
    let mut stop = signals::StopCheck::new(256, || term.is_some_and(|n| n.termination_requested()));
    let mut reaper = spin::Reaper::new(nodes, std::env::var_os(crate::host::isolate::RUNNER_PID_ENV).is_none());
    let look = |died: &mut [bool]| {
        if stop.requested() {
            return spin::Look::Stop;
        }
        reaper.look(died);
        spin::Look::Go
    };
    let steal_timer = StealTimer::start();
    let end = spin::spin(&mut lanes, look, control.as_mut().map(|(p, _)| p));
    let events = control.map(|(_, h)| h.finish()).unwrap_or_default();
    let isolation = placement.restore();
    let run = report::Run { end: &end, core: cfg.core, realtime_priority: placement.realtime_priority, threads: std::mem::take(&mut placement.threads), steal: steal_timer.stop() };
    let dead = std::mem::take(&mut reaper.dead);
    let mut lane0 = Some((isolation, events));
    let mut reports = Vec::with_capacity(lanes.len());
    // Every lane closed before any is finished: their traces are written
    // and synced at once, not one lane after another.
    let afters: Vec<After> = lanes
        .iter_mut()
        .enumerate()
        .map(|(k, lane)| {
            let after = before_finish(k, lane);
            lane.close();
            after
        })
        .collect();
    for (lane, dead) in lanes.into_iter().zip(dead) {
        let (isolation, events) = lane0.take().unwrap_or_default();
        reports.push(conclude(lane, dead, isolation, events, &run)?);
    }
    // Each lane's report, written (and synced) beside the others'.
    std::thread::scope(|s| {
        let writing: Vec<_> = reports.iter().zip(&cfg.lanes).map(|(r, l)| s.spawn(move || write_json(&l.out_dir.join("emulator.json"), r))).collect();
        writing.into_iter().try_for_each(|w| w.join().expect("a report writer panicked"))
    })?;
    for (r, after) in reports.iter().zip(afters) {
        after(r)?;
    }
    if several {
        write_joint(cfg, &reports, end.ended_by)?;
    }
    Ok(reports)
}

/// A lane after the loop: its paths finished (traces and histograms
/// written), its report assembled.
fn conclude<F: ForwardChannel + 'static>(
    mut lane: Lane<F>,
    dead_peers: Vec<String>,
    isolation: Option<crate::host::isolate::IsolationSummary>,
    events: Vec<crate::service::control::ControlEvent>,
    run: &report::Run,
) -> Result<EmulatorReport, PathError> {
    let duration_ns = run.end.duration_ns();
    lane.end_turn(run.end.t_end);
    let busy = lane.loop_busy();
    let Lane { forward, reverse, peer_events, robot_died, .. } = lane;
    let fwd = forward.finish(duration_ns)?;
    let mut paths = std::collections::BTreeMap::new();
    for r in reverse {
        let name = r.name();
        paths.insert(name.to_string(), r.finish(duration_ns)?);
    }
    let end = report::LaneEnd { busy, peer_events, dead_peers, robot_died, isolation, events };
    Ok(report::lane_report(fwd, paths, end, run))
}


/// Writes `<out>/emulator.json` of several lanes: every lane's account and
/// their total.
fn write_joint(cfg: &EmulatorConfig, reports: &[EmulatorReport], ended_by: crate::service::schema::Ended) -> Result<(), WriteError> {
    let run_ids: Vec<String> = cfg.lanes.iter().map(|l| l.args.run_id.clone().unwrap_or_default()).collect();
    let dirs: Vec<_> = cfg.lanes.iter().map(|l| l.out_dir.clone()).collect();
    let joint = report::joint(reports, &run_ids, &dirs, ended_by);
    write_json(&cfg.out_dir.join("emulator.json"), &joint)?;
    let t = &joint.total.account;
    eprintln!(
        "emulator: {} streams: {} entered, {} delivered, {} held at end; balanced {}; ended by {}",
        reports.len(),
        t.entered,
        t.delivered,
        t.held_at_end,
        joint.balanced,
        joint.ended_by
    );
    Ok(())
}

/// The live control of the run, when it has one: room for switched phases,
/// the control thread started and its telemetry tapped from lane 0's trace
/// (before the loop's core is pinned).
fn start_control<T: Carried>(cfg: &EmulatorConfig, link: &mut Link<T>) -> Result<Option<(ControlPort, ControlHandle)>, control::StartError> {
    let Some((run, telemetry_ms)) = cfg.control.clone() else { return Ok(None) };
    link.injector_mut().reserve_phases(control::PHASE_ROOM);
    let interval_ns = (telemetry_ms > 0).then(|| telemetry_ms.saturating_mul(1_000_000));
    let lane0 = &cfg.lanes[0];
    let settings = control::Settings {
        run,
        spec: lane0.scenario.clone(),
        queue_order: link.injector_mut().queue_order(),
        out_dir: lane0.out_dir.clone(),
        telemetry_interval_ns: interval_ns,
        unsupported: if lane0.accept_raw() { lane0.unsupported() } else { T::UNSUPPORTED },
    };
    let (port, handle) = control::start(settings)?;
    if let Some(tap) = interval_ns.and_then(|ns| handle.aggregator(ns)) {
        link.tap_trace(tap);
    }
    Ok(Some((port, handle)))
}

/// Pins the loop's thread, keeping every trace writer of every lane and the
/// control thread off its core, clears the core if asked, and raises the
/// thread's priority if asked (`host::placement`, which says loudly what
/// it could not do).
fn place<F: ForwardChannel + 'static>(cfg: &EmulatorConfig, lanes: &[Lane<F>], control: Option<&ControlHandle>) -> Result<crate::host::placement::Placement, crate::host::placement::PlaceError> {
    use crate::host::placement::{place_loop, KeepOff, KeepOffFn, LoopPlacement};
    let several = lanes.len() > 1;
    let names: Vec<Vec<String>> = lanes
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let whose = if several { format!("stream {k}'s ") } else { String::new() };
            std::iter::once(format!("{whose}forward trace writer")).chain(l.reverse.iter().map(|r| format!("{whose}{} trace writer", r.name()))).collect()
        })
        .collect();
    let mut threads: Vec<Box<dyn KeepOff + '_>> = Vec::new();
    for (l, names) in lanes.iter().zip(&names) {
        threads.push(Box::new(KeepOffFn(&names[0], |c| l.forward.keep_trace_off_core(c))));
        for (r, name) in l.reverse.iter().zip(&names[1..]) {
            threads.push(Box::new(KeepOffFn(name, |c| r.keep_trace_off_core(c))));
        }
    }
    if let Some(h) = control {
        threads.push(Box::new(KeepOffFn("the control thread", |c| h.keep_off_core(c))));
    }
    let keep_off: Vec<&dyn KeepOff> = threads.iter().map(|t| t.as_ref()).collect();
    // Every thread of the emulator's process off the loop's core, a DDS
    // library's own among them.
    let want = LoopPlacement { core: cfg.core, isolate: cfg.isolate, rt_priority: cfg.rt_priority, keep_process_off: true };
    place_loop("emulator", &want, &keep_off)
}
