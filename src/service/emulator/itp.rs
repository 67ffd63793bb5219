//! The emulator's lanes of ITP frames over iceoryx2 and UDP: each lane's
//! transports opened from its endpoints ([`crate::transport::open`]), its
//! forward path and reverse paths; at the end, `udp.json` where a side is
//! UDP.

use crate::scenario::Scenario;
use crate::service::emulator::config::{EmulatorConfig, LaneConfig};
use crate::service::emulator::forward::{ConsoleAddr, Forward};
use crate::service::emulator::lane::Lane;
use crate::service::emulator::path::{Channel, Path};
use crate::service::emulator::reverse::OpenError;
use crate::service::emulator::{report, reverse, run, udp_return};
use crate::service::schema::{BoundEndpoints, EmulatorReport};
use crate::transport::udp::Arena;
use crate::transport::{Egress, Ingress, IpcNode};
use std::cell::RefCell;
use std::rc::Rc;

/// A lane of ITP frames.
pub type ItpLane = Lane<Forward<Ingress, Egress>>;

/// A lane as opened, and what its end needs of its transports.
struct Opened {
    lane: ItpLane,
    node: Option<IpcNode>,
    arena: Option<Rc<RefCell<Arena>>>,
    bound: BoundEndpoints,
}

/// Opens lane `l`'s transports and paths (before the loop is pinned: each
/// path starts its trace writer).
fn open_lane(l: &LaneConfig) -> Result<Opened, OpenError> {
    std::fs::create_dir_all(&l.out_dir).map_err(|cause| OpenError::Dir { dir: l.out_dir.clone(), cause })?;
    let a = &l.args;
    let t = crate::transport::open(&a.udp.ingress, &a.udp.egress, &a.wiring(l.queue_capacity))?;
    let console = ConsoleAddr::default();
    let o = reverse::Opening { args: a, t: &t, seed: l.seed, expected_frames: a.expected_frames, out_dir: &l.out_dir, console: &console };
    let reverse = reverse::open_all(&o)?;
    let scenario = Scenario::new(&l.scenario, l.seed)?;
    if let Some(kind) = crate::service::link::unsupported_stage(&scenario, l.unsupported()) {
        return Err(OpenError::RawStage { scenario: scenario.name().to_string(), stage: kind.name() });
    }
    let bound = report::bound(&t.ingress, &t.egress, a.udp.egress.udp());
    let crate::transport::Transports { ingress, egress, node, arena } = t;
    let udp_in = matches!(ingress, Ingress::Udp(_));
    let mut chan = Forward::new(ingress, egress, a.drop_bad_checksum, l.accept_raw());
    if udp_in {
        chan.share_console(console);
    }
    let forward = Path::new(chan, scenario, l.seed, l.queue_capacity, a.expected_frames, &l.out_dir, true)?;
    if a.udp.ingress.is_udp() || a.udp.egress.is_udp() {
        report::write_json(&l.out_dir.join("udp_endpoints.json"), &bound)?;
    }
    Ok(Opened { lane: Lane::new(forward, reverse), node, arena, bound })
}

/// Runs the emulator of `cfg`'s ITP lanes; their reports.
pub fn main(cfg: &EmulatorConfig) -> Result<Vec<EmulatorReport>, super::EmulatorError> {
    let mut opened = Vec::with_capacity(cfg.lanes.len());
    for (k, l) in cfg.lanes.iter().enumerate() {
        opened.push(open_lane(l).map_err(|cause| super::EmulatorError::Stream { stream: k, cause })?);
        say_lane(cfg, k, &opened[k]);
    }
    let (mut lanes, mut nodes, mut ends) = (Vec::new(), Vec::new(), Vec::new());
    for o in opened {
        lanes.push(o.lane);
        nodes.push(o.node);
        ends.push((o.arena, o.bound));
    }
    // The UDP side of each lane, read before its paths finish and written
    // beside its report.
    let udp_side = |k: usize, lane: &ItpLane| {
        let l = &cfg.lanes[k];
        let (arena, bound) = &ends[k];
        let u = (l.args.udp.ingress.is_udp() || l.args.udp.egress.is_udp())
            .then(|| report::udp_report(&l.args, &lane.forward.chan.source, arena.as_ref().map(|a| a.borrow()).as_deref(), bound));
        let dir = l.out_dir.clone();
        let after: run::After = Box::new(move |r: &EmulatorReport| {
            let Some(mut u) = u else { return Ok(()) };
            u.return_path = r.process.paths.get(<udp_return::UdpReturn as Channel>::NAME).cloned();
            report::write_json(&dir.join("udp.json"), &u)?;
            eprintln!("{}", report::summary_line(r, &u));
            Ok(())
        });
        after
    };
    Ok(run::run(cfg, lanes, nodes, udp_side)?)
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

