//! The emulator's ROS 2 flags resolved once: each lane's topics (forward
//! and return), the types and QoS given by topic, the domain and limits
//! ([`Plan`]); and each lane's scenario, seed, queue and directory by the
//! rules of several streams ([`config`]).

use crate::service::args::{EmulatorArgs, ScenarioArgs, StreamArgs};
use crate::service::emulator::config::{ConfigError, EmulatorConfig, LaneConfig};
use crate::service::seeds;
use crate::scenario::ScenarioError;
use crate::service::args::ArgsError;
use crate::transport::ros2::qos;
use crate::transport::ros2::{NameError, TopicName, TypeName};
use std::collections::BTreeMap;

/// Default release-queue capacity of a ROS 2 lane: 4096 messages (4 s at
/// 1 kHz; 256 MiB of address space at 64 KiB a slot, of which only what
/// messages touch becomes resident).
pub const DEFAULT_QUEUE_CAPACITY: usize = 4096;

/// The most memory a lane's slots may reserve: 64 GiB.
const SLOTS_BYTES_MAX: usize = 64 << 30;

/// Why the ROS 2 flags make no emulator.
#[derive(Debug, thiserror::Error)]
pub enum Ros2PlanError {
    #[error("--ros2-topic relays ROS 2 topics: --ingress and --egress (iceoryx2 or UDP endpoints) do not apply")]
    Endpoints,
    #[error("--ros2-topic makes a lane of each pair; --streams does not apply (give --ros2-topic once per lane)")]
    Streams,
    #[error("--video-mbps, --no-feedback, --return-to, --no-return and --payload apply to iceoryx2 and UDP lanes, not to ROS 2 topics")]
    NotForTopics,
    #[error("--ros2-return given {returns} times for {lanes} lanes (--ros2-topic): the K-th return topic is lane K's")]
    Returns { returns: usize, lanes: usize },
    #[error("--ros2-max-bytes must be at least 1")]
    MaxBytes,
    #[error("--wait-for-peer-s must be a non-negative number of seconds, got {0}")]
    WaitForPeer(f64),
    /// A flag's value without its `=`.
    #[error("{flag} {text}: expected {expected}")]
    Shape { flag: &'static str, text: String, expected: &'static str },
    /// A flag's topic or type name.
    #[error("{flag} {text}: {cause}")]
    Name { flag: &'static str, text: String, cause: NameError },
    #[error("{flag}: {topic} given twice")]
    Twice { flag: &'static str, topic: TopicName },
    #[error("{0} relayed onto itself: a lane's output would be its own input")]
    OntoItself(TopicName),
    #[error("{0} is read by two lanes (or a lane and a return)")]
    ReadTwice(TopicName),
    #[error("--ros2-qos {topic}: {cause}")]
    Qos { topic: TopicName, cause: qos::QosParseError },
    #[error("ROS_DOMAIN_ID={text}: not a domain id: {cause}")]
    DomainEnv { text: String, cause: std::num::ParseIntError },
    #[error("ROS 2 domain {0}: domain ids go from 0 to 232")]
    Domain(u16),
    /// A lane's `--stream-scenario`.
    #[error(transparent)]
    Args(#[from] ArgsError),
    /// A lane's scenario (`lane` is `None` for the run's own).
    #[error("{}{cause}", lane.map(|k| format!("lane {k}: ")).unwrap_or_default())]
    Scenario { lane: Option<usize>, cause: ScenarioError },
    #[error("--queue-capacity must be at least 1 message")]
    QueueCapacity,
    /// The lanes' placement and control.
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("lane {lane}: {slots} slots of --ros2-max-bytes {max_bytes} exceed {gib} GiB; lower --queue-capacity or --ros2-max-bytes")]
    SlotsTooLarge { lane: usize, slots: usize, max_bytes: usize, gib: usize },
}

/// One lane's topics, as the arguments name them.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneTopics {
    pub forward: (TopicName, TopicName),
    pub ret: Option<(TopicName, TopicName)>,
}

/// `IN=OUT`.
fn pair(flag: &'static str, text: &str) -> Result<(TopicName, TopicName), Ros2PlanError> {
    let (a, b) = text.split_once('=').ok_or_else(|| Ros2PlanError::Shape { flag, text: text.into(), expected: "IN=OUT, two topic names" })?;
    Ok((topic(flag, text, a)?, topic(flag, text, b)?))
}

/// The topic `name` of `flag text`.
fn topic(flag: &'static str, text: &str, name: &str) -> Result<TopicName, Ros2PlanError> {
    TopicName::parse(name.trim()).map_err(|cause| Ros2PlanError::Name { flag, text: text.into(), cause })
}

/// `TOPIC=VALUE` flags, by topic.
fn by_topic(flag: &'static str, texts: &[String]) -> Result<BTreeMap<TopicName, String>, Ros2PlanError> {
    let mut m = BTreeMap::new();
    for text in texts {
        let (t, v) = text.split_once('=').ok_or_else(|| Ros2PlanError::Shape { flag, text: text.clone(), expected: "TOPIC=VALUE" })?;
        let t = topic(flag, text, t)?;
        if m.insert(t.clone(), v.trim().to_string()).is_some() {
            return Err(Ros2PlanError::Twice { flag, topic: t });
        }
    }
    Ok(m)
}

/// The ROS 2 domain: `given`, else `$ROS_DOMAIN_ID`, else 0.
pub fn domain(given: Option<u16>) -> Result<u16, Ros2PlanError> {
    let domain = match given {
        Some(d) => d,
        None => match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.trim().is_empty() => v.trim().parse().map_err(|cause| Ros2PlanError::DomainEnv { text: v.clone(), cause })?,
            _ => 0,
        },
    };
    // DDS's default port mapping leaves room for domains 0 to 232.
    if domain > 232 {
        return Err(Ros2PlanError::Domain(domain));
    }
    Ok(domain)
}

/// The ROS 2 arguments resolved: each lane's topics, the given types and
/// QoS by topic, and the domain.
#[derive(Debug, Clone)]
pub struct Plan {
    pub lanes: Vec<LaneTopics>,
    pub types: BTreeMap<TopicName, TypeName>,
    pub qos: BTreeMap<TopicName, String>,
    pub domain: u16,
    pub max_bytes: usize,
    pub discovery_ns: u64,
    pub linger_ns: u64,
}

impl Plan {
    pub fn of(a: &EmulatorArgs) -> Result<Plan, Ros2PlanError> {
        let r = &a.ros2;
        if a.ends.ingress != crate::service::args::EndsArgs::default().ingress || a.ends.egress != crate::service::args::EndsArgs::default().egress {
            return Err(Ros2PlanError::Endpoints);
        }
        if a.stream.streams > 1 {
            return Err(Ros2PlanError::Streams);
        }
        if a.channels.video.on() || a.channels.feedback.no_feedback || a.transports != crate::transport::TransportArgs::default() {
            return Err(Ros2PlanError::NotForTopics);
        }
        if r.ros2_return.len() > r.ros2_topic.len() {
            return Err(Ros2PlanError::Returns { returns: r.ros2_return.len(), lanes: r.ros2_topic.len() });
        }
        if r.ros2_max_bytes < 1 {
            return Err(Ros2PlanError::MaxBytes);
        }
        if let Some(s) = a.wait_for_peer_s.filter(|s| !(s.is_finite() && *s >= 0.0)) {
            return Err(Ros2PlanError::WaitForPeer(s));
        }
        let mut lanes = Vec::new();
        for (k, text) in r.ros2_topic.iter().enumerate() {
            let forward = pair("--ros2-topic", text)?;
            let ret = r.ros2_return.get(k).map(|t| pair("--ros2-return", t)).transpose()?;
            lanes.push(LaneTopics { forward, ret });
        }
        // A topic is read by one lane only: two readers of one topic would
        // each relay every message.
        let mut read = std::collections::BTreeSet::new();
        for l in &lanes {
            for (from, to) in std::iter::once(&l.forward).chain(&l.ret) {
                if from == to {
                    return Err(Ros2PlanError::OntoItself(from.clone()));
                }
                if !read.insert(from.clone()) {
                    return Err(Ros2PlanError::ReadTwice(from.clone()));
                }
            }
        }
        let types = by_topic("--ros2-type", &r.ros2_type)?
            .into_iter()
            .map(|(t, v)| match TypeName::parse(&v) {
                Ok(n) => Ok((t, n)),
                Err(cause) => Err(Ros2PlanError::Name { flag: "--ros2-type", text: format!("{t}={v}"), cause }),
            })
            .collect::<Result<BTreeMap<_, _>, _>>()?;
        let qos = by_topic("--ros2-qos", &r.ros2_qos)?;
        for (t, text) in &qos {
            qos::parse(text, &qos::ros_default()).map_err(|cause| Ros2PlanError::Qos { topic: t.clone(), cause })?;
        }
        let domain = domain(r.ros2_domain)?;
        Ok(Plan {
            lanes,
            types,
            qos,
            domain,
            max_bytes: r.ros2_max_bytes,
            discovery_ns: (r.ros2_discovery_s * 1e9) as u64,
            linger_ns: (r.ros2_linger_ms * 1e6) as u64,
        })
    }
}

/// The emulator of `args`' ROS 2 lanes: each lane's own arguments,
/// scenario, seed, queue and directory (by the rules of several streams:
/// `--stream-scenario K=…`, the seed derived for lane K), the loop's place
/// and live control.
pub fn config(args: &EmulatorArgs, lanes: usize) -> Result<EmulatorConfig, Ros2PlanError> {
    let mut scenarios = BTreeMap::new();
    for text in &args.stream.stream_scenario {
        let (k, what) = crate::service::args::groups::parse_stream_scenario(text, lanes as u32)?;
        scenarios.insert(k, what);
    }
    let spec = crate::load::resolve(&args.scenario.scenario).map_err(|cause| Ros2PlanError::Scenario { lane: None, cause })?;
    let seed = seeds::run(args.scenario.seed, &spec);
    let mut out = Vec::new();
    for k in 0..lanes {
        let name = scenarios.get(&k).unwrap_or(&args.scenario.scenario).clone();
        let scenario = crate::load::resolve(&name).map_err(|cause| Ros2PlanError::Scenario { lane: Some(k), cause })?;
        let lane_seed = seeds::stream(seed, k);
        let queue_capacity = args.scenario.queue_capacity.or(scenario.queue_capacity).unwrap_or(DEFAULT_QUEUE_CAPACITY);
        if queue_capacity < 1 {
            return Err(Ros2PlanError::QueueCapacity);
        }
        let bytes = (queue_capacity + 1).checked_mul(args.ros2.ros2_max_bytes).filter(|b| *b <= SLOTS_BYTES_MAX);
        if bytes.is_none() {
            return Err(Ros2PlanError::SlotsTooLarge { lane: k, slots: queue_capacity + 1, max_bytes: args.ros2.ros2_max_bytes, gib: SLOTS_BYTES_MAX >> 30 });
        }
        let out_dir = crate::service::args::streams::dir(&args.out, lanes, k);
        let mut lane_args = EmulatorArgs {
            scenario: ScenarioArgs { scenario: name, seed: Some(lane_seed), queue_capacity: args.scenario.queue_capacity },
            out: out_dir.clone(),
            stream: StreamArgs::default(),
            ..args.clone()
        };
        lane_args.channels.map_seeds(|s| seeds::stream(s, k));
        out.push(LaneConfig { args: lane_args, scenario, seed: lane_seed, queue_capacity, out_dir });
    }
    Ok(EmulatorConfig::with_lanes(args, out)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        e: EmulatorArgs,
    }

    fn args(extra: &[&str]) -> EmulatorArgs {
        let mut v = vec!["emulator", "--scenario", "PLM-2", "--seed", "5"];
        v.extend_from_slice(extra);
        Cli::parse_from(v).e
    }

    #[test]
    fn lanes_come_from_the_topic_pairs_with_their_returns_types_and_qos() {
        let a = args(&[
            "--ros2-topic",
            "/MTMR/measured_cp=/PSM1/servo_cp",
            "--ros2-topic",
            "/MTML/measured_cp=/PSM2/servo_cp",
            "--ros2-return",
            "/PSM1/measured_cp=/MTMR/feedback",
            "--ros2-type",
            "/MTMR/measured_cp=geometry_msgs/msg/PoseStamped",
            "--ros2-qos",
            "/PSM1/servo_cp=best_effort",
            "--ros2-domain",
            "7",
        ]);
        let p = Plan::of(&a).unwrap();
        assert_eq!(p.lanes.len(), 2);
        assert_eq!(p.lanes[0].forward.1.as_str(), "/PSM1/servo_cp");
        assert_eq!(p.lanes[0].ret.as_ref().unwrap().0.as_str(), "/PSM1/measured_cp");
        assert!(p.lanes[1].ret.is_none());
        assert_eq!(p.types[&TopicName::parse("/MTMR/measured_cp").unwrap()].dds(), "geometry_msgs::msg::dds_::PoseStamped_");
        assert_eq!(p.domain, 7);
        let cfg = config(&a, 2).unwrap();
        // Lane 0 keeps the run's seed; lane 1 gets its own; each its directory.
        assert_eq!((cfg.lanes[0].seed, cfg.lanes[1].seed), (5, seeds::stream(5, 1)));
        assert!(cfg.lanes[1].out_dir.ends_with("stream-1"));
        assert_eq!(cfg.lanes[0].queue_capacity, DEFAULT_QUEUE_CAPACITY);
    }

    #[test]
    fn bad_ros2_arguments_say_what_is_wrong() {
        for (extra, says) in [
            (&["--ros2-topic", "/a"][..], "expected IN=OUT"),
            (&["--ros2-topic", "/a=/a"], "onto itself"),
            (&["--ros2-topic", "/a=/b", "--ros2-topic", "/a=/c"], "read by two lanes"),
            (&["--ros2-topic", "/a=/b", "--ros2-return", "/c=/d", "--ros2-return", "/e=/f"], "the K-th return topic"),
            (&["--ros2-topic", "/a=/b", "--ros2-type", "/a=PoseStamped"], "package/msg/Type"),
            (&["--ros2-topic", "/a=/b", "--ros2-qos", "/a=fast"], "is not a policy"),
            (&["--ros2-topic", "/a=/b", "--ros2-domain", "300"], "0 to 232"),
            (&["--ros2-topic", "/a=/b", "--ingress", "udp://127.0.0.1:9"], "do not apply"),
            (&["--ros2-topic", "/1a=/b"], "digit"),
        ] {
            let e = Plan::of(&args(extra)).map(|_| ()).unwrap_err();
            assert!(format!("{e:#}").contains(says), "{extra:?}: {e:#}");
        }
    }
}
