//! `ros2.json`, and what the ROS 2 channels add to their paths' reports:
//! each direction's topics, type and QoS, the nodes that came and left, why
//! the stream ended, and the motion of known kinematic types.

use crate::ros2msg::MotionReport;
use crate::service::schema::BadInput;
use crate::transport::ros2::qos::Summary;
use crate::transport::ros2::Role;
use serde::{Deserialize, Serialize};

/// What the return channel adds to its path's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ReturnExtra {
    /// Messages the robot's publishers said they sent (their sequence
    /// numbers), as far as they were tracked.
    pub sent_by_robot: Option<u64>,
    /// Messages missing from those sequences before the emulator: lost on
    /// the DDS hop or by the reader's history.
    pub lost_before_ingress: u64,
    pub bad_input: BadInput,
}

/// Why the forward stream ended, once it has.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StreamEnd {
    /// `publishers_gone` or `idle`.
    pub reason: String,
    /// Seconds into the loop.
    pub t_s: f64,
    /// What the log said.
    pub detail: String,
}

/// What a topic relayed, and how, for `ros2.json`.
#[derive(Debug, Clone, Serialize)]
pub struct TopicReport {
    pub from: String,
    pub to: String,
    #[serde(rename = "type")]
    pub type_name: String,
    /// The publishers' type hash as they announced it, if they did.
    pub type_hash: Option<String>,
    /// `command_line` or `publisher`.
    pub type_from: &'static str,
    /// `command_line`, `publisher` or `default` (ROS 2's: reliable,
    /// volatile, depth 10).
    pub qos_from: &'static str,
    pub reader_qos: Summary,
    pub writer_qos: Summary,
    pub max_bytes: usize,
    pub slots: usize,
    pub slots_high_water: usize,
    /// Messages missing from the publishers' sequences before the emulator
    /// (the forward stream's; the return path's are in its report).
    pub lost_before_ingress: u64,
    /// Messages the publishers sent before the emulator heard from them.
    pub sent_before_emulator: u64,
    /// Messages of publishers beyond those followed.
    pub writers_untracked: u64,
    /// Releases refused because a reliable subscriber's window was full.
    pub window_full: u64,
    /// The encapsulation of the last message refused for it.
    pub bad_encoding: Option<&'static str>,
    /// Why the stream ended, if it ended by itself.
    pub ended: Option<StreamEnd>,
    /// The console's and the robot's motion, where the type is a known
    /// kinematic one (the forward stream's).
    pub motion: Option<MotionReport>,
    /// Every publisher of `from` and subscriber of `to` seen, with when it
    /// came and left.
    pub endpoints: Vec<EndpointSeen>,
    /// What happened on the two topics, in order.
    pub events: Vec<EventRow>,
}

/// A remote publisher or subscriber, as seen over the run.
#[derive(Debug, Clone, Serialize)]
pub struct EndpointSeen {
    pub role: Role,
    pub topic: String,
    /// Its ROS 2 node, else its DDS GUID.
    pub node: String,
    #[serde(rename = "type")]
    pub type_name: String,
    pub type_hash: Option<String>,
    /// Seconds since the emulator joined the domain (`None`: already there).
    pub joined_s: Option<f64>,
    pub left_s: Option<f64>,
    /// `disposed` (its node said so) or `lease_expired` (it stopped
    /// announcing itself: killed, or cut off).
    pub left: Option<&'static str>,
}

/// One event of a lane's topics.
#[derive(Debug, Clone, Serialize)]
pub struct EventRow {
    pub t_s: f64,
    pub role: Role,
    pub topic: String,
    pub node: String,
    /// `joined`, `left`, `type_mismatch` or `qos_incompatible`.
    pub what: &'static str,
    pub detail: String,
}

/// `ros2.json`: a lane's topics.
#[derive(Debug, Clone, Serialize)]
pub struct Ros2Report {
    pub domain_id: u16,
    /// The forward account closes and, where the stream ended by itself,
    /// the publishers' own count is what entered, what was lost before the
    /// emulator and what they sent before it listened.
    pub balanced: bool,
    pub forward: TopicReport,
    pub return_path: Option<TopicReport>,
    /// Graph events past those kept.
    pub events_dropped: u64,
}
