//! What the emulator writes as a process: `emulator.json` (its shaping of
//! the forward stream, its own frame account, how its loop ran, and each
//! reverse path's report under its channel's name), and the joint report
//! of several streams.

use super::ended::Ended;
use super::path::{Account, LinkMeasures, PathReport};
use crate::host::isolate::IsolationSummary;
use crate::metrics::Summary;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Bad input from the sender, by kind: each also a drop (`wrong_size` for
/// the lengths, `bad_flags`), and who was sending when it came.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BadInput {
    /// `len` 0.
    pub len_zero: u64,
    /// `len` between 1 and 123: a payload shorter than an ITP frame.
    pub len_short: u64,
    /// `len` above 124: more than the sample can carry.
    pub len_oversize: u64,
    /// Control bits no sender may set (garbage), a raw flag on an ingress
    /// without raw payloads, or a malformed end marker.
    pub bad_flags: u64,
    /// The senders on the ingress when bad input was seen (node, executable
    /// and pid; or address).
    pub from: Vec<String>,
}

impl BadInput {
    /// Bad inputs of every kind.
    pub fn total(&self) -> u64 {
        self.len_zero + self.len_short + self.len_oversize + self.bad_flags
    }
}

/// A change in a peer's presence, seen by the emulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PeerEvent {
    /// Seconds since the emulator started.
    pub t_s: f64,
    /// `console` or `simulator`.
    pub peer: String,
    /// Connected peers now.
    pub connected: usize,
}

/// The forward stream's frame account (`emulator.json`'s `frames`),
/// written with its `balanced` flag ([`EmulatorFrames::balanced`]).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
pub struct EmulatorFrames {
    #[serde(flatten)]
    pub account: Account,
    /// Frames the console said it sent (from its end marker), if it ended.
    pub sent_by_console: Option<u64>,
    /// Frames that passed with a wrong checksum (when not dropped for it).
    pub bad_checksum_passed: u64,
    /// Bad input, by kind, and who sent it.
    #[serde(default)]
    pub bad_input: BadInput,
    /// Of the delivered frames, those released while no robot was
    /// subscribed: they went nowhere (a stand-alone emulator started before
    /// its robot; see `--wait-for-peer-s`).
    #[serde(default)]
    pub delivered_unsubscribed: u64,
}

impl EmulatorFrames {
    /// Whether every frame is accounted for as far as the emulator can
    /// tell: its account closes, and the console's word (the count in its
    /// end marker), when it gave one, is what entered. The same rule as a
    /// reverse path's `balanced`; whether the robot received what was
    /// delivered only the run report can tell.
    pub fn balanced(&self) -> bool {
        self.account.closes() && self.sent_by_console.is_none_or(|n| n == self.account.entered)
    }

    /// Adds `o`'s counts to these (a console's word adds up only when every
    /// console gave it).
    pub fn add(&mut self, o: &EmulatorFrames) {
        self.account.add(&o.account);
        self.sent_by_console = match (self.sent_by_console, o.sent_by_console) {
            (Some(a), Some(b)) => Some(a + b),
            _ => None,
        };
        self.bad_checksum_passed += o.bad_checksum_passed;
        self.delivered_unsubscribed += o.delivered_unsubscribed;
    }
}

impl Serialize for EmulatorFrames {
    /// The fields, and `balanced` after them: derived, never stored, so
    /// that it cannot disagree with the counts (read back, it is ignored).
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        #[derive(Serialize)]
        struct Written<'a> {
            #[serde(flatten)]
            account: &'a Account,
            sent_by_console: Option<u64>,
            bad_checksum_passed: u64,
            bad_input: &'a BadInput,
            delivered_unsubscribed: u64,
            balanced: bool,
        }
        let f = self;
        Written {
            account: &f.account,
            sent_by_console: f.sent_by_console,
            bad_checksum_passed: f.bad_checksum_passed,
            bad_input: &f.bad_input,
            delivered_unsubscribed: f.delivered_unsubscribed,
            balanced: f.balanced(),
        }
        .serialize(s)
    }
}

/// What the link did to the stream, and where its files are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Shaping {
    #[serde(flatten)]
    pub link: LinkMeasures,
    pub peer_events: Vec<PeerEvent>,
    /// Live control actions that took effect (`netfi ctl`), in order; also
    /// streamed to `events.jsonl` as they happen.
    #[serde(default)]
    pub events: Vec<crate::service::control::ControlEvent>,
    pub trace_path: Option<PathBuf>,
    pub decision_hlog: Option<PathBuf>,
    pub lateness_hlog: Option<PathBuf>,
}

/// The emulator as a process: its set-up, its own frame account, how its
/// loop ran and ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorProcess {
    pub scenario: String,
    pub seed: u64,
    pub core: Option<usize>,
    /// SCHED_FIFO priority the loop ran at, if any.
    pub realtime_priority: Option<i32>,
    /// The process's other threads (trace writers, the control thread, a
    /// DDS library's threads), by name, and the CPUs they could use: off
    /// the loop's core where another one was there.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub threads: Vec<crate::host::placement::ThreadPlace>,
    /// What was moved off the loop's core for the run (`--isolate`), and
    /// put back after.
    #[serde(default)]
    pub isolation: Option<IsolationSummary>,
    pub queue_order: String,
    pub queue_capacity: usize,
    pub frames: EmulatorFrames,
    /// Why the loop ended: `end_marker` (the console finished and every held
    /// frame was released), `signal`, or `peer_died` (see `dead_peers`).
    pub ended_by: Ended,
    /// Peers of the run found dead by the emulator (role, executable, pid).
    #[serde(default)]
    pub dead_peers: Vec<String>,
    pub duration_s: f64,
    /// Turns of the busy loop, and the mean time of one: how often it looked
    /// for due releases and for a new frame.
    #[serde(default)]
    pub loop_iterations: u64,
    #[serde(default)]
    pub loop_iteration_ns_mean: f64,
    pub receive_errors: u64,
    pub send_errors: u64,
    pub trace_overflowed: u64,
    pub steal_ms: u64,
    pub steal_fraction: f64,
    /// The loop's time on frames, and the rate it implies ([`LoopBusy`]).
    #[serde(default)]
    pub busy: Option<LoopBusy>,
    /// The motion in the frames taken in (the console's) and released
    /// (towards the robot), with `--kinematics`: a
    /// [`crate::kinematics::KinematicsReport`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinematics: Option<serde_json::Value>,
}

/// The emulator's own report, written as `emulator.json`: one flat JSON
/// object. What the run report shows at its top level (the shaping) is
/// kept apart from the rest (the process and its reverse paths), so that
/// the run report carries each field once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorReport {
    #[serde(flatten)]
    pub shaping: Shaping,
    #[serde(flatten)]
    pub process: WithPaths<EmulatorProcess>,
}

/// `T`'s members, and each reverse path's report (feedback, video, the UDP
/// return) as a member under its channel's name, with `paths` listing
/// those names: one JSON object. Reads as a `T`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WithPaths<T> {
    pub inner: T,
    /// The reverse paths' reports, by channel name.
    pub paths: BTreeMap<String, serde_json::Value>,
}

impl<T> std::ops::Deref for WithPaths<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.inner
    }
}

impl<T> std::ops::DerefMut for WithPaths<T> {
    fn deref_mut(&mut self) -> &mut T {
        &mut self.inner
    }
}

impl<T> WithPaths<T> {
    /// The report of the reverse path `name`, if the run had one.
    pub fn path<X: DeserializeOwned>(&self, name: &str) -> Option<PathReport<X>> {
        serde_json::from_value(self.paths.get(name)?.clone()).ok()
    }
}

impl<T: Serialize> Serialize for WithPaths<T> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::Error;
        let mut object = match serde_json::to_value(&self.inner).map_err(S::Error::custom)? {
            serde_json::Value::Object(m) => m,
            _ => return Err(S::Error::custom("a report with paths is an object")),
        };
        object.insert("paths".into(), self.paths.keys().cloned().collect::<Vec<_>>().into());
        object.extend(self.paths.clone());
        object.serialize(s)
    }
}

impl<'de, T: DeserializeOwned> Deserialize<'de> for WithPaths<T> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let object = serde_json::Map::<String, serde_json::Value>::deserialize(d)?;
        let names: Vec<String> = match object.get("paths") {
            Some(v) => serde_json::from_value(v.clone()).map_err(D::Error::custom)?,
            None => Vec::new(),
        };
        let paths = names.iter().filter_map(|n| Some((n.clone(), object.get(n)?.clone()))).collect();
        let inner = serde_json::from_value(serde_json::Value::Object(object)).map_err(D::Error::custom)?;
        Ok(WithPaths { inner, paths })
    }
}

/// The emulator loop's time on frames, measured in every run from the clock
/// read each turn already makes, and the capacity it implies.
///
/// A turn is *busy* when it took at least one frame off the ingress or
/// released at least one (the stream's own frames; the reverse paths alone
/// do not make a turn busy). A busy turn's time runs from its start to the
/// start of the next turn (or the loop's end), so it holds everything the
/// turn did: the iceoryx2 (or UDP) receive and send, the copies of the
/// sample into the loop, the queue and the publisher's sample, the
/// decision, the trace and histograms, the reverse paths' polls of that
/// turn, and the loop's own bookkeeping every 4096 turns when it falls in
/// one. It leaves out every idle turn (polling an empty ingress with nothing
/// due), and the wait of a release prepared ahead of its time (the
/// preparation overlapping that wait, one pop and copy, is left out with
/// it: this only happens on an idle loop, never on a busy stream). Anything
/// that takes the core during a busy turn (another thread, an interrupt, the
/// hypervisor) is counted in it, so the time is an upper bound on what the
/// frames cost, and the capacity a lower bound on the rate this loop could
/// carry with the core to itself. When one loop serves several streams,
/// each stream's turn ends at the clock read right after it, and the
/// releases made for every stream between turns are in no stream's time.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopBusy {
    /// Turns of the loop (of this stream, when one loop serves several).
    pub turns: u64,
    /// Of those, turns that took or released at least one frame.
    pub busy_turns: u64,
    /// Their time, ns.
    pub busy_ns: u64,
    /// Frames taken off the ingress (entered, rejected ones included).
    pub frames: u64,
    /// `busy_ns / frames`: the loop's time per frame, taking and releasing.
    pub busy_ns_per_frame: Option<f64>,
    /// `1e9 / busy_ns_per_frame`: the frames a second the loop could take
    /// and release if it did nothing but busy turns.
    pub capacity_frames_per_s: Option<f64>,
    /// Of the busy turns, those longer than the long-turn bound, and their
    /// time (also in `busy_turns` and `busy_ns`): the loop most likely lost
    /// its core inside them (a turn's own work is far shorter).
    #[serde(default)]
    pub long_turns: u64,
    #[serde(default)]
    pub long_ns: u64,
    /// The time per frame of the busy turns but the long ones, over the
    /// frames taken and released in them, scaled to every frame: the cost
    /// with the time the core was lost for mostly left out, a better
    /// estimate than `busy_ns_per_frame` where other work shares the core.
    /// A long turn that did not lose its core is a large batch, which pays
    /// the turn's fixed work once for many frames, so leaving it out can
    /// only raise this figure: it still leans towards the cost's high side.
    #[serde(default)]
    pub short_turns_ns_per_frame: Option<f64>,
    /// `1e9 / short_turns_ns_per_frame`.
    #[serde(default)]
    pub short_turns_capacity_frames_per_s: Option<f64>,
}

/// One stream's part of the emulator's report of several streams.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorStream {
    pub stream: usize,
    /// The run id its services are named from.
    pub run_id: String,
    pub scenario: String,
    pub seed: u64,
    /// Its directory (its own `emulator.json`, trace and histograms).
    pub dir: PathBuf,
    pub frames: EmulatorFrames,
    pub loss_rate: f64,
    pub ingress_wait_ns: Summary,
    pub decision_ns: Summary,
    pub release_lateness_ns: Summary,
}

/// `emulator.json` of a run of several streams: each stream, the total,
/// and the one loop that served them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EmulatorStreams {
    pub streams: Vec<EmulatorStream>,
    /// The streams' accounts summed.
    pub total: EmulatorFrames,
    /// Every stream's account closes.
    pub balanced: bool,
    pub core: Option<usize>,
    /// Why the one loop ended: `end_marker`, `signal` or `peer_died`.
    pub ended_by: Ended,
    pub duration_s: f64,
    /// Rounds of the loop (each turns every stream once), and the mean
    /// time of one.
    pub loop_rounds: u64,
    pub loop_round_ns_mean: f64,
    pub steal_fraction: f64,
    /// The loop's time on frames, all streams together (the streams' own
    /// `busy` summed).
    #[serde(default)]
    pub busy: Option<LoopBusy>,
}


#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reverse_paths_stand_under_their_names_and_come_back() {
        let report: EmulatorReport = serde_json::from_value(serde_json::json!({
            "loss_rate": 0.5, "loss_rate_ci95": [0.4, 0.6], "stages": [],
            "injected_delay_ns": Summary::default(), "ingress_wait_ns": Summary::default(),
            "decision_ns": Summary::default(), "release_lateness_ns": Summary::default(),
            "peer_events": [], "trace_path": null, "decision_hlog": null, "lateness_hlog": null,
            "scenario": "PLM-2", "seed": 7, "core": null, "realtime_priority": null,
            "queue_order": "fifo", "queue_capacity": 16,
            "frames": { "entered": 4, "delivered": 2, "dropped": {"ge_lomax": 2}, "held_at_end": 0,
                        "sent_by_console": 4, "bad_checksum_passed": 0 },
            "ended_by": "end_marker", "duration_s": 1.0, "receive_errors": 0, "send_errors": 0,
            "trace_overflowed": 0, "steal_ms": 0, "steal_fraction": 0.0,
            "paths": ["feedback"], "feedback": { "entered": 3, "sent_by_robot": 3 },
            "stranger": { "entered": 9 }
        }))
        .unwrap();
        assert_eq!(report.process.frames.account.entered, 4);
        assert!(report.process.frames.account.closes());
        assert_eq!(report.process.paths.keys().collect::<Vec<_>>(), ["feedback"], "only the listed paths are paths");
        let back = serde_json::to_value(&report).unwrap();
        assert_eq!(back["paths"], serde_json::json!(["feedback"]));
        assert_eq!(back["feedback"]["sent_by_robot"], 3);
        assert_eq!(back["frames"]["entered"], 4);
        assert_eq!(back["loss_rate"], 0.5);
        assert_eq!(serde_json::from_value::<EmulatorReport>(back).unwrap(), report);
    }

    /// Every field set, none to its default.
    fn frames() -> EmulatorFrames {
        EmulatorFrames {
            account: Account {
                entered: 10,
                delivered: 6,
                duplicated: 1,
                corrupted: 2,
                corrupted_delivered: 1,
                dropped: [("bernoulli".to_string(), 4)].into(),
                held_at_end: 1,
            },
            sent_by_console: Some(10),
            bad_checksum_passed: 3,
            bad_input: BadInput { len_zero: 1, len_short: 2, len_oversize: 3, bad_flags: 4, from: vec!["console (pid 1)".into()] },
            delivered_unsubscribed: 5,
        }
    }

    #[test]
    fn the_forward_frames_say_whether_they_balance_and_read_back_whole() {
        let f = frames();
        let json = serde_json::to_value(&f).unwrap();
        assert_eq!(json["balanced"], true, "{json}");
        assert_eq!(json["entered"], 10, "the account stands flat beside the rest: {json}");
        // Every field is written: what is read back is what was written.
        assert_eq!(serde_json::from_value::<EmulatorFrames>(json).unwrap(), f);
        // The console said it sent more than entered: frames were lost before the emulator.
        let lost = EmulatorFrames { sent_by_console: Some(11), ..frames() };
        assert!(!lost.balanced());
        assert_eq!(serde_json::to_value(&lost).unwrap()["balanced"], false);
        // The account does not close.
        let mut open = frames();
        open.account.held_at_end = 0;
        assert!(!open.balanced());
        // No word from the console: the account alone decides, as for a reverse path.
        assert!(EmulatorFrames { sent_by_console: None, ..frames() }.balanced());
        // A `balanced` read back is not believed: the counts decide.
        let mut lie = serde_json::to_value(&lost).unwrap();
        lie["balanced"] = true.into();
        assert!(!serde_json::from_value::<EmulatorFrames>(lie).unwrap().balanced());
    }
}
