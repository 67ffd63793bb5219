//! The emulator's ROS 2 flags resolved once: each lane's topics (forward
//! and return), the types and QoS given by topic, the domain and limits
//! ([`Plan`]); and each lane's scenario, seed, queue and directory by the
//! rules of several streams ([`config`]).

use crate::service::args::{EmulatorArgs, ScenarioArgs, StreamArgs};
use crate::service::emulator::config::{EmulatorConfig, LaneConfig};
use crate::service::seeds;
use crate::transport::ros2::qos;
use crate::transport::ros2::{TopicName, TypeName};
use anyhow::{bail, Context};
use std::collections::BTreeMap;

/// Default release-queue capacity of a ROS 2 lane: 4096 messages (4 s at
/// 1 kHz; 256 MiB of address space at 64 KiB a slot, of which only what
/// messages touch becomes resident).
pub const DEFAULT_QUEUE_CAPACITY: usize = 4096;

/// The most memory a lane's slots may reserve: 64 GiB.
const SLOTS_BYTES_MAX: usize = 64 << 30;

/// One lane's topics, as the arguments name them.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneTopics {
    pub forward: (TopicName, TopicName),
    pub ret: Option<(TopicName, TopicName)>,
}

/// `IN=OUT`.
fn pair(flag: &str, text: &str) -> anyhow::Result<(TopicName, TopicName)> {
    let (a, b) = text.split_once('=').with_context(|| format!("{flag} {text}: expected IN=OUT, two topic names"))?;
    Ok((TopicName::parse(a.trim()).with_context(|| format!("{flag} {text}"))?, TopicName::parse(b.trim()).with_context(|| format!("{flag} {text}"))?))
}

/// `TOPIC=VALUE` flags, by topic.
fn by_topic(flag: &str, texts: &[String]) -> anyhow::Result<BTreeMap<TopicName, String>> {
    let mut m = BTreeMap::new();
    for text in texts {
        let (t, v) = text.split_once('=').with_context(|| format!("{flag} {text}: expected TOPIC=VALUE"))?;
        let t = TopicName::parse(t.trim()).with_context(|| format!("{flag} {text}"))?;
        anyhow::ensure!(m.insert(t.clone(), v.trim().to_string()).is_none(), "{flag}: {t} given twice");
    }
    Ok(m)
}

/// The ROS 2 domain: `given`, else `$ROS_DOMAIN_ID`, else 0.
pub fn domain(given: Option<u16>) -> anyhow::Result<u16> {
    let domain = match given {
        Some(d) => d,
        None => match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.trim().is_empty() => v.trim().parse().with_context(|| format!("ROS_DOMAIN_ID={v}: not a domain id"))?,
            _ => 0,
        },
    };
    // DDS's default port mapping leaves room for domains 0 to 232.
    anyhow::ensure!(domain <= 232, "ROS 2 domain {domain}: domain ids go from 0 to 232");
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
    pub fn of(a: &EmulatorArgs) -> anyhow::Result<Plan> {
        let r = &a.ros2;
        if a.udp.ingress.is_udp() || a.udp.egress.is_udp() {
            bail!("--ros2-topic relays ROS 2 topics: --ingress and --egress (iceoryx2 or UDP endpoints) do not apply");
        }
        if a.stream.streams > 1 {
            bail!("--ros2-topic makes a lane of each pair; --streams does not apply (give --ros2-topic once per lane)");
        }
        if a.video.on() || a.return_path.no_feedback || a.udp.return_to.is_some() || a.udp.no_return || a.udp.payload == crate::transport::Payload::Raw {
            bail!("--video-mbps, --no-feedback, --return-to, --no-return and --payload apply to iceoryx2 and UDP lanes, not to ROS 2 topics");
        }
        if r.ros2_return.len() > r.ros2_topic.len() {
            bail!("--ros2-return given {} times for {} lanes (--ros2-topic): the K-th return topic is lane K's", r.ros2_return.len(), r.ros2_topic.len());
        }
        anyhow::ensure!(r.ros2_max_bytes >= 1, "--ros2-max-bytes must be at least 1");
        if let Some(s) = a.wait_for_peer_s.filter(|s| !(s.is_finite() && *s >= 0.0)) {
            bail!("--wait-for-peer-s must be a non-negative number of seconds, got {s}");
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
                anyhow::ensure!(from != to, "{from} relayed onto itself: a lane's output would be its own input");
                anyhow::ensure!(read.insert(from.clone()), "{from} is read by two lanes (or a lane and a return)");
            }
        }
        let types = by_topic("--ros2-type", &r.ros2_type)?
            .into_iter()
            .map(|(t, v)| Ok((t.clone(), TypeName::parse(&v).with_context(|| format!("--ros2-type {t}={v}"))?)))
            .collect::<anyhow::Result<BTreeMap<_, _>>>()?;
        let qos = by_topic("--ros2-qos", &r.ros2_qos)?;
        for (t, text) in &qos {
            qos::parse(text, &qos::ros_default()).with_context(|| format!("--ros2-qos {t}"))?;
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
pub fn config(args: &EmulatorArgs, lanes: usize) -> anyhow::Result<EmulatorConfig> {
    let mut scenarios = BTreeMap::new();
    for text in &args.stream.stream_scenario {
        let (k, what) = crate::service::args::groups::parse_stream_scenario(text, lanes as u32)?;
        scenarios.insert(k, what);
    }
    let spec = crate::load::resolve(&args.scenario.scenario)?;
    let seed = seeds::run(args.scenario.seed, &spec);
    let mut out = Vec::new();
    for k in 0..lanes {
        let name = scenarios.get(&k).unwrap_or(&args.scenario.scenario).clone();
        let scenario = crate::load::resolve(&name).with_context(|| format!("lane {k}"))?;
        let lane_seed = seeds::stream(seed, k);
        let queue_capacity = args.scenario.queue_capacity.or(scenario.queue_capacity).unwrap_or(DEFAULT_QUEUE_CAPACITY);
        anyhow::ensure!(queue_capacity >= 1, "--queue-capacity must be at least 1 message");
        let bytes = (queue_capacity + 1).checked_mul(args.ros2.ros2_max_bytes).filter(|b| *b <= SLOTS_BYTES_MAX);
        anyhow::ensure!(
            bytes.is_some(),
            "lane {k}: {} slots of --ros2-max-bytes {} exceed {} GiB; lower --queue-capacity or --ros2-max-bytes",
            queue_capacity + 1,
            args.ros2.ros2_max_bytes,
            SLOTS_BYTES_MAX >> 30
        );
        let out_dir = crate::service::args::streams::dir(&args.out, lanes, k);
        let mut lane_args = EmulatorArgs {
            scenario: ScenarioArgs { scenario: name, seed: Some(lane_seed), queue_capacity: args.scenario.queue_capacity },
            out: out_dir.clone(),
            stream: StreamArgs::default(),
            ..args.clone()
        };
        lane_args.return_path.return_seed = args.return_path.return_seed.map(|s| seeds::stream(s, k));
        out.push(LaneConfig { args: lane_args, scenario, seed: lane_seed, queue_capacity, out_dir });
    }
    EmulatorConfig::with_lanes(args, out)
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
