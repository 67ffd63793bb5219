//! The ROS 2 channels: messages of one topic taken in and written out on
//! another, each a frame of its path's link. The forward channel carries the
//! console's topic to the robot's (a lane's forward path); the return
//! channel the robot's state back to the console (a reverse path through
//! `--return-scenario`). Both are [`Topic`], differing in their
//! [`Direction`].
//!
//! **A message is a slot.** The reader's decoder copies each message's
//! serialized bytes into a slot of the channel's own (fixed at start-up:
//! one more slot than the link's queue holds, so a slot is always free);
//! the link queues only the slot's number and the message's size (which the
//! `rate` and `trace` stages see), and the writer sends the slot's bytes at
//! release. A message larger than `--ros2-max-bytes` is the drop
//! `too_large`, an empty one `wrong_size`, one in an encapsulation the
//! emulator does not relay `bad_flags`; a message of a known kinematic type
//! (PoseStamped, TransformStamped, JointState: [`crate::ros2msg`]) that
//! does not read as its type, `wrong_size`. Each is bad input, counted with
//! its sender. Messages of a known kinematic type are read on both sides
//! (taken in, released): the console's and the robot's motion, the robot's
//! stalls and the divergence, in `ros2.json`. The slot holds one message, so a `duplicate` stage (a second
//! release of the same slot) and a `corrupt` stage (bits of an ITP frame,
//! which a CDR message is not) are refused by name.
//!
//! **The end.** ROS 2 has no end of stream: the forward stream ends once
//! its publishers have all been gone for `--ros2-linger-ms` (a node that
//! restarts within it continues the run), or, with `--idle-end-ms`, once no
//! message has come for that long. The publishers' own count (their DDS
//! sequence numbers) stands for the console's end marker; gaps in those
//! numbers are messages lost before the emulator saw them (the DDS hop, or
//! the reader's history overrun by a flood), counted as
//! `lost_before_ingress`.
//!
//! Off the hot path (every 4096 turns), the forward channel polls the
//! domain's graph: who publishes and subscribes, who left, who cannot
//! match; each change a logged event.

use crate::clock::now_ns;
use crate::injector::{DropCause, Invalid};
use crate::ros2msg::{Kind, Motion};
use crate::service::emulator::path::{Channel, Ending, ForwardChannel, Take, GRACE_NS};
use crate::service::link::{Arrival, Carried};
use crate::service::schema::ros2::{ReturnExtra, StreamEnd};
use crate::service::schema::{Account, BadInput, ForwardExtra};
use crate::transport::ros2::senders::Senders;
use crate::transport::ros2::node::NAME_WAIT_NS;
use crate::transport::ros2::{Happened, Payload, Reader, Role, Ros2Node, Slots, TopicName, TypeName, Writer};
use crate::transport::PortError;
use serde::Serialize;
use std::cell::RefCell;
use std::marker::PhantomData;
use std::rc::Rc;

/// What a ROS 2 path's link holds: the slot of the message, its size, and
/// the times it carries.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ros2Item {
    pub slot: u32,
    pub len: u32,
    pub ingress_ns: u64,
    /// The publisher's source timestamp (DDS ticks; 0: none), written on the
    /// relayed message so that its subscriber's message info says when the
    /// message was first sent.
    pub source_ticks: u64,
}

impl Carried for Ros2Item {
    #[inline]
    fn ingress_ns(&self) -> u64 {
        self.ingress_ns
    }
}

/// What differs between the two ROS 2 channels.
pub trait Direction: 'static {
    /// The channel's name (its report's key, its seed's derivation).
    const NAME: &'static str;
    const TRACE_FILE: &'static str;
    const ENDING: Ending;
    /// What it adds to its path's report.
    type Extra: Serialize + serde::de::DeserializeOwned;
    /// That, from the channel's counts and the publishers' own count.
    fn extra(c: &Counts, sent: Option<u64>) -> Self::Extra;
}

/// The console's topic to the robot's: a lane's forward path.
/// The most writers of bad input a report names.
const BAD_SENDERS_MAX: usize = 16;

pub struct Forward;

/// The robot's state topic back to the console's: a reverse path.
pub struct Return;

impl Direction for Forward {
    const NAME: &'static str = "forward";
    const TRACE_FILE: &'static str = "trace_emulator.csv";
    const ENDING: Ending = Ending::OnMarker;
    type Extra = ForwardExtra;

    fn extra(c: &Counts, sent: Option<u64>) -> ForwardExtra {
        ForwardExtra { sent_by_console: sent, bad_checksum_passed: 0, bad_input: c.bad_input.clone(), kinematics: None }
    }
}

impl Direction for Return {
    const NAME: &'static str = "ros2_return";
    const TRACE_FILE: &'static str = "trace_ros2_return.csv";
    const ENDING: Ending = Ending::AfterForward { grace_ns: GRACE_NS };
    type Extra = ReturnExtra;

    fn extra(c: &Counts, sent: Option<u64>) -> ReturnExtra {
        ReturnExtra { sent_by_robot: sent, lost_before_ingress: c.lost_before_ingress, bad_input: c.bad_input.clone() }
    }
}

/// What a channel counts of what it took.
#[derive(Debug, Clone, Default)]
pub struct Counts {
    pub bad_input: BadInput,
    /// Messages missing from the publishers' sequences.
    pub lost_before_ingress: u64,
    /// Messages of publishers beyond [`WRITERS_TRACKED`](crate::transport::ros2::senders::WRITERS_TRACKED).
    pub writers_untracked: u64,
    /// The encapsulation of the last message refused for it.
    pub last_bad_encoding: Option<&'static str>,
    /// Writes that failed because a reliable subscriber's window was full.
    pub window_full: u64,
}

/// A ROS 2 channel: a reader of one topic, a writer of another, the slots
/// between them.
pub struct Topic<D: Direction> {
    reader: Reader,
    writer: Writer,
    slots: RefCell<Slots>,
    /// A free slot, kept for the next message.
    next: Option<u32>,
    node: Rc<RefCell<Ros2Node>>,
    pub from: TopicName,
    pub to: TopicName,
    pub type_name: TypeName,
    senders: Senders,
    /// What it counted.
    pub counts: Counts,
    /// The writer of the last bad input.
    bad_from: Option<rustdds::GUID>,
    /// The writers that sent bad input (at most [`BAD_SENDERS_MAX`]).
    bad_senders: Vec<rustdds::GUID>,
    /// Publishers of `from` and subscribers of `to` of the lane's type, as
    /// last seen.
    publishers: usize,
    subscribers: usize,
    /// Items released while no subscriber was matched.
    unsubscribed: u64,
    /// CLOCK_REALTIME − CLOCK_MONOTONIC, ns, at start: maps the publishers'
    /// source timestamps onto the emulator's clock.
    realtime_offset_ns: i128,
    /// When the stream's publishers were all gone (having been there).
    gone_since_ns: Option<u64>,
    seen_publisher: bool,
    linger_ns: u64,
    idle_end_ns: Option<u64>,
    t_start_ns: u64,
    last_take_ns: u64,
    /// The graph's events looked at so far.
    events_seen: usize,
    /// Set off the hot path when the stream has ended; the next empty take
    /// says so.
    pub end: Option<StreamEnd>,
    /// The console's and the robot's motion, where the type is a known
    /// kinematic one.
    pub motion: Option<Motion>,
    _d: PhantomData<D>,
}

/// What a channel is opened with.
pub struct TopicPorts {
    pub reader: Reader,
    pub writer: Writer,
    pub from: TopicName,
    pub to: TopicName,
    pub type_name: TypeName,
    /// Slots for this many messages at once (the link's queue, plus one).
    pub slots: usize,
    pub max_bytes: usize,
    /// How long the publishers may be gone before the stream ends, ns.
    pub linger_ns: u64,
    /// End once no message came for this long, ns.
    pub idle_end_ns: Option<u64>,
}

/// CLOCK_REALTIME − CLOCK_MONOTONIC now, ns.
fn realtime_offset_ns() -> i128 {
    let mono = now_ns();
    let real = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    real as i128 - i128::from(mono)
}

impl<D: Direction> Topic<D> {
    /// Keeps the writer of the last bad input among the bad senders (off
    /// the hot path; named when the report is written).
    fn note_bad_sender(&mut self) {
        if let Some(g) = self.bad_from {
            if !self.bad_senders.contains(&g) && self.bad_senders.len() < BAD_SENDERS_MAX {
                self.bad_senders.push(g);
            }
        }
    }

    /// The channel of `p` on `node`; its log's times count from `t0_ns`
    /// (when the emulator joined the domain).
    pub fn new(p: TopicPorts, node: Rc<RefCell<Ros2Node>>, t0_ns: u64) -> Topic<D> {
        let t = t0_ns;
        let events_seen = node.borrow().events.len();
        let motion = Kind::of(&p.type_name.ros()).map(|k| Motion::new(k, crate::kinematics::STALL_THRESHOLD_NS_DEFAULT));
        Topic {
            reader: p.reader,
            writer: p.writer,
            slots: RefCell::new(Slots::new(p.slots, p.max_bytes)),
            next: None,
            node,
            from: p.from,
            to: p.to,
            type_name: p.type_name,
            senders: Senders::new(),
            counts: Counts::default(),
            bad_from: None,
            bad_senders: Vec::new(),
            publishers: 0,
            subscribers: 0,
            unsubscribed: 0,
            realtime_offset_ns: realtime_offset_ns(),
            gone_since_ns: None,
            seen_publisher: false,
            linger_ns: p.linger_ns,
            idle_end_ns: p.idle_end_ns,
            t_start_ns: t,
            last_take_ns: 0,
            events_seen,
            end: None,
            motion,
            _d: PhantomData,
        }
    }

    /// The slots' size and their high-water mark.
    pub fn slots(&self) -> (usize, usize, usize) {
        let s = self.slots.borrow();
        (s.slots(), s.slot_bytes(), s.high_water())
    }

    /// What the publishers said they sent before the emulator heard from
    /// them.
    pub fn sent_before_first(&self) -> u64 {
        self.senders.before_first()
    }

    /// The publishers' own count, where every publisher was tracked.
    fn sent(&self) -> Option<u64> {
        (self.counts.writers_untracked == 0 && !self.senders.is_empty()).then(|| self.senders.sent())
    }

    /// The emulator's time of a source timestamp, if it has one and it is
    /// not in the future.
    #[inline]
    fn send_ns(&self, ticks: Option<rustdds::Timestamp>, now: u64) -> u64 {
        match ticks {
            Some(t) => {
                let mono = crate::transport::ros2::unix_ns(t) as i128 - self.realtime_offset_ns;
                mono.clamp(0, i128::from(now)) as u64
            }
            None => now,
        }
    }

    /// A message of a known kinematic type, taken in at `t` into `slot`:
    /// whether it reads as its type (the console's motion follows it);
    /// `true` for any other type.
    #[inline]
    fn read_console(&mut self, slot: u32, t: u64) -> bool {
        let Some(m) = self.motion.as_mut() else { return true };
        match m.read(self.slots.get_mut().get(slot)) {
            Some(s) => {
                m.console(t, &s);
                true
            }
            None => false,
        }
    }

    /// Off the hot path, at `now`: the graph's news, the lane's publishers
    /// and subscribers, and whether the stream has ended.
    pub fn look(&mut self, now: u64) {
        self.reader.drain_notifications();
        let mut node = self.node.borrow_mut();
        node.poll(now);
        let ours = self.type_name.dds();
        self.publishers = node.remotes(&self.from, Role::Publisher).filter(|r| r.dds_type == ours).count();
        self.subscribers = node.remotes(&self.to, Role::Subscriber).filter(|r| r.dds_type == ours).count();
        drop(node);
        self.say_events(now, false);
        self.look_for_end(now);
    }

    /// Says each change on the lane's topics once, in order, naming the
    /// node: an endpoint's node is named by its participant's
    /// `ros_discovery_info`, which may come after the endpoint itself, so an
    /// endpoint's coming (and what follows it) waits for it up to
    /// [`NAME_WAIT_NS`];
    /// `all` says what is left, by GUID where no name came.
    fn say_events(&mut self, now: u64, all: bool) {
        let node = self.node.borrow();
        let ours = self.type_name.dds();
        let mut said = self.events_seen;
        for e in &node.events[self.events_seen..] {
            let mine = (e.role == Role::Publisher && e.topic == self.from) || (e.role == Role::Subscriber && e.topic == self.to);
            if !mine {
                said += 1;
                continue;
            }
            // A node that leaves nameless was nameless when it came: its
            // leaving waits for nothing.
            let waits = !matches!(e.happened, Happened::Left { .. });
            if !all && waits && node.node_of(e.guid).is_none() && now.saturating_sub(e.t_ns) < NAME_WAIT_NS {
                break;
            }
            said += 1;
            let who = format!("{} {} of {}", e.role.name(), node.name(e.guid), e.topic);
            let t_s = (e.t_ns.saturating_sub(self.t_start_ns)) as f64 / 1e9;
            match &e.happened {
                Happened::Joined if e.dds_type != ours => eprintln!(
                    "emulator: {}: ERROR at {t_s:.3} s: the {who} has type {}, the lane relays {}: they cannot match (DDS matches by type name)",
                    D::NAME,
                    e.dds_type,
                    self.type_name
                ),
                Happened::Joined => eprintln!("emulator: {}: at {t_s:.3} s the {who} came", D::NAME),
                Happened::Left { reason } => eprintln!("emulator: {}: at {t_s:.3} s the {who} left ({reason})", D::NAME),
                Happened::QosIncompatible(m) => eprintln!("emulator: {}: ERROR at {t_s:.3} s: the {who} cannot match: {m}", D::NAME),
            }
        }
        self.events_seen = said;
    }

    fn look_for_end(&mut self, now: u64) {
        if self.end.is_some() {
            return;
        }
        let t_s = now.saturating_sub(self.t_start_ns) as f64 / 1e9;
        if self.publishers > 0 {
            self.seen_publisher = true;
            self.gone_since_ns = None;
        } else if self.seen_publisher {
            let since = *self.gone_since_ns.get_or_insert(now);
            if now - since >= self.linger_ns {
                let node = self.node.borrow();
                let last = node.events.iter().rev().find(|e| e.role == Role::Publisher && e.topic == self.from && matches!(e.happened, Happened::Left { .. }));
                let detail = match last {
                    Some(e) => format!("the publisher {} of {} left ({})", node.name(e.guid), self.from, match e.happened {
                        Happened::Left { reason } => reason,
                        _ => "",
                    }),
                    None => format!("the publishers of {} are gone", self.from),
                };
                self.end = Some(StreamEnd { reason: "publishers_gone".into(), t_s, detail });
            }
        }
        if let Some(idle) = self.idle_end_ns.filter(|_| self.last_take_ns > 0 && self.end.is_none()) {
            if now.saturating_sub(self.last_take_ns) >= idle {
                self.end = Some(StreamEnd { reason: "idle".into(), t_s, detail: format!("no message on {} for {} ms", self.from, idle / 1_000_000) });
            }
        }
        if let Some(e) = &self.end {
            eprintln!("emulator: {}: the stream ends at {:.3} s: {}", D::NAME, e.t_s, e.detail);
        }
    }
}

impl<D: Direction> Channel for Topic<D> {
    type Item = Ros2Item;
    type Extra = D::Extra;
    const NAME: &'static str = D::NAME;
    const TRACE_FILE: &'static str = D::TRACE_FILE;
    const ENDING: Ending = D::ENDING;

    #[inline]
    fn take(&mut self, _next_ingress_index: u64, clock: &mut impl FnMut() -> u64) -> Take<Ros2Item> {
        // A slot is always free: the link holds one message fewer than
        // there are slots.
        let slot = match self.next {
            Some(s) => s,
            None => {
                let s = self.slots.get_mut().alloc().expect("a free slot");
                self.next = Some(s);
                s
            }
        };
        let m = match self.reader.take(&self.slots, slot) {
            Ok(Some(m)) => m,
            Ok(None) if self.end.is_some() => return Take::End(self.sent().unwrap_or(0)),
            Ok(None) => return Take::Nothing,
            Err(e) => return Take::Failed(PortError { port: self.from.to_string(), message: e.to_string() }),
        };
        let t = clock();
        self.last_take_ns = t;
        let arrival = Arrival { sequence: Some(m.sequence as u32), console_index: m.sequence as u64, send_ns: self.send_ns(m.source, t) };
        match self.senders.saw(m.writer.to_bytes(), m.sequence) {
            Some(missing) => self.counts.lost_before_ingress += missing,
            None => self.counts.writers_untracked += 1,
        }
        let why = match m.payload {
            Payload::Stored { len } if self.read_console(slot, t) => {
                self.next = None;
                let source_ticks = m.source.map_or(0, |s| s.to_ticks());
                return Take::Item(Ros2Item { slot, len, ingress_ns: t, source_ticks }, Some(u64::from(len)), arrival);
            }
            Payload::Stored { .. } => {
                self.counts.bad_input.len_short += 1;
                Invalid::WrongSize
            }
            Payload::TooLarge { .. } => {
                self.counts.bad_input.len_oversize += 1;
                Invalid::TooLarge
            }
            Payload::Empty => {
                self.counts.bad_input.len_zero += 1;
                Invalid::WrongSize
            }
            Payload::Encoding(name) => {
                self.counts.bad_input.bad_flags += 1;
                self.counts.last_bad_encoding = Some(name);
                Invalid::BadFlags
            }
        };
        self.bad_from = Some(m.writer);
        Take::Reject(t, why, arrival)
    }

    #[inline]
    fn dropped(&mut self, item: &Ros2Item, _cause: DropCause) {
        self.slots.get_mut().free(item.slot);
    }

    /// Writes the slot's bytes under the publisher's source timestamp and
    /// frees the slot.
    #[inline]
    fn release(&mut self, item: &Ros2Item, _scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
        let slots = self.slots.get_mut();
        let source = (item.source_ticks != 0).then(|| rustdds::Timestamp::from_ticks(item.source_ticks));
        let release_ns = stamp();
        let written = self.writer.write(slots.get(item.slot), source);
        if let Some(m) = self.motion.as_mut() {
            if let Some(s) = m.read(slots.get(item.slot)) {
                m.robot(release_ns, &s);
            }
        }
        slots.free(item.slot);
        self.unsubscribed += u64::from(self.subscribers == 0);
        match written {
            Ok(()) => Ok(release_ns),
            Err(e) => {
                self.counts.window_full += u64::from(matches!(e, crate::transport::ros2::WriteFailure::WindowFull { .. }));
                Err((now_ns(), PortError { port: self.to.to_string(), message: e.to_string() }))
            }
        }
    }

    /// ROS 2 has no end of stream to send.
    fn send_end(&mut self, _released: u64) {}

    fn senders(&mut self) -> Option<usize> {
        self.look(now_ns());
        Some(self.publishers)
    }

    fn receivers(&mut self) -> Option<usize> {
        Some(self.subscribers)
    }

    fn unsubscribed(&self) -> u64 {
        self.unsubscribed
    }

    /// Balanced also asks, of a stream that ended by itself (its
    /// publishers gone, or idle: every message they sent has come), that
    /// the publishers' count is what entered, plus what was lost before the
    /// emulator and what was sent before it listened.
    fn finish(&mut self, account: &Account, _sent: Option<u64>) -> (D::Extra, bool) {
        // Named now, not when the bad input came: a node's name arrives
        // with `ros_discovery_info`, which may come after its first message.
        self.note_bad_sender();
        self.say_events(now_ns(), true);
        let node = self.node.borrow();
        self.counts.bad_input.from = self.bad_senders.iter().map(|g| node.name(*g)).collect();
        drop(node);
        let sent = self.sent();
        let own = match (&self.end, sent) {
            (Some(_), Some(s)) => s == account.entered + self.counts.lost_before_ingress + self.senders.before_first(),
            _ => true,
        };
        (D::extra(&self.counts, sent), own)
    }
}

impl ForwardChannel for Topic<Forward> {
    /// Every 4096 turns: the graph's news and the stream's end (the
    /// channel's look off the hot path), and who sent bad input.
    fn name_bad_senders(&mut self, seen: &mut u64) {
        self.look(now_ns());
        if self.counts.bad_input.total() == *seen {
            return;
        }
        *seen = self.counts.bad_input.total();
        self.note_bad_sender();
    }
}
