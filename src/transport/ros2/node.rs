//! The emulator on a ROS 2 domain: one DDS participant for all its lanes,
//! the readers and writers it opens for them, and what it knows of the
//! others there (the graph): every remote publisher and subscriber of a
//! ROS 2 topic with its type, type hash and QoS, the ROS 2 node each
//! belongs to (from `ros_discovery_info`), and what happened to them (came,
//! left and why, could not match and why), in order.
//!
//! Everything here is off the emulator's hot path: opening before the loop
//! starts, [`Ros2Node::poll`] every few thousand turns.

use super::names::{type_hash, TopicName, TypeName};
use super::port::{RawCdr, RawOut, Reader, Writer};
use super::qos::{self, QosMismatch};
use rustdds::{RTPSEntity, DomainParticipant, DomainParticipantStatusEvent, DomainParticipantStatusListener, LostReason, Publisher, QosPolicies, StatusEvented, Subscriber, TopicKind, GUID};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};

/// Why the emulator could not take its place on a ROS 2 domain.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The DDS participant could not be created.
    #[error("joining ROS 2 domain {domain}: {reason}")]
    Participant {
        /// The domain id.
        domain: u16,
        /// What the DDS implementation said.
        reason: String,
    },
    /// A reader or writer of a topic could not be created.
    #[error("opening the {what} of {topic}: {reason}")]
    Endpoint {
        /// `topic`, `reader` or `writer`.
        what: &'static str,
        /// The ROS 2 topic.
        topic: String,
        /// What the DDS implementation said.
        reason: String,
    },
}

/// How long a message that names a node waits for its name: a node's
/// name comes in its participant's `ros_discovery_info`, which Fast DDS
/// sends a reader that joined later on its writer's next heartbeat (every
/// 3 s).
pub const NAME_WAIT_NS: u64 = 4_000_000_000;

/// Most graph events kept; later ones are counted, not kept.
pub const EVENTS_MAX: usize = 10_000;

/// A remote ROS 2 endpoint as discovered.
#[derive(Debug, Clone)]
pub struct Remote {
    /// Its DDS GUID.
    pub guid: GUID,
    /// Whether it publishes (a DDS writer) or subscribes.
    pub role: Role,
    /// Its ROS 2 topic.
    pub topic: TopicName,
    /// Its DDS type name as announced.
    pub dds_type: String,
    /// Its type hash as announced (ROS 2 Iron and later), if any.
    pub type_hash: Option<String>,
    /// The QoS it announced (offered by a publisher, requested by a
    /// subscriber).
    pub qos: QosPolicies,
}

/// Publisher or subscriber.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// A DDS writer.
    Publisher,
    /// A DDS reader.
    Subscriber,
}

impl Role {
    /// `publisher` or `subscriber`.
    pub fn name(self) -> &'static str {
        match self {
            Role::Publisher => "publisher",
            Role::Subscriber => "subscriber",
        }
    }
}

/// What happened to a remote endpoint.
#[derive(Debug, Clone, PartialEq)]
pub enum Happened {
    /// It was discovered.
    Joined,
    /// It left: `disposed` (its node said so) or `lease_expired` (its node
    /// stopped announcing itself: killed, or cut off).
    Left {
        /// `disposed` or `lease_expired`.
        reason: &'static str,
    },
    /// It and one of the emulator's own endpoints cannot match.
    QosIncompatible(QosMismatch),
}

/// One event of the graph, at `t_ns` (the emulator's monotonic clock).
#[derive(Debug, Clone)]
pub struct GraphEvent {
    /// When the emulator learned of it.
    pub t_ns: u64,
    /// The remote endpoint's GUID.
    pub guid: GUID,
    /// Publisher or subscriber.
    pub role: Role,
    /// Its topic.
    pub topic: TopicName,
    /// Its DDS type name.
    pub dds_type: String,
    /// What happened.
    pub happened: Happened,
}

/// `ros_discovery_info`'s types (`rmw_dds_common/msg`, 16-byte gids from
/// ROS 2 Iron on): which node each participant's endpoints belong to.
#[derive(Debug, Deserialize)]
struct Gid {
    data: [u8; 16],
}

#[derive(Debug, Deserialize)]
struct NodeEntitiesInfo {
    node_namespace: String,
    node_name: String,
    reader_gid_seq: Vec<Gid>,
    writer_gid_seq: Vec<Gid>,
}

#[derive(Debug, Deserialize)]
struct ParticipantEntitiesInfo {
    gid: Gid,
    node_entities_info_seq: Vec<NodeEntitiesInfo>,
}

type EntitiesReader = rustdds::no_key::SimpleDataReader<ParticipantEntitiesInfo, rustdds::CDRDeserializerAdapter<ParticipantEntitiesInfo>>;

/// The emulator's participant in a ROS 2 domain, and its graph.
pub struct Ros2Node {
    dp: DomainParticipant,
    subscriber: Subscriber,
    publisher: Publisher,
    status: DomainParticipantStatusListener,
    entities: Option<EntitiesReader>,
    /// The node of each endpoint (by gid), and the nodes of each
    /// participant (by GUID prefix), as `ros_discovery_info` said.
    endpoint_nodes: HashMap<[u8; 16], String>,
    participant_nodes: HashMap<[u8; 12], Vec<String>>,
    remotes: BTreeMap<GUID, Remote>,
    /// What happened, in order (at most [`EVENTS_MAX`]).
    pub events: Vec<GraphEvent>,
    /// Events past [`EVENTS_MAX`], not kept.
    pub events_dropped: u64,
    /// When the last participant or endpoint new to the emulator was
    /// discovered (0: none yet).
    pub last_discovery_ns: u64,
}

fn prefix(g: GUID) -> [u8; 12] {
    let b = g.to_bytes();
    let mut p = [0u8; 12];
    p.copy_from_slice(&b[..12]);
    p
}

impl Ros2Node {
    /// Joins ROS 2 domain `domain` (its DDS participant starts its threads
    /// now: the caller decides where they may run).
    pub fn open(domain: u16) -> Result<Ros2Node, OpenError> {
        let err = |e: &dyn std::fmt::Display| OpenError::Participant { domain, reason: e.to_string() };
        let dp = DomainParticipant::new(domain).map_err(|e| err(&e))?;
        let none = QosPolicies::qos_none();
        let subscriber = dp.create_subscriber(&none).map_err(|e| err(&e))?;
        let publisher = dp.create_publisher(&none).map_err(|e| err(&e))?;
        let status = dp.status_listener();
        // The nodes' names are a courtesy of the report: without them,
        // endpoints are named by GUID.
        let entities = (|| {
            let q = rustdds::QosPolicyBuilder::new()
                .reliable(rustdds::Duration::ZERO)
                .durability(rustdds::policy::Durability::TransientLocal)
                .history(rustdds::policy::History::KeepLast { depth: 64 })
                .build();
            let t = dp.create_topic("ros_discovery_info".into(), "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_".into(), &q, TopicKind::NoKey).ok()?;
            subscriber.create_simple_datareader_no_key::<ParticipantEntitiesInfo, rustdds::CDRDeserializerAdapter<_>>(&t, Some(q)).ok()
        })();
        Ok(Ros2Node {
            dp,
            subscriber,
            publisher,
            status,
            entities,
            endpoint_nodes: HashMap::new(),
            participant_nodes: HashMap::new(),
            remotes: BTreeMap::new(),
            events: Vec::new(),
            events_dropped: 0,
            last_discovery_ns: 0,
        })
    }

    /// The domain id.
    pub fn domain_id(&self) -> u16 {
        self.dp.domain_id()
    }

    fn topic(&self, topic: &TopicName, type_name: &TypeName, q: &QosPolicies) -> Result<rustdds::Topic, OpenError> {
        self.dp
            .create_topic(topic.dds(), type_name.dds(), q, TopicKind::NoKey)
            .map_err(|e| OpenError::Endpoint { what: "topic", topic: topic.to_string(), reason: e.to_string() })
    }

    /// A reader of `topic`'s messages of `type_name`, asking for `q`.
    pub fn reader(&self, topic: &TopicName, type_name: &TypeName, q: &QosPolicies) -> Result<Reader, OpenError> {
        let t = self.topic(topic, type_name, q)?;
        let inner = self
            .subscriber
            .create_simple_datareader_no_key::<super::port::Payload, RawCdr>(&t, Some(q.clone()))
            .map_err(|e| OpenError::Endpoint { what: "reader", topic: topic.to_string(), reason: e.to_string() })?;
        Ok(Reader::new(inner, topic.to_string()))
    }

    /// A writer of `topic`'s messages of `type_name`, offering `q` (a
    /// reliable one never blocks: [`qos::writer`]).
    pub fn writer(&self, topic: &TopicName, type_name: &TypeName, q: &QosPolicies) -> Result<Writer, OpenError> {
        let q = qos::writer(q);
        let t = self.topic(topic, type_name, &q)?;
        let inner = self
            .publisher
            .create_datawriter_no_key::<rustdds::bytes::Bytes, RawOut>(&t, Some(q))
            .map_err(|e| OpenError::Endpoint { what: "writer", topic: topic.to_string(), reason: e.to_string() })?;
        Ok(Writer::new(inner, topic.to_string()))
    }

    /// The remote endpoints of `topic` in `role` known now.
    pub fn remotes(&self, topic: &TopicName, role: Role) -> impl Iterator<Item = &Remote> {
        let topic = topic.clone();
        self.remotes.values().filter(move |r| r.role == role && r.topic == topic)
    }

    /// The ROS 2 node of endpoint `guid` (`/namespace/name`), else of its
    /// participant (its nodes, comma-separated), if known.
    pub fn node_of(&self, guid: GUID) -> Option<String> {
        self.endpoint_nodes.get(&guid.to_bytes()).cloned().or_else(|| self.participant_nodes.get(&prefix(guid)).map(|n| n.join(",")))
    }

    /// `guid`'s node, else the GUID itself, for messages and reports.
    pub fn name(&self, guid: GUID) -> String {
        self.node_of(guid).unwrap_or_else(|| guid_hex(guid))
    }

    fn push(&mut self, e: GraphEvent) {
        if self.events.len() < EVENTS_MAX {
            self.events.push(e);
        } else {
            self.events_dropped += 1;
        }
    }

    /// Takes in what discovery learned since the last poll, at `now_ns`.
    pub fn poll(&mut self, now_ns: u64) {
        while let Some(e) = self.status.try_recv_status() {
            self.take_event(e, now_ns);
        }
        let mut infos = Vec::new();
        if let Some(r) = &self.entities {
            r.drain_read_notifications();
            while let Ok(Some(c)) = r.try_take_one() {
                infos.push(c.sample);
            }
        }
        for p in infos {
            let nodes: Vec<String> = p.node_entities_info_seq.iter().map(|n| full_name(&n.node_namespace, &n.node_name)).collect();
            for n in &p.node_entities_info_seq {
                let name = full_name(&n.node_namespace, &n.node_name);
                for g in n.reader_gid_seq.iter().chain(&n.writer_gid_seq) {
                    self.endpoint_nodes.insert(g.data, name.clone());
                }
            }
            let mut pre = [0u8; 12];
            pre.copy_from_slice(&p.gid.data[..12]);
            self.participant_nodes.insert(pre, nodes);
        }
    }

    fn take_event(&mut self, e: DomainParticipantStatusEvent, t_ns: u64) {
        use DomainParticipantStatusEvent as E;
        let (guid, role, d) = match e {
            E::WriterDetected { writer } => (writer.guid, Role::Publisher, Some(writer)),
            E::ReaderDetected { reader } => (reader.guid, Role::Subscriber, Some(reader)),
            E::WriterLost { guid, reason } | E::ReaderLost { guid, reason } => {
                self.left(guid, reason, t_ns);
                return;
            }
            E::ParticipantDiscovered { .. } => {
                self.last_discovery_ns = t_ns;
                return;
            }
            E::ParticipantLost { id, reason } => {
                let gone: Vec<GUID> = self.remotes.keys().filter(|g| g.prefix == id).copied().collect();
                gone.into_iter().for_each(|g| self.left(g, reason.clone(), t_ns));
                return;
            }
            E::RemoteWriterQosIncompatible { remote_writer, requested_qos, offered_qos, .. } => {
                self.incompatible(remote_writer, &offered_qos, &requested_qos, t_ns);
                return;
            }
            E::RemoteReaderQosIncompatible { remote_reader, requested_qos, offered_qos, .. } => {
                self.incompatible(remote_reader, &offered_qos, &requested_qos, t_ns);
                return;
            }
            _ => return,
        };
        let Some(d) = d else { return };
        // Our own endpoints, and DDS topics that are not ROS 2 topics.
        if guid.prefix == self.dp.guid().prefix || self.remotes.contains_key(&guid) {
            return;
        }
        let Some(topic) = TopicName::from_dds(&d.topic_name) else { return };
        let r = Remote { guid, role, topic: topic.clone(), dds_type: d.type_name.clone(), type_hash: type_hash(&d.user_data), qos: d.qos.clone() };
        self.remotes.insert(guid, r);
        self.last_discovery_ns = t_ns;
        self.push(GraphEvent { t_ns, guid, role, topic, dds_type: d.type_name, happened: Happened::Joined });
    }

    fn left(&mut self, guid: GUID, reason: LostReason, t_ns: u64) {
        let Some(r) = self.remotes.remove(&guid) else { return };
        let reason = match reason {
            LostReason::Disposed => "disposed",
            LostReason::Timeout { .. } => "lease_expired",
        };
        self.push(GraphEvent { t_ns, guid, role: r.role, topic: r.topic, dds_type: r.dds_type, happened: Happened::Left { reason } });
    }

    fn incompatible(&mut self, remote: GUID, offered: &QosPolicies, requested: &QosPolicies, t_ns: u64) {
        let Some(r) = self.remotes.get(&remote).cloned() else { return };
        let name = self.name(remote);
        let (writer, reader) = match r.role {
            Role::Publisher => (format!("the publisher {name}"), "the emulator's reader".to_string()),
            Role::Subscriber => ("the emulator's writer".to_string(), format!("the subscriber {name}")),
        };
        let Err(m) = qos::check(offered, requested, &writer, &reader) else { return };
        self.push(GraphEvent { t_ns, guid: remote, role: r.role, topic: r.topic, dds_type: r.dds_type, happened: Happened::QosIncompatible(m) });
    }
}

/// A GUID as 32 hex digits (prefix, then entity id), as ROS 2's tools
/// print a gid.
pub fn guid_hex(g: GUID) -> String {
    g.to_bytes().iter().map(|b| format!("{b:02x}")).collect()
}

/// `/namespace/name` of a node.
fn full_name(namespace: &str, name: &str) -> String {
    if namespace.ends_with('/') {
        format!("{namespace}{name}")
    } else {
        format!("{namespace}/{name}")
    }
}
