//! The emulator's ROS 2 flags (`netfi emulator --ros2-topic …`): the topic
//! pairs that make its lanes, their return topics, the types and QoS given,
//! the domain and the limits. `crate::service::emulator::ros2` resolves
//! them.

use crate::flags::values::{wait_millis, wait_seconds};
use crate::flags::{Argv, Render};
use clap::Args;

/// The emulator's ROS 2 flags (`netfi emulator --ros2-topic …`).
#[derive(Debug, Clone, PartialEq, Args)]
pub struct Ros2Args {
    /// Relay the messages of ROS 2 topic IN to topic OUT (any message type,
    /// byte for byte) through the scenario; repeatable: each pair is a lane
    /// of its own (scenario: `--stream-scenario K=…`, seed derived from
    /// --seed, files in `<out>/stream-K/` when more than one).
    #[arg(long, value_name = "IN=OUT")]
    pub ros2_topic: Vec<String>,
    /// Lane K's return topic, the K-th given: messages on IN (the robot's
    /// state) go to OUT (the console's) through --return-scenario.
    #[arg(long, value_name = "IN=OUT")]
    pub ros2_return: Vec<String>,
    /// The message type on TOPIC (a topic the emulator reads), e.g.
    /// `/MTMR/measured_cp=geometry_msgs/msg/PoseStamped`; a publisher of
    /// another type is an error. Default: the publisher's.
    #[arg(long, value_name = "TOPIC=TYPE")]
    pub ros2_type: Vec<String>,
    /// The QoS on TOPIC: on a topic the emulator reads, what its reader
    /// requests; on one it writes, what its writer offers. A list of
    /// `reliable`/`best_effort`, `volatile`/`transient_local`,
    /// `depth=N`/`keep_all`. Default: the publisher's.
    #[arg(long, value_name = "TOPIC=QOS")]
    pub ros2_qos: Vec<String>,
    /// The ROS 2 domain (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, value_name = "ID")]
    pub ros2_domain: Option<u16>,
    /// The largest serialized message relayed, bytes; a larger one is the
    /// drop `too_large`. Each lane holds its queue's worth of slots of this
    /// size.
    #[arg(long, default_value_t = DEFAULT_MAX_BYTES, value_name = "BYTES")]
    pub ros2_max_bytes: usize,
    /// How long to wait at start for the publisher of each topic read, to
    /// learn its type and QoS (with `--ros2-type` given, the lane opens
    /// without one after this); at most an hour.
    #[arg(long, default_value = "10", value_parser = wait_seconds, value_name = "S")]
    pub ros2_discovery_s: f64,
    /// How long a lane's publishers may all be gone before its stream ends
    /// (a node restarted within it continues the run); at most an hour.
    #[arg(long, default_value = "1000", value_parser = wait_millis, value_name = "MS")]
    pub ros2_linger_ms: f64,
}

/// Default `--ros2-max-bytes`: 64 KiB.
pub const DEFAULT_MAX_BYTES: usize = 1 << 16;

impl Default for Ros2Args {
    /// No ROS 2 lanes; the limits at their defaults.
    fn default() -> Self {
        Ros2Args {
            ros2_topic: Vec::new(),
            ros2_return: Vec::new(),
            ros2_type: Vec::new(),
            ros2_qos: Vec::new(),
            ros2_domain: None,
            ros2_max_bytes: DEFAULT_MAX_BYTES,
            ros2_discovery_s: 10.0,
            ros2_linger_ms: 1000.0,
        }
    }
}

impl Ros2Args {
    /// Whether the emulator relays ROS 2 topics.
    pub fn on(&self) -> bool {
        !self.ros2_topic.is_empty()
    }
}

impl Render for Ros2Args {
    fn render(&self, a: &mut Argv) {
        for t in &self.ros2_topic {
            a.val("--ros2-topic", t);
        }
        for t in &self.ros2_return {
            a.val("--ros2-return", t);
        }
        for t in &self.ros2_type {
            a.val("--ros2-type", t);
        }
        for t in &self.ros2_qos {
            a.val("--ros2-qos", t);
        }
        a.opt("--ros2-domain", self.ros2_domain)
            .unless_default("--ros2-max-bytes", self.ros2_max_bytes, DEFAULT_MAX_BYTES)
            .unless_default("--ros2-discovery-s", self.ros2_discovery_s, 10.0)
            .unless_default("--ros2-linger-ms", self.ros2_linger_ms, 1000.0);
    }
}
