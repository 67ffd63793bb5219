//! The emulator service: one loop, pinned to one core, over N ≥ 1 lanes
//! (streams). A lane is a forward path (console → robot) and its reverse
//! paths (the robot's feedback, the camera's video, the UDP return); a
//! path is one [`Link`](crate::service::link::Link) between the ports of a
//! [`Channel`](path::Channel), written once ([`path`]). Each turn of a
//! lane releases what is due, polls its reverse paths and takes every
//! frame waiting at its ingress (up to a batch), deciding each; nothing in
//! it allocates, locks or makes a system call beyond the transports' own.
//!
//! | file | what |
//! |---|---|
//! | `path` | the path around a link, generic over its channel; the reverse paths' object |
//! | `forward`, `feedback`, `video`, `udp_return` | the channels, one file each |
//! | `reverse` | what opening a reverse path needs, and the list of them |
//! | `lane` | one stream: its forward path, its reverse paths, its turn and its end |
//! | `spin` | the one loop over the lanes, and the reaper of dead peers |
//! | `busy` | the loop's busy time and the capacity it implies |
//! | `config` | the arguments resolved once: each lane's scenario, seed and queue |
//! | `report` | `emulator.json`, the joint report of several lanes, `udp.json` |

pub mod busy;
pub mod config;
pub mod feedback;
pub mod forward;
pub mod lane;
pub mod path;
pub mod report;
pub mod reverse;
pub mod spin;
pub mod udp_return;
pub mod video;

pub use crate::service::schema::{BadInput, EmulatorReport, LoopBusy};
pub use forward::{classify, Forward};

use crate::host::StealTimer;
use crate::scenario::Scenario;
use crate::service::args::EmulatorArgs;
use crate::service::control::{self, ControlHandle, ControlPort};
use crate::service::schema::BoundEndpoints;
use crate::service::signals;
use crate::transport::{Egress, Ingress, IpcNode};
use anyhow::Context;
use config::{EmulatorConfig, LaneConfig};
use forward::ConsoleAddr;
use lane::Lane;
use path::Path;
use std::cell::RefCell;
use std::rc::Rc;

/// What a raw sample (`--payload raw`) cannot go through: its bytes live
/// in the UDP source's arena, freed at its release, so a copy would be sent
/// from a freed slot, and a flip would miss.
const RAW_UNSUPPORTED: &[crate::model::ModelKind] = &[crate::model::ModelKind::Duplicate, crate::model::ModelKind::Corrupt];

/// A lane as opened, and what its end needs of its transports.
struct Opened {
    lane: Lane<Ingress, Egress>,
    node: Option<IpcNode>,
    arena: Option<Rc<RefCell<crate::transport::udp::Arena>>>,
    bound: BoundEndpoints,
}

/// Opens lane `l`'s transports and paths (before the loop is pinned: each
/// path starts its trace writer).
fn open_lane(l: &LaneConfig) -> anyhow::Result<Opened> {
    std::fs::create_dir_all(&l.out_dir).with_context(|| format!("creating {}", l.out_dir.display()))?;
    let a = &l.args;
    let t = crate::transport::open(&a.udp.ingress, &a.udp.egress, &a.wiring(l.queue_capacity))?;
    let console = ConsoleAddr::default();
    let o = reverse::Opening { args: a, t: &t, seed: l.seed, expected_frames: a.expected_frames, out_dir: &l.out_dir, console: &console };
    let reverse = reverse::open_all(&o)?;
    let scenario = Scenario::new(&l.scenario, l.seed)?;
    if let Some(kind) = crate::service::link::unsupported_stage(&scenario, RAW_UNSUPPORTED).filter(|_| l.accept_raw()) {
        anyhow::bail!("scenario `{}`: the `{}` stage applies to ITP frames, not to raw datagrams (--payload raw)", scenario.name(), kind.name());
    }
    let bound = report::bound(&t.ingress, &t.egress, a.udp.egress.udp());
    let crate::transport::Transports { ingress, egress, node, arena } = t;
    let udp_in = matches!(ingress, Ingress::Udp(_));
    let mut chan = Forward::new(ingress, egress, a.drop_bad_checksum, l.accept_raw());
    if udp_in {
        chan.share_console(console);
    }
    let forward = Path::new(chan, scenario, l.seed, l.queue_capacity, a.expected_frames, &l.out_dir, true)?;
    Ok(Opened { lane: Lane::new(forward, reverse), node, arena, bound })
}

/// Wires the emulator: arguments → lanes → the loop → each lane's report
/// (and the joint one of several, and `udp.json` where a side is UDP).
/// Returns lane 0's report.
pub fn main(args: &EmulatorArgs) -> anyhow::Result<EmulatorReport> {
    let cfg = EmulatorConfig::of(args)?;
    crate::service::write_pid(&cfg.out_dir, "emulator")?;
    let mut opened = Vec::with_capacity(cfg.lanes.len());
    for (k, l) in cfg.lanes.iter().enumerate() {
        opened.push(open_lane(l).with_context(|| format!("stream {k}"))?);
        say_lane(&cfg, k, &opened[k]);
    }
    let (mut lanes, nodes, arenas, bounds) = split(opened);
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
    let mut control = start_control(&cfg, &mut lanes[0].forward.link)?;
    let mut placement = place::place(&cfg, &lanes, control.as_ref().map(|(_, h)| h))?;
    signals::install();
    for (l, b) in cfg.lanes.iter().zip(&bounds).filter(|(l, _)| l.args.udp.ingress.is_udp() || l.args.udp.egress.is_udp()) {
        let p = l.out_dir.join("udp_endpoints.json");
        std::fs::write(&p, serde_json::to_vec_pretty(b)?).with_context(|| format!("writing {}", p.display()))?;
    }
    // Ready only now, set up and placed: a console started on it is taken
    // in at once. Said before the set-up, frames queued at the ingress for
    // its length (0.1–0.3 s with a cleared core and a queue and trace sized
    // for 10⁵–10⁶ frames/s) and beyond the subscriber's buffer were lost.
    std::fs::write(cfg.out_dir.join("emulator.ready"), b"").context("writing emulator.ready")?;
    let term = nodes[0].as_ref();
    let mut stop = signals::StopCheck::new(256, || term.is_some_and(|n| n.termination_requested()));
    let mut reaper = spin::Reaper::new(&nodes, std::env::var_os(crate::host::isolate::RUNNER_PID_ENV).is_none());
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
    let isolation = placement.isolation.as_mut().map(|iso| iso.restore());
    let run = report::Run { end: &end, core: cfg.core, realtime_priority: placement.realtime_priority, steal: steal_timer.stop() };
    let dead = std::mem::take(&mut reaper.dead);
    let mut lane0 = Some((isolation, events));
    let mut reports = Vec::with_capacity(lanes.len());
    for (k, ((lane, dead), l)) in lanes.into_iter().zip(dead).zip(&cfg.lanes).enumerate() {
        let (isolation, events) = lane0.take().unwrap_or_default();
        let udp = (l.args.udp.ingress.is_udp() || l.args.udp.egress.is_udp())
            .then(|| report::udp_report(&l.args, &lane.forward.chan.source, arenas[k].as_ref().map(|a| a.borrow()).as_deref(), &bounds[k]));
        let r = conclude(lane, dead, isolation, events, &run)?;
        write_json(&l.out_dir.join("emulator.json"), &r)?;
        if let Some(mut u) = udp {
            u.return_path = r.process.paths.get(<udp_return::UdpReturn as path::Channel>::NAME).cloned();
            write_json(&l.out_dir.join("udp.json"), &u)?;
            eprintln!("{}", report::summary_line(&r, &u));
        }
        reports.push(r);
    }
    // The nodes outlive the ports.
    drop(nodes);
    if several {
        write_joint(&cfg, &reports, end.ended_by)?;
    }
    Ok(reports.swap_remove(0))
}

/// The lanes as opened, apart from what their ends need.
#[allow(clippy::type_complexity)]
fn split(opened: Vec<Opened>) -> (Vec<Lane<Ingress, Egress>>, Vec<Option<IpcNode>>, Vec<Option<Rc<RefCell<crate::transport::udp::Arena>>>>, Vec<BoundEndpoints>) {
    let mut out = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for o in opened {
        out.0.push(o.lane);
        out.1.push(o.node);
        out.2.push(o.arena);
        out.3.push(o.bound);
    }
    out
}

/// Says what lane `k` is, as the log shows it.
fn say_lane(cfg: &EmulatorConfig, k: usize, o: &Opened) {
    let l = &cfg.lanes[k];
    let a = &l.args;
    if cfg.several() {
        eprintln!("emulator: stream {k}: run {} scenario {} seed {}", a.run_id.as_deref().unwrap_or("?"), l.scenario.name, l.seed);
    } else if a.udp.ingress.is_udp() || a.udp.egress.is_udp() {
        eprintln!(
            "emulator: scenario {} seed {}, queue {}, core {:?}; ingress {}{}, egress {}{}, payload {:?}",
            l.scenario.name,
            l.seed,
            l.queue_capacity,
            cfg.core,
            a.udp.ingress,
            o.bound.ingress.map_or(String::new(), |x| format!(" (bound {x})")),
            a.udp.egress,
            o.bound.egress_local.map_or(String::new(), |x| format!(" (from {x})")),
            a.udp.payload,
        );
    } else {
        eprintln!("emulator: scenario {} seed {}, queue {}, core {:?}", l.scenario.name, l.seed, l.queue_capacity, cfg.core);
    }
}

/// A lane after the loop: its paths finished (traces and histograms
/// written), its report assembled.
fn conclude(
    mut lane: Lane<Ingress, Egress>,
    dead_peers: Vec<String>,
    isolation: Option<crate::host::isolate::IsolationSummary>,
    events: Vec<crate::service::control::ControlEvent>,
    run: &report::Run,
) -> anyhow::Result<EmulatorReport> {
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

/// Writes `value` as pretty JSON to `path`.
fn write_json(path: &std::path::Path, value: &impl serde::Serialize) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_vec_pretty(value)?).with_context(|| format!("writing {}", path.display()))
}

/// Writes `<out>/emulator.json` of several lanes: every lane's account and
/// their total.
fn write_joint(cfg: &EmulatorConfig, reports: &[EmulatorReport], ended_by: &str) -> anyhow::Result<()> {
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
fn start_control(cfg: &EmulatorConfig, link: &mut crate::service::link::Link<crate::sample::FrameSample>) -> anyhow::Result<Option<(ControlPort, ControlHandle)>> {
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
        unsupported: if lane0.accept_raw() { RAW_UNSUPPORTED } else { <crate::sample::FrameSample as crate::service::link::Carried>::UNSUPPORTED },
    };
    let (port, handle) = control::start(settings)?;
    if let Some(tap) = interval_ns.and_then(|ns| handle.aggregator(ns)) {
        link.tap_trace(tap);
    }
    Ok(Some((port, handle)))
}

/// Where the loop runs.
mod place {
    use super::{ControlHandle, EmulatorConfig, Lane};
    use crate::host::isolate::{self, Isolation};
    use crate::transport::{FrameSink, FrameSource};

    /// How the loop's thread was placed.
    pub(super) struct Placement {
        pub(super) isolation: Option<Isolation>,
        pub(super) realtime_priority: Option<i32>,
    }

    /// Pins the loop's thread (keeping every trace writer and the control
    /// thread off its core), clears the core if asked, and raises the
    /// thread's priority if asked.
    pub(super) fn place<S: FrameSource, K: FrameSink>(cfg: &EmulatorConfig, lanes: &[Lane<S, K>], control: Option<&ControlHandle>) -> anyhow::Result<Placement> {
        if let Some(core) = cfg.core {
            let ok = core_affinity::set_for_current(core_affinity::CoreId { id: core });
            anyhow::ensure!(ok, "could not pin the emulator to core {core}");
            for l in lanes {
                for what in l.keep_traces_off_core(core) {
                    warn_unless_off(false, &format!("the {what} trace writer"), core);
                }
            }
            if let Some(h) = control {
                warn_unless_off(h.keep_off_core(core), "the control thread", core);
            }
        }
        // After pinning: the loop's own threads are placed; everything else
        // that may run elsewhere leaves the core until the run ends.
        let isolation = match (cfg.isolate, cfg.core) {
            (true, Some(core)) => match isolate::isolate(core) {
                Ok(iso) => {
                    eprintln!("emulator: {}", iso.summary());
                    Some(iso)
                }
                Err(e) => {
                    eprintln!("emulator: WARNING: could not clear core {core}: {e}");
                    Some(Isolation::not_cleared(core, format!("could not clear core {core}: {e}")))
                }
            },
            (true, None) => {
                let why = isolate::pin_problem().unwrap_or_else(|| "--isolate needs a pinned core; nothing cleared".into());
                eprintln!("emulator: WARNING: {why}");
                Some(Isolation::not_cleared(0, why))
            }
            _ => None,
        };
        let realtime_priority = cfg.rt_priority.and_then(realtime);
        Ok(Placement { isolation, realtime_priority })
    }

    /// Says loudly that one of the emulator's own threads (`what`) could
    /// not be kept off the loop's core: it may use no other core, so each
    /// time it runs it takes the core from the loop.
    fn warn_unless_off(kept: bool, what: &str, core: usize) {
        if !kept {
            eprintln!("emulator: WARNING: {what} could not be kept off core {core} (it may use no other): the loop loses its core whenever that thread runs");
        }
    }

    /// Moves the loop to SCHED_FIFO `p`, warning of real-time throttling;
    /// the priority it got, if any.
    fn realtime(p: i32) -> Option<i32> {
        match crate::service::set_realtime(p) {
            Ok(()) => {
                if let Some((runtime, period)) = crate::service::rt_throttling() {
                    eprintln!(
                        "emulator: WARNING: real-time throttling is on (kernel.sched_rt_runtime_us = {runtime} of {period}): this busy loop at SCHED_FIFO will be stopped for {} ms of every {} ms; set it to -1, or use --isolate without --rt-priority",
                        (period - runtime) / 1000,
                        period / 1000
                    );
                }
                Some(p)
            }
            Err(e) => {
                eprintln!("emulator: staying at normal priority: SCHED_FIFO {p} refused ({e})");
                None
            }
        }
    }
}
