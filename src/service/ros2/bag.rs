//! ROS 2 topics recorded and replayed as MCAP, the format of ROS 2's
//! `ros2 bag` (rosbag2's default storage since Iron): `netfi ros2 record`
//! is a subscriber like any robot node and writes what it received;
//! `netfi ros2 replay` publishes a recording's messages at their original
//! timing, as the console of a run (the ROS analogue of `--capture`).
//!
//! Contract:
//!
//! - A message is kept as rosbag2 keeps it: its serialized CDR with the
//!   4-byte encapsulation header, on a channel of message encoding `cdr`
//!   whose schema is named by the ROS type (`geometry_msgs/msg/PoseStamped`,
//!   encoding `ros2msg`). For the known kinematic types (PoseStamped,
//!   TransformStamped, JointState) the schema holds the complete message
//!   definition ([`crate::ros2msg::Kind::definition`]), so tools that decode
//!   from it (Foxglove, rosbags) read the messages without the type
//!   installed; for any other type it is empty (netfi relays bytes and
//!   carries no other definitions): tools that read by type name take it.
//! - The file's profile is `ros2`; each channel's `offered_qos_profiles`
//!   metadata is its publishers' QoS as rosbag2 writes it
//!   ([`qos::rosbag2_profiles`]).
//! - `log_time` is when the recorder took the message; `publish_time` is its
//!   publisher's source timestamp (ns since the Unix epoch).
//! - Replay keeps the recording's spacing by `log_time` (scaled by
//!   `--rate`), publishes each topic with its recorded type, and skips, with
//!   a count, messages in an encapsulation other than little-endian CDR.

use crate::service::args::{millis, seconds};
use crate::transport::ros2::DEFAULT_MAX_BYTES;
use crate::service::emulator::ros2::plan::{domain, Ros2PlanError};
use crate::transport::ros2::{port::unix_ns, qos, NameError, OpenError, Payload, Role, Ros2Node, Slots, TakeError, TopicName, TypeName};
use clap::{Args, Subcommand};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

/// Why a recording was not made, or not replayed.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// The domain.
    #[error(transparent)]
    Domain(#[from] Ros2PlanError),
    /// The participant, a reader or a writer.
    #[error(transparent)]
    Dds(#[from] OpenError),
    #[error(transparent)]
    Take(#[from] TakeError),
    /// Writing the MCAP file.
    #[error(transparent)]
    Mcap(#[from] mcap::McapError),
    #[error("creating {}", .0.display())]
    Create(PathBuf, #[source] std::io::Error),
    #[error("writing {}", .0.display())]
    Ready(PathBuf, #[source] std::io::Error),
    /// The recording could not be written whole: it is left cut, as
    /// `NAME.partial`.
    #[error("writing {}", .0.display())]
    Write(PathBuf, #[source] std::io::Error),
    #[error("reading {}", .0.display())]
    Read(PathBuf, #[source] std::io::Error),
    #[error("reading {}", .0.display())]
    ReadMcap(PathBuf, #[source] mcap::McapError),
    #[error("topic {text}")]
    Topic {
        text: String,
        #[source]
        cause: NameError,
    },
    #[error("no publisher of {topic} within {seconds} s: its type is not known")]
    NoPublisher { topic: TopicName, seconds: f64 },
    /// A type as its publisher, or the recording, names it.
    #[error("{}the type of {topic}", .file.as_ref().map(|f| format!("{}: ", f.display())).unwrap_or_default())]
    Type {
        file: Option<PathBuf>,
        topic: TopicName,
        #[source]
        cause: NameError,
    },
    #[error("{}: topic {topic}", .file.display())]
    RecordedTopic {
        file: PathBuf,
        topic: String,
        #[source]
        cause: NameError,
    },
    #[error("{}: topic {topic} has no schema (no type)", .file.display())]
    NoSchema { file: PathBuf, topic: String },
    #[error("--rate must be above 0, got {0}")]
    Rate(f64),
    #[error("{}: no message of encoding cdr to replay", .0.display())]
    Empty(PathBuf),
}

/// `netfi ros2 …`.
#[derive(Debug, Subcommand)]
pub enum Ros2Cmd {
    /// Record ROS 2 topics into an MCAP file (a subscriber like any node;
    /// each topic's type and QoS from its publisher).
    Record(RecordArgs),
    /// Publish an MCAP recording's messages at their original timing.
    Replay(ReplayArgs),
}

/// `netfi ros2 record`.
#[derive(Debug, Clone, Args)]
pub struct RecordArgs {
    /// The MCAP file to write.
    pub out: PathBuf,
    /// The topics to record.
    #[arg(required = true)]
    pub topics: Vec<String>,
    /// The ROS 2 domain (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, value_name = "ID")]
    pub ros2_domain: Option<u16>,
    /// How long to wait for each topic's publisher.
    #[arg(long, default_value = "10", value_parser = seconds, value_name = "S")]
    pub discovery_s: f64,
    /// End once no message came for this long (after the first).
    #[arg(long, default_value = "2000", value_parser = millis, value_name = "MS")]
    pub idle_end_ms: f64,
    /// End after this many messages in all.
    #[arg(long)]
    pub count: Option<u64>,
    /// The largest serialized message kept, bytes; a larger one is skipped
    /// and counted.
    #[arg(long, default_value_t = DEFAULT_MAX_BYTES, value_name = "BYTES")]
    pub max_bytes: usize,
    /// A file written once every topic is subscribed (for scripts).
    #[arg(long)]
    pub ready: Option<PathBuf>,
}

/// `netfi ros2 replay`.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// The MCAP file (rosbag2's, or `netfi ros2 record`'s).
    pub file: PathBuf,
    /// The ROS 2 domain (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, value_name = "ID")]
    pub ros2_domain: Option<u16>,
    /// Only these topics (default: every topic of encoding `cdr`).
    #[arg(long = "topic", value_name = "TOPIC")]
    pub topics: Vec<String>,
    /// Play this many times faster than recorded.
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// Wait up to this long for a subscriber of every topic before the
    /// first message (a volatile topic's messages before it are lost).
    #[arg(long, default_value = "10", value_parser = seconds, value_name = "S")]
    pub wait_for_subscribers_s: f64,
    /// Stay this long after the last message, for reliable resends.
    #[arg(long, default_value = "1000", value_parser = millis, value_name = "MS")]
    pub linger_ms: f64,
}

/// The encapsulation header of little-endian CDR, as rosbag2 stores it.
const CDR_LE_HEADER: [u8; 4] = [0, 1, 0, 0];

/// Runs `netfi ros2 …`.
pub fn run(cmd: Ros2Cmd) -> Result<(), BagError> {
    match cmd {
        Ros2Cmd::Record(a) => record(&a).map(|n| eprintln!("ros2 record: {n} messages into {}", a.out.display())),
        Ros2Cmd::Replay(a) => replay(&a).map(|n| eprintln!("ros2 replay: {n} messages published from {}", a.file.display())),
    }
}

/// Polls `node` until `ready` says so or `wait` passes; whether it did.
fn wait_until(node: &mut Ros2Node, wait: Duration, mut ready: impl FnMut(&Ros2Node) -> bool) -> bool {
    let t0 = std::time::Instant::now();
    loop {
        node.poll(crate::clock::now_ns());
        if ready(node) {
            return true;
        }
        if t0.elapsed() >= wait {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Records `a.topics` into `a.out`; the messages written.
pub fn record(a: &RecordArgs) -> Result<u64, BagError> {
    let mut node = Ros2Node::open(domain(a.ros2_domain)?)?;
    // `NAME.partial` until the recording is whole (crate::durable).
    let file = crate::durable::PartialFile::create(&a.out).map_err(|e| BagError::Create(a.out.clone(), std::io::Error::other(e)))?;
    let partial = file.partial().to_path_buf();
    // rosbag2's profile: readers that pick a decoder by it take the
    // messages as ROS 2 CDR.
    let mut out = mcap::WriteOptions::new().profile("ros2").create(std::io::BufWriter::new(file))?;
    let mut readers = Vec::new();
    for text in &a.topics {
        let topic = TopicName::parse(text).map_err(|cause| BagError::Topic { text: text.clone(), cause })?;
        let found = wait_until(&mut node, Duration::from_secs_f64(a.discovery_s), |n| n.remotes(&topic, Role::Publisher).next().is_some());
        let Some(p) = found.then(|| node.remotes(&topic, Role::Publisher).next().cloned()).flatten() else {
            return Err(BagError::NoPublisher { topic, seconds: a.discovery_s });
        };
        let type_name = TypeName::parse(&p.dds_type).map_err(|cause| BagError::Type { file: None, topic: topic.clone(), cause })?;
        let reader = node.reader(&topic, &type_name, &qos::reader(&p.qos))?;
        let definition = crate::ros2msg::Kind::of(&type_name.ros()).map_or("", crate::ros2msg::Kind::definition);
        let schema = out.add_schema(&type_name.ros(), "ros2msg", definition.as_bytes())?;
        let offered = qos::rosbag2_profiles(node.remotes(&topic, Role::Publisher).map(|r| &r.qos));
        let channel = out.add_channel(schema, topic.as_str(), "cdr", &BTreeMap::from([("offered_qos_profiles".to_string(), offered)]))?;
        let why = if definition.is_empty() { ", schema without its definition: not a type netfi knows" } else { "" };
        eprintln!("ros2 record: {topic} ({type_name}{why})");
        readers.push((reader, channel));
    }
    if let Some(r) = &a.ready {
        crate::durable::write_whole(r, b"").map_err(|e| BagError::Ready(r.clone(), std::io::Error::other(e)))?;
    }
    let slots = RefCell::new(Slots::new(1, a.max_bytes));
    let slot = slots.borrow_mut().alloc().expect("one slot");
    let (mut written, mut skipped, mut last_ns) = (0u64, 0u64, None::<u64>);
    let idle_ns = (a.idle_end_ms * 1e6) as u64;
    let mut data = Vec::with_capacity(a.max_bytes + 4);
    'run: loop {
        let mut any = false;
        for (reader, channel) in &mut readers {
            while let Some(t) = reader.take(&slots, slot)? {
                any = true;
                let Payload::Stored { .. } = t.payload else {
                    skipped += 1;
                    continue;
                };
                let log_time = unix_ns(rustdds::Timestamp::now());
                data.clear();
                data.extend_from_slice(&CDR_LE_HEADER);
                data.extend_from_slice(slots.borrow().get(slot));
                let header = mcap::records::MessageHeader { channel_id: *channel, sequence: written as u32, log_time, publish_time: t.source.map_or(log_time, unix_ns) };
                out.write_to_known_channel(&header, &data)?;
                written += 1;
                if a.count.is_some_and(|c| written >= c) {
                    break 'run;
                }
            }
        }
        let now = crate::clock::now_ns();
        if any {
            last_ns = Some(now);
        } else if last_ns.is_some_and(|l| now - l >= idle_ns) {
            break;
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    out.finish()?;
    let file = out.into_inner().into_inner().map_err(|e| BagError::Write(partial.clone(), e.into_error()))?;
    file.commit().map_err(|e| BagError::Write(partial, std::io::Error::other(e)))?;
    if skipped > 0 {
        eprintln!("ros2 record: {skipped} messages skipped (larger than --max-bytes, empty, or not little-endian CDR)");
    }
    Ok(written)
}

/// One message of a recording.
struct Recorded {
    log_time: u64,
    writer: usize,
    data: Vec<u8>,
}

/// Publishes `a.file`'s messages at their recorded spacing; those
/// published.
pub fn replay(a: &ReplayArgs) -> Result<u64, BagError> {
    if !(a.rate.is_finite() && a.rate > 0.0) {
        return Err(BagError::Rate(a.rate));
    }
    let bytes = crate::load::read_file(&a.file).map_err(|e| BagError::Read(a.file.clone(), e))?;
    let mut node = Ros2Node::open(domain(a.ros2_domain)?)?;
    let (mut writers, mut by_channel, mut messages) = (Vec::new(), BTreeMap::new(), Vec::new());
    let mut skipped = 0u64;
    let unread = |e| BagError::ReadMcap(a.file.clone(), e);
    for m in mcap::MessageStream::new(&bytes).map_err(unread)? {
        let m = m.map_err(unread)?;
        let c = &m.channel;
        if c.message_encoding != "cdr" || !(a.topics.is_empty() || a.topics.contains(&c.topic)) {
            continue;
        }
        let k = match by_channel.get(&c.id) {
            Some(k) => *k,
            None => {
                let topic = TopicName::parse(&c.topic).map_err(|cause| BagError::RecordedTopic { file: a.file.clone(), topic: c.topic.clone(), cause })?;
                let schema = c.schema.as_ref().ok_or_else(|| BagError::NoSchema { file: a.file.clone(), topic: c.topic.clone() })?;
                let type_name = TypeName::parse(&schema.name).map_err(|cause| BagError::Type { file: Some(a.file.clone()), topic: topic.clone(), cause })?;
                eprintln!("ros2 replay: {topic} ({type_name})");
                writers.push((node.writer(&topic, &type_name, &qos::relay(None))?, topic));
                by_channel.insert(c.id, writers.len() - 1);
                writers.len() - 1
            }
        };
        if m.data.len() < 4 || m.data[..2] != CDR_LE_HEADER[..2] {
            skipped += 1;
            continue;
        }
        messages.push(Recorded { log_time: m.log_time, writer: k, data: m.data[4..].to_vec() });
    }
    if messages.is_empty() {
        return Err(BagError::Empty(a.file.clone()));
    }
    messages.sort_by_key(|m| m.log_time);
    let all = wait_until(&mut node, Duration::from_secs_f64(a.wait_for_subscribers_s), |n| writers.iter().all(|(_, t)| n.remotes(t, Role::Subscriber).next().is_some()));
    if !all {
        eprintln!("ros2 replay: WARNING: not every topic has a subscriber after {} s; publishing anyway", a.wait_for_subscribers_s);
    }
    let (t0, first) = (crate::clock::now_ns(), messages[0].log_time);
    let mut published = 0u64;
    for m in &messages {
        let due = t0 + ((m.log_time - first) as f64 / a.rate) as u64;
        crate::clock::sleep_until_ns(due);
        match writers[m.writer].0.write(&m.data, None) {
            Ok(()) => published += 1,
            Err(e) => eprintln!("ros2 replay: {e}"),
        }
    }
    std::thread::sleep(Duration::from_secs_f64(a.linger_ms / 1e3));
    if skipped > 0 {
        eprintln!("ros2 replay: {skipped} messages skipped (not little-endian CDR)");
    }
    Ok(published)
}
