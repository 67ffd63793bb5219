//! The emulator's lanes of ITP frames over iceoryx2 and UDP: each lane's
//! transports opened from its endpoints ([`crate::transport::open`]), its
//! forward path and reverse paths; at the end, `udp.json` where a side is
//! UDP.

use crate::scenario::Scenario;
use crate::service::emulator::config::{EmulatorConfig, LaneConfig};
use crate::service::emulator::forward::Forward;
use crate::service::emulator::lane::Lane;
use crate::service::emulator::path::Path;
use crate::service::emulator::opening::{OpenError, Opening};
use crate::service::emulator::{report, run};
use crate::service::schema::EmulatorReport;
use crate::transport::{Egress, Ingress, Sessions};

/// A lane of ITP frames.
pub type ItpLane = Lane<Forward<Ingress, Egress>>;

/// Why a lane of ITP frames did not open: its transports, forward path or
/// files, or one of its reverse paths.
#[derive(Debug, thiserror::Error)]
pub enum LaneError {
    #[error(transparent)]
    Open(#[from] OpenError),
    #[error(transparent)]
    Channel(#[from] crate::service::channel::ChannelOpenError),
}

/// Opens lane `l`'s transports and paths (before the loop is pinned: each
/// path starts its trace writer); what its transports keep open beside.
fn open_lane(l: &LaneConfig, stop: &dyn Fn() -> bool) -> Result<(ItpLane, Sessions), LaneError> {
    std::fs::create_dir_all(&l.out_dir).map_err(|cause| OpenError::Dir { dir: l.out_dir.clone(), cause })?;
    let a = &l.args;
    let t = crate::transport::open(&a.ends.ingress, &a.ends.egress, &a.transports, &a.wiring(l.queue_capacity, stop)).map_err(OpenError::from)?;
    let shape = a.lane_shape();
    let o = Opening { shape, sessions: &t.sessions, seed: l.seed, expected_frames: a.expected_frames, out_dir: &l.out_dir };
    let reverse = a.channels.open_all(&shape, &o)?;
    let scenario = Scenario::new(&l.scenario, l.seed).map_err(OpenError::from)?;
    if let Some(kind) = crate::service::link::unsupported_stage(&scenario, l.unsupported()) {
        return Err(OpenError::RawStage { scenario: scenario.name().to_string(), stage: kind.name() }.into());
    }
    for (file, value) in t.sessions.at_start() {
        report::write_json(&l.out_dir.join(file), &value).map_err(OpenError::from)?;
    }
    let crate::transport::Transports { ingress, egress, sessions } = t;
    let chan = Forward::new(ingress, egress, a.drop_bad_checksum, l.accept_raw()).following_motion(a.kinematics);
    let forward = Path::new(chan, scenario, l.seed, l.queue_capacity, a.expected_frames, &l.out_dir, true).map_err(OpenError::from)?;
    Ok((Lane::new(forward, reverse), sessions))
}

/// Runs the emulator of `cfg`'s ITP lanes; their reports.
pub fn main(cfg: &EmulatorConfig) -> Result<Vec<EmulatorReport>, super::EmulatorError> {
    let (mut lanes, mut sessions) = (Vec::with_capacity(cfg.lanes.len()), Vec::with_capacity(cfg.lanes.len()));
    let stop = crate::service::signals::stop_requested;
    for (k, l) in cfg.lanes.iter().enumerate() {
        // A stop asked for while lanes open (64 take seconds) is acted on
        // at once: the lanes open so far run their end as any stopped run's.
        if stop() || sessions.iter().any(crate::transport::Sessions::termination_requested) {
            eprintln!("emulator: stopped while opening its lanes: {k} of {} open; the others have no report", cfg.lanes.len());
            break;
        }
        let (lane, s) = open_lane(l, &stop).map_err(|cause| super::EmulatorError::Stream { stream: k, cause })?;
        say_lane(cfg, k, &s);
        lanes.push(lane);
        sessions.push(s);
    }
    // Each transport's report of a lane, made before its paths finish, and
    // written beside its report with what it says of the reverse paths.
    let reports = |k: usize, lane: &ItpLane| {
        let l = &cfg.lanes[k];
        let a = &l.args;
        let mut t = sessions[k].reports(&a.transports, (&a.ends.ingress, &a.ends.egress), &lane.forward.chan.source, &lane.forward.chan.sink);
        let dir = l.out_dir.clone();
        let after: run::After = Box::new(move |r: &EmulatorReport| {
            if t.is_empty() {
                return Ok(());
            }
            t.attach(&r.process.paths, &r.shaping.link.release_lateness_ns);
            for (file, value) in t.files() {
                report::write_json(&dir.join(file), &value)?;
            }
            eprintln!("{}{}", report::summary_line(r), t.summary());
            Ok(())
        });
        after
    };
    let nodes: Vec<Option<&crate::transport::IpcNode>> = sessions.iter().map(|s| s.iceoryx2.as_ref()).collect();
    let reports = run::run(cfg, lanes, &nodes, reports)?;
    // What the transports kept open outlives the ports.
    drop(sessions);
    Ok(reports)
}

/// Says what lane `k` is, as the log shows it.
fn say_lane(cfg: &EmulatorConfig, k: usize, s: &Sessions) {
    let l = &cfg.lanes[k];
    let a = &l.args;
    if cfg.several() {
        eprintln!("emulator: stream {k}: run {} scenario {} seed {}", a.run_id.as_deref().unwrap_or("?"), l.scenario.name, l.seed);
        return;
    }
    let sides = s.describe(&a.transports, (&a.ends.ingress, &a.ends.egress)).map_or(String::new(), |d| format!("; {d}"));
    eprintln!("emulator: scenario {} seed {}, queue {}, core {:?}{sides}", l.scenario.name, l.seed, l.queue_capacity, cfg.core);
}
