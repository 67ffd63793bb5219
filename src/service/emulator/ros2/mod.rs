//! The emulator's lanes of ROS 2 topics (`--ros2-topic IN=OUT`, one lane
//! each): the emulator joins the ROS 2 domain as one DDS participant, and
//! each lane relays the messages of one topic to another through its own
//! scenario, seed and account, with, where `--ros2-return` names one, a
//! return topic through `--return-scenario`. The type and QoS of each topic
//! are the publisher's as discovered, or given (`--ros2-type`,
//! `--ros2-qos`); a publisher or subscriber that cannot match them is an
//! error at start, and a logged event later. Beside each lane's
//! `emulator.json`, `ros2.json` says what the lane relayed with which QoS,
//! who came and left, and why its stream ended.


pub mod plan;
pub mod topic;

use crate::scenario::Scenario;
use crate::service::args::EmulatorArgs;
use crate::service::emulator::config::LaneConfig;
use crate::service::emulator::lane::Lane;
use crate::service::emulator::opening::PathPlan;
use crate::service::emulator::path::{Path, Reverse};
use crate::service::emulator::ros2::plan::{config, LaneTopics, Plan, DEFAULT_QUEUE_CAPACITY};
use crate::service::emulator::ros2::topic::{Forward, Return, Topic, TopicPorts};
use crate::service::emulator::run;
use crate::service::schema::ros2::{EndpointSeen, EventRow, Ros2Report, TopicReport};
use crate::service::schema::EmulatorReport;
use crate::service::seeds;
use crate::transport::ros2::qos::{self, Summary};
use crate::transport::ros2::node::NAME_WAIT_NS;
use crate::transport::ros2::{Happened, Remote, Role, Ros2Node, TopicName, TypeName};
use crate::service::emulator::opening::OpenError;
use crate::transport::ros2::qos::QosParseError;
use crate::transport::ros2::OpenError as DdsOpenError;
use rustdds::QosPolicies;
use std::cell::RefCell;
use std::rc::Rc;

/// Why a lane's topics did not open: a type or QoS that does not match
/// what the other side announced, a type that cannot be told, or DDS.
#[derive(Debug, thiserror::Error)]
pub enum TopicError {
    #[error("type mismatch on {from}: --ros2-type gives {given}, but the publisher {publisher} publishes {publishes} (DDS matches by type name: nothing would be relayed)")]
    PublisherType { from: TopicName, given: TypeName, publisher: String, publishes: String },
    #[error("type mismatch on {to}: the subscriber {subscriber} expects {expects}, the lane relays {relays} from {from}")]
    SubscriberType { to: TopicName, subscriber: String, expects: String, relays: TypeName, from: TopicName },
    #[error("the publisher of {from} announces type `{announced}`, which is not a ROS 2 message type")]
    NotAType {
        from: TopicName,
        announced: String,
        #[source]
        cause: crate::transport::ros2::NameError,
    },
    #[error("no publisher of {from} found within {seconds:.0} s in ROS 2 domain {domain}: start it first, or give its type (--ros2-type {from}=package/msg/Type)")]
    NoPublisher { from: TopicName, seconds: f64, domain: u16 },
    #[error("the publishers of {from} disagree on its type ({types}): give the one to relay with --ros2-type {from}=…")]
    Disagree { from: TopicName, types: String },
    #[error("QoS mismatch on {topic}: {why}")]
    Qos { topic: TopicName, why: qos::QosMismatch },
    #[error(transparent)]
    QosText(#[from] QosParseError),
    #[error(transparent)]
    Dds(#[from] DdsOpenError),
    /// The lane's directory, scenario, paths.
    #[error(transparent)]
    Open(#[from] OpenError),
}

/// A type as announced, by its ROS 2 name where it has one.
fn shown(dds_type: &str) -> String {
    TypeName::parse(dds_type).map_or(dds_type.to_string(), |t| t.to_string())
}

/// How a topic was opened: its type and QoS and where they came from.
#[derive(Debug, Clone)]
struct Opened {
    type_name: TypeName,
    type_hash: Option<String>,
    type_from: &'static str,
    qos_from: &'static str,
    reader_qos: QosPolicies,
    writer_qos: QosPolicies,
}

/// Polls the graph until `topic` has a publisher or `wait_ns` passes; then
/// a little longer, so that the others there are seen too. Its publishers.
fn discover(node: &mut Ros2Node, topic: &TopicName, wait_ns: u64) -> Vec<Remote> {
    let t0 = crate::clock::now_ns();
    let mut found_at = None;
    loop {
        let now = crate::clock::now_ns();
        node.poll(now);
        let found = node.remotes(topic, Role::Publisher).next().is_some();
        if found {
            found_at.get_or_insert(now);
        }
        // Discovery of one participant's endpoints comes in a burst; others'
        // (the subscribers of the topic written) soon after.
        if found_at.is_some_and(|t| now - t >= 500_000_000) || (!found && now - t0 >= wait_ns) {
            return node.remotes(topic, Role::Publisher).cloned().collect();
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}


/// How long discovery must have been quiet (no participant or endpoint new
/// to the emulator) before the subscribers of a lane's topic are taken as
/// those there at start: a participant's endpoints come soon after the
/// participant, but one participant's may come well after another's (the
/// publisher's), and a subscriber of another type found only after the
/// lane opened would be logged, not refused.
const QUIET_NS: u64 = 1_000_000_000;

/// The longest that wait, in a domain where nodes keep coming.
const QUIET_MAX_NS: u64 = 5_000_000_000;

/// Polls the graph until discovery has been quiet for [`QUIET_NS`], or
/// [`QUIET_MAX_NS`] has passed.
fn quiet(node: &mut Ros2Node) {
    let t0 = crate::clock::now_ns();
    loop {
        let now = crate::clock::now_ns();
        node.poll(now);
        if now.saturating_sub(node.last_discovery_ns) >= QUIET_NS || now - t0 >= QUIET_MAX_NS {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The node of `guid`, waiting for its name up to [`NAME_WAIT_NS`]; else
/// the GUID. Only where a message names it: a refusal.
fn named(node: &mut Ros2Node, guid: rustdds::GUID) -> String {
    let t0 = crate::clock::now_ns();
    loop {
        let now = crate::clock::now_ns();
        node.poll(now);
        if let Some(n) = node.node_of(guid) {
            return n;
        }
        if now - t0 >= NAME_WAIT_NS {
            return node.name(guid);
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Decides the type and QoS of a lane's `from` → `to`, from what is given
/// and what is discovered, and checks every publisher of `from` and
/// subscriber of `to` against them. A mismatch is an error that names both
/// sides.
fn settle(node: &mut Ros2Node, plan: &Plan, from: &TopicName, to: &TopicName) -> Result<Opened, TopicError> {
    let given = plan.types.get(from);
    eprintln!("emulator: looking for the publisher of {from} (up to {:.0} s)", plan.discovery_ns as f64 / 1e9);
    let pubs = discover(node, from, plan.discovery_ns);
    let mut types: Vec<&str> = pubs.iter().map(|p| p.dds_type.as_str()).collect();
    types.sort_unstable();
    types.dedup();
    let (type_name, type_from) = match (given, &types[..]) {
        (Some(t), _) => {
            if let Some(p) = pubs.iter().find(|p| p.dds_type != t.dds()) {
                return Err(TopicError::PublisherType { from: from.clone(), given: t.clone(), publisher: named(node, p.guid), publishes: shown(&p.dds_type) });
            }
            (t.clone(), "command_line")
        }
        (None, [one]) => {
            let t = TypeName::parse(one).map_err(|cause| TopicError::NotAType { from: from.clone(), announced: one.to_string(), cause })?;
            (t, "publisher")
        }
        (None, []) => return Err(TopicError::NoPublisher { from: from.clone(), seconds: plan.discovery_ns as f64 / 1e9, domain: plan.domain }),
        (None, many) => return Err(TopicError::Disagree { from: from.clone(), types: many.join(", ") }),
    };
    if pubs.is_empty() {
        eprintln!("emulator: WARNING: no publisher of {from} yet; relaying {type_name} as given");
    }
    let offered = qos::weakest(pubs.iter().map(|p| &p.qos));
    let (requested, qos_from) = match (plan.qos.get(from), &offered) {
        (Some(text), _) => (qos::parse(text, &qos::ros_default())?, "command_line"),
        (None, Some(o)) => (o.clone(), "publisher"),
        (None, None) => (qos::ros_default(), "default"),
    };
    let reader_qos = qos::reader(&requested);
    for p in &pubs {
        if qos::check(&p.qos, &reader_qos, "", "").is_err() {
            let name = named(node, p.guid);
            qos::check(&p.qos, &reader_qos, &format!("the publisher {name} of {from}"), &format!("the emulator's reader (--ros2-qos {from}=…)"))
                .map_err(|why| TopicError::Qos { topic: from.clone(), why })?;
        }
    }
    // The writer offers what the publishers offered (their subscribers
    // were configured for it), or what is given.
    let base = qos::relay(offered.as_ref());
    let writer_qos = match plan.qos.get(to) {
        Some(text) => qos::parse(text, &base)?,
        None => base,
    };
    quiet(node);
    let subs: Vec<Remote> = node.remotes(to, Role::Subscriber).cloned().collect();
    for s in &subs {
        let bad = s.dds_type != type_name.dds() || qos::check(&qos::writer(&writer_qos), &s.qos, "", "").is_err();
        let name = if bad { named(node, s.guid) } else { continue };
        if s.dds_type != type_name.dds() {
            return Err(TopicError::SubscriberType { to: to.clone(), subscriber: name, expects: shown(&s.dds_type), relays: type_name, from: from.clone() });
        }
        qos::check(&qos::writer(&writer_qos), &s.qos, &format!("the emulator's writer (the QoS of {from}'s publisher, or --ros2-qos {to}=…)"), &format!("the subscriber {name} of {to}"))
            .map_err(|why| TopicError::Qos { topic: to.clone(), why })?;
    }
    let type_hash = pubs.iter().find_map(|p| p.type_hash.clone());
    Ok(Opened { type_name, type_hash, type_from, qos_from, reader_qos, writer_qos })
}

/// Opens the channel of `from` → `to` as `o` decided: its writer first,
/// so that a publisher that waits for a subscriber (the emulator's reader)
/// does not publish before the emulator can relay; with `wait_ns`, the
/// reader only once `to` has a subscriber of the lane's type (or after
/// that long), so that nothing is released into nothing.
fn ports(node: &RefCell<Ros2Node>, plan: &Plan, o: &Opened, (from, to): (&TopicName, &TopicName), slots: usize, idle_end_ns: Option<u64>, wait_ns: Option<u64>) -> Result<TopicPorts, TopicError> {
    let writer = node.borrow().writer(to, &o.type_name, &o.writer_qos)?;
    if let Some(wait_ns) = wait_ns {
        eprintln!("emulator: waiting up to {:.1} s for a subscriber of {to} ({}) before reading {from}", wait_ns as f64 / 1e9, o.type_name);
        let t0 = crate::clock::now_ns();
        loop {
            let now = crate::clock::now_ns();
            let mut n = node.borrow_mut();
            n.poll(now);
            let found = n.remotes(to, Role::Subscriber).find(|s| s.dds_type == o.type_name.dds()).map(|s| s.guid);
            if let Some(s) = found {
                let came = match now.saturating_sub(t0) {
                    0..=50_000_000 => "is there".to_string(),
                    waited => format!("came after {:.1} s", waited as f64 / 1e9),
                };
                let name = named(&mut n, s);
                eprintln!("emulator: the subscriber {name} of {to} {came}: reading {from}");
                break;
            }
            // A subscriber that came meanwhile with another type is refused
            // as one found when the lane was settled.
            let other = n.remotes(to, Role::Subscriber).find(|s| s.dds_type != o.type_name.dds()).cloned();
            if let Some(s) = other {
                let name = named(&mut n, s.guid);
                return Err(TopicError::SubscriberType { to: to.clone(), subscriber: name, expects: shown(&s.dds_type), relays: o.type_name.clone(), from: from.clone() });
            }
            if now - t0 >= wait_ns {
                eprintln!("emulator: WARNING: no subscriber of {to} within {:.1} s; relaying anyway", wait_ns as f64 / 1e9);
                break;
            }
            drop(n);
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
    if wait_ns.is_none() && !node.borrow().remotes(to, Role::Subscriber).any(|s| s.dds_type == o.type_name.dds()) {
        eprintln!("emulator: no subscriber of {to} yet: what is released before one comes goes nowhere (delivered_unsubscribed; --wait-for-peer-s S waits for one)");
    }
    let reader = node.borrow().reader(from, &o.type_name, &o.reader_qos)?;
    Ok(TopicPorts {
        reader,
        writer,
        from: from.clone(),
        to: to.clone(),
        type_name: o.type_name.clone(),
        slots,
        max_bytes: plan.max_bytes,
        linger_ns: plan.linger_ns,
        idle_end_ns,
    })
}

/// A lane of ROS 2 topics.
pub type Ros2Lane = Lane<Topic<Forward>>;

/// What the end of a lane needs: how its topics were opened.
struct LaneEnd {
    forward: Opened,
    ret: Option<Opened>,
}

/// Settles lane `topics`' type and QoS in each direction.
fn settle_lane(node: &RefCell<Ros2Node>, plan: &Plan, topics: &LaneTopics) -> Result<LaneEnd, TopicError> {
    let (from, to) = &topics.forward;
    let forward = settle(&mut node.borrow_mut(), plan, from, to)?;
    let ret = topics.ret.as_ref().map(|(from, to)| settle(&mut node.borrow_mut(), plan, from, to)).transpose()?;
    Ok(LaneEnd { forward, ret })
}

/// Opens a lane as `end` settled it: its channels, its forward path and its
/// return path (before the loop is pinned: each path starts its trace
/// writer).
fn open_lane(node: &Rc<RefCell<Ros2Node>>, plan: &Plan, l: &LaneConfig, topics: &LaneTopics, end: &LaneEnd, t0_ns: u64) -> Result<Ros2Lane, TopicError> {
    std::fs::create_dir_all(&l.out_dir).map_err(|cause| OpenError::Dir { dir: l.out_dir.clone(), cause })?;
    let a = &l.args;
    let (from, to) = &topics.forward;
    let idle_end_ns = a.ends.idle_end_ms.map(|ms| (ms * 1e6) as u64);
    let wait_ns = a.wait_for_peer_s.map(|s| (s * 1e9) as u64);
    let chan = Topic::<Forward>::new(ports(node, plan, &end.forward, (from, to), l.queue_capacity + 1, idle_end_ns, wait_ns)?, node.clone(), t0_ns);
    let scenario = Scenario::new(&l.scenario, l.seed).map_err(OpenError::from)?;
    let forward = Path::new(chan, scenario, l.seed, l.queue_capacity, a.expected_frames, &l.out_dir, true).map_err(OpenError::from)?;
    let mut reverse: Vec<Box<dyn Reverse>> = Vec::new();
    if let (Some((from, to)), Some(o)) = (&topics.ret, &end.ret) {
        let r = &a.channels.feedback;
        let rp = PathPlan::resolve("--return-scenario", r.return_scenario.as_deref(), r.return_seed, l.seed, seeds::ROS2_RETURN_TAG, DEFAULT_QUEUE_CAPACITY)?;
        let chan = Topic::<Return>::new(ports(node, plan, o, (from, to), rp.queue_capacity + 1, None, None)?, node.clone(), t0_ns);
        reverse.push(Box::new(rp.open(chan, a.expected_frames, &l.out_dir)?));
    }
    Ok(Lane::new(forward, reverse))
}

/// What `node` saw of `from`'s publishers and `to`'s subscribers, `t0_ns`
/// being the time it joined.
fn seen(node: &Ros2Node, from: &TopicName, to: &TopicName, t0_ns: u64) -> (Vec<EndpointSeen>, Vec<EventRow>) {
    let mine = |role: Role, topic: &TopicName| (role == Role::Publisher && topic == from) || (role == Role::Subscriber && topic == to);
    let t_s = |t: u64| t.saturating_sub(t0_ns) as f64 / 1e9;
    let mut endpoints: Vec<EndpointSeen> = Vec::new();
    let mut events = Vec::new();
    for e in node.events.iter().filter(|e| mine(e.role, &e.topic)) {
        let name = node.name(e.guid);
        let (what, detail) = match &e.happened {
            Happened::Joined => {
                endpoints.push(EndpointSeen {
                    role: e.role,
                    topic: e.topic.to_string(),
                    node: name.clone(),
                    type_name: TypeName::parse(&e.dds_type).map_or(e.dds_type.clone(), |t| t.to_string()),
                    type_hash: None,
                    joined_s: Some(t_s(e.t_ns)),
                    left_s: None,
                    left: None,
                });
                ("joined", e.dds_type.to_string())
            }
            Happened::Left { reason } => {
                let guid = crate::transport::ros2::node::guid_hex(e.guid);
                if let Some(p) = endpoints.iter_mut().rev().find(|p| p.node == name && p.left.is_none() && p.role == e.role) {
                    p.left_s = Some(t_s(e.t_ns));
                    p.left = Some(reason);
                }
                ("left", format!("{reason} ({guid})"))
            }
            Happened::QosIncompatible(m) => ("qos_incompatible", m.to_string()),
        };
        events.push(EventRow { t_s: t_s(e.t_ns), role: e.role, topic: e.topic.to_string(), node: name, what, detail });
    }
    for p in endpoints.iter_mut() {
        p.type_hash = node.remotes(&TopicName::parse(&p.topic).expect("a topic name"), p.role).find(|r| node.name(r.guid) == p.node).and_then(|r| r.type_hash.clone());
    }
    (endpoints, events)
}

/// `ros2.json`'s part of one direction.
fn topic_report<D: crate::service::emulator::ros2::topic::Direction>(node: &Ros2Node, o: &Opened, chan: Option<&Topic<D>>, from: &TopicName, to: &TopicName, max_bytes: usize, t0_ns: u64) -> TopicReport {
    let (endpoints, events) = seen(node, from, to, t0_ns);
    let (slots, _, high) = chan.map_or((0, 0, 0), |c| c.slots());
    TopicReport {
        from: from.to_string(),
        to: to.to_string(),
        type_name: o.type_name.to_string(),
        type_hash: o.type_hash.clone(),
        type_from: o.type_from,
        qos_from: o.qos_from,
        reader_qos: Summary::of(&o.reader_qos),
        writer_qos: Summary::of(&qos::writer(&o.writer_qos)),
        max_bytes,
        slots,
        slots_high_water: high,
        lost_before_ingress: chan.map_or(0, |c| c.counts.lost_before_ingress),
        sent_before_emulator: chan.map_or(0, |c| c.sent_before_first()),
        writers_untracked: chan.map_or(0, |c| c.counts.writers_untracked),
        window_full: chan.map_or(0, |c| c.counts.window_full),
        bad_encoding: chan.and_then(|c| c.counts.last_bad_encoding),
        ended: chan.and_then(|c| c.end.clone()),
        motion: chan.and_then(|c| c.motion.as_ref()).map(|m| m.report()),
        endpoints,
        events,
    }
}

/// Runs the emulator of `args`' ROS 2 lanes; their reports.
pub fn main(args: &EmulatorArgs) -> Result<Vec<EmulatorReport>, super::EmulatorError> {
    let plan = Plan::of(args)?;
    let cfg = config(args, plan.lanes.len())?;
    crate::service::write_pid(&cfg.out_dir, "emulator")?;
    // The participant's threads (receive, discovery, send) start now and
    // keep the mask of the thread that starts them: off the loop's core.
    crate::host::placement::place("ROS 2 participant", None, cfg.core)?;
    let t0_ns = crate::clock::now_ns();
    let node = Rc::new(RefCell::new(Ros2Node::open(plan.domain)?));
    eprintln!("emulator: ROS 2 domain {}; {} lane(s)", plan.domain, plan.lanes.len());
    // Every topic is settled before any is read: a publisher that starts
    // once the emulator subscribes waits for the whole set-up, not for the
    // discovery of another lane's topics.
    let in_lane = |k: usize| {
        let (from, to) = plan.lanes[k].forward.clone();
        move |cause| super::EmulatorError::Lane { lane: k, from, to, cause }
    };
    let ends = plan.lanes.iter().enumerate().map(|(k, t)| settle_lane(&node, &plan, t).map_err(in_lane(k))).collect::<Result<Vec<_>, _>>()?;
    let mut lanes = Vec::new();
    for (k, ((l, topics), end)) in cfg.lanes.iter().zip(&plan.lanes).zip(&ends).enumerate() {
        lanes.push(open_lane(&node, &plan, l, topics, end, t0_ns).map_err(in_lane(k))?);
        let o = &end.forward;
        eprintln!(
            "emulator: lane {k}: {} → {} ({}, {} QoS {}), scenario {} seed {}, queue {}",
            topics.forward.0,
            topics.forward.1,
            o.type_name,
            o.qos_from,
            serde_json::to_string(&Summary::of(&o.reader_qos)).unwrap_or_default(),
            l.scenario.name,
            l.seed,
            l.queue_capacity
        );
    }
    let nodes: Vec<Option<&crate::transport::IpcNode>> = (0..lanes.len()).map(|_| None).collect();
    let before_finish = |k: usize, lane: &Ros2Lane| {
        let topics = &plan.lanes[k];
        let end = &ends[k];
        let n = node.borrow();
        let (from, to) = &topics.forward;
        let mut report = Ros2Report {
            domain_id: plan.domain,
            balanced: false,
            forward: topic_report(&n, &end.forward, Some(&lane.forward.chan), from, to, plan.max_bytes, t0_ns),
            return_path: topics.ret.as_ref().zip(end.ret.as_ref()).map(|((f, t), o)| topic_report::<Return>(&n, o, None, f, t, plan.max_bytes, t0_ns)),
            events_dropped: n.events_dropped,
        };
        let dir = cfg.lanes[k].out_dir.clone();
        let after: run::After = Box::new(move |r: &EmulatorReport| {
            let a = &r.process.frames.account;
            let f = &report.forward;
            report.balanced = a.closes()
                && match (&f.ended, r.process.frames.sent_by_console) {
                    (Some(_), Some(sent)) => sent == a.entered + f.lost_before_ingress + f.sent_before_emulator,
                    _ => true,
                };
            super::report::write_json(&dir.join("ros2.json"), &report)?;
            eprintln!(
                "emulator: {} → {}: {} entered, {} delivered, {} dropped {:?}, {} held at end, {} lost before ingress; ended by {}{}",
                report.forward.from,
                report.forward.to,
                a.entered,
                a.delivered,
                a.dropped_total(),
                a.dropped,
                a.held_at_end,
                report.forward.lost_before_ingress,
                r.process.ended_by,
                report.forward.ended.as_ref().map_or(String::new(), |e| format!(" ({})", e.detail))
            );
            Ok(())
        });
        after
    };
    Ok(run::run(&cfg, lanes, &nodes, before_finish)?)
}
