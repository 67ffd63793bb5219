//! The run report (`report.json`): every frame from the console's send to
//! the robot's receive, what netfi itself added, the delay law, the
//! reverse paths, how each process ended and what went wrong. Types only;
//! `service::report` joins the services' reports into one.

use super::emulator::{EmulatorProcess, PeerEvent, WithPaths};
use crate::check::StageReport;
use crate::host::Steal;
use crate::metrics::Summary;
use crate::service::console::ConsoleReport;
use crate::service::simulator::SimulatorReport;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Every frame, from the console's send to the simulator's receive.
///
/// `sent = entered + lost_before_emulator`,
/// `entered + duplicated = delivered + dropped + held_at_end`,
/// `delivered = received + lost_after_emulator`; `balanced` is true when
/// nothing was lost outside the scenario (no frame vanished between the
/// processes) and the emulator's own account closes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameAccount {
    pub sent: Option<u64>,
    pub entered: Option<u64>,
    pub delivered: Option<u64>,
    pub received: Option<u64>,
    /// Copies made by `duplicate` stages (docs/spec.md §3.8): each is then
    /// delivered, dropped or held like a frame, so `delivered` may exceed
    /// `entered` by at most these.
    #[serde(default)]
    pub duplicated: Option<u64>,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: Option<u64>,
    pub lost_before_emulator: Option<u64>,
    pub lost_after_emulator: Option<u64>,
    pub balanced: bool,
    /// What `corrupt` stages did and what the robot's checksum caught;
    /// absent when nothing was corrupted.
    #[serde(default)]
    pub corruption: Option<Corruption>,
}

/// Frames the emulator corrupted (docs/spec.md §3.9) against what the
/// simulator's ITP checksum check caught.
///
/// `delivered = caught + passed`. The checksum does not cover `pactyp`,
/// `version`, the rotations or `grasp`: a flip there passes the check and
/// the robot applies it (a flip in the grasp byte changes the grip). Caught
/// are the frames the simulator found with a bad checksum, less those that
/// already had one when they entered the emulator (`bad_checksum_passed`);
/// exact when no frame was lost after the emulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Corruption {
    /// Frames and copies queued with bits flipped.
    pub corrupted: u64,
    /// Of those, the ones released to the robot.
    pub delivered: u64,
    /// Delivered corrupted frames the robot's checksum check rejected.
    pub caught: Option<u64>,
    /// Delivered corrupted frames whose checksum still held.
    pub passed: Option<u64>,
}

/// What the injector itself adds, in ns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Overhead {
    /// Console send → taken off the console port by the emulator.
    pub ingress_wait: Option<Summary>,
    /// Frame taken off the console port → fate decided.
    pub decision: Option<Summary>,
    /// Actual − scheduled release.
    pub release_lateness: Option<Summary>,
    /// Simulator receive − console send − injected delay, through the emulator.
    pub end_to_end_extra: Option<Summary>,
    /// Simulator receive − console send of the same frames sent directly
    /// (the physical floor of one hop, measured in the same run).
    pub direct_hop: Option<Summary>,
    /// `end_to_end_extra − direct_hop`, percentile by percentile: what the
    /// emulator adds over a direct console → simulator hop. A difference of
    /// two distributions' percentiles, not a per-frame figure: it is
    /// negative where the direct hop's tail is the longer one (the two
    /// paths are preempted at different moments), and the text report says
    /// so where it prints one.
    pub added_over_direct: Option<BTreeMap<String, i64>>,
}

/// How one process ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProcessEnd {
    pub role: String,
    pub pid: u32,
    pub core: Option<usize>,
    /// `exit 0`, `exit N`, `signal N`, or `running` (still running when the
    /// runner gave up on it).
    pub status: String,
    pub log: PathBuf,
}

/// The run's files, as the report was assembled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Files {
    pub out_dir: PathBuf,
    /// The scenario as the run read it (`scenario.toml`); absent where the
    /// run's directory has none (an emulator started by hand).
    pub scenario: Option<PathBuf>,
    pub trace: Option<PathBuf>,
    pub decision_hlog: Option<PathBuf>,
    pub lateness_hlog: Option<PathBuf>,
    pub end_to_end_hlog: Option<PathBuf>,
    pub report_json: PathBuf,
    /// The files of the reverse channels, by name (`video_trace`: the
    /// emulator's video trace; `video_received`: the console's record of
    /// the video it received), where the run had them.
    #[serde(flatten)]
    pub channels: BTreeMap<String, PathBuf>,
}

/// One quantile of the delay law: as the model gives it, as the emulator
/// drew it, and as the simulator saw it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DelayQuantile {
    pub q: f64,
    /// The analytic quantile, when the scenario is one delay stage.
    pub model_ms: Option<f64>,
    /// Where the empirical quantile of a correct sampler lies with 95%
    /// confidence (DKW band mapped through the analytic law).
    pub model_band_ms: Option<[f64; 2]>,
    pub injected_ms: f64,
    pub seen_ms: f64,
    /// What the transport and the emulator's timing added at this quantile.
    pub seen_minus_injected_us: f64,
}

/// The delays the robot saw against the model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DelayCheck {
    pub frames: u64,
    pub dkw_epsilon: f64,
    pub quantiles: Vec<DelayQuantile>,
    pub max_abs_seen_minus_injected_us: f64,
    /// Every drawn quantile inside the model's 95% band.
    pub injected_within_model_band: Option<bool>,
}

/// Where a run comes from, so that a trial can be matched to its video and
/// robot logs: the netfi version, the command line as run, when it started
/// (wall clock, UTC), its seed and the host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    pub version: String,
    /// The command line, quoted so that a shell runs it again as it was.
    pub command_line: String,
    /// RFC 3339, UTC, to the second.
    pub started_utc: String,
    pub seed: u64,
    pub host: String,
}

/// The report of one run: of a `netfi run`, or assembled from what the
/// services of a run started by hand wrote in its directory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// Version, command line, wall-clock start, seed and host (absent in
    /// reports of older versions).
    #[serde(default)]
    pub provenance: Option<Provenance>,
    pub run_id: String,
    pub scenario: String,
    pub seed: u64,
    pub duration_s: f64,
    /// Stopped at a person's request (Ctrl-C, SIGTERM, the UI's stop)
    /// before its planned end: a normal end, reported as such, with what
    /// was in flight at the stop accounted for.
    #[serde(default)]
    pub stopped: bool,
    /// The run's runner did not finish it (it was killed, or failed before
    /// writing the run's report): this report was rebuilt by `netfi
    /// report` from what the run's processes left, and may be short of
    /// what they would have written. Absent when false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub interrupted: bool,
    /// No `netfi run` started this run: an emulator started by hand, with
    /// clients of any make, reported by `netfi report` from what it and
    /// they left. What no report gives (a foreign client's counts) is not
    /// known, and the frames balance on the counts there are. Absent when
    /// false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub by_hand: bool,
    pub frames: FrameAccount,
    /// The whole run's realized loss: the scenario's drops over the frames
    /// it decided (malformed frames, dropped before it, are in neither);
    /// where the run had several phases or live switches it mixes their
    /// conditions (see `phases`).
    pub loss_rate: Option<f64>,
    pub loss_rate_ci95: Option<[f64; 2]>,
    /// The models' loss in bursts longer than the run likely met, included
    /// in the upper end of `loss_rate_ci95` (docs/spec.md §5); absent where
    /// no stage has such bursts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_rate_unseen_model: Option<f64>,
    /// Each stretch of the run under one condition, in time order, where
    /// the run had phases, live switches or pauses (absent otherwise).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub phases: Vec<PhaseFigures>,
    /// Why the run's stretches could not be told apart, where it had
    /// several and they could not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phases_unknown: Option<String>,
    /// Each stage of each phase of the run's timeline (its own and those
    /// switched in): what it realized against its model.
    pub stages: Vec<StageReport>,
    /// The link stages (`rate`, `trace`): utilisation, queue occupancy
    /// over time, queueing delay percentiles (absent when none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub links: Vec<crate::check::LinkReport>,
    /// Injected delay of delivered frames (ns).
    pub injected_delay_ns: Option<Summary>,
    pub overhead_ns: Overhead,
    /// Delays seen vs drawn vs the analytic law (scenarios that delay).
    pub delay_check: Option<DelayCheck>,
    pub kinematics: Option<serde_json::Value>,
    /// Each reverse channel's section, under its name, where the run had
    /// it (`feedback`: the feedback loop; `video`: the video stream).
    #[serde(flatten)]
    pub channels: crate::service::channel::ChannelSections,
    pub processes: Vec<ProcessEnd>,
    /// What went wrong: dead processes, frames lost between processes,
    /// files cut short (`NAME.partial`).
    pub faults: Vec<String>,
    /// What the run did that is no fault but is worth saying: the report
    /// of an earlier run in the same directory replaced.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The services' reports the run's directory does not have (as
    /// `console.json`: what the console wrote): the figures that need one
    /// are unknown. A run of foreign clients has no console or robot
    /// report; in a `netfi run`, a missing report is also a fault.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub missing: Vec<String>,
    pub peer_events: Vec<PeerEvent>,
    /// Live control actions that took effect (`netfi ctl`): seconds from
    /// the run's first frame, and what was done.
    #[serde(default)]
    pub events: Vec<crate::service::control::ControlEvent>,
    pub steal: Steal,
    pub files: Files,
    pub console: Option<ConsoleReport>,
    /// The emulator's report less what stands above (its shaping: loss,
    /// stages, delays, overhead, peer events, files).
    pub emulator: Option<WithPaths<EmulatorProcess>>,
    pub simulator: Option<SimulatorReport>,
    /// Each transport's part of the emulator's report, under the
    /// transport's name, where it has one (`udp`: the sockets, what the
    /// kernel dropped before the emulator took it, and the senders it
    /// refused).
    #[serde(flatten)]
    pub transports: crate::transport::TransportReports,
    /// A run of ROS 2 topics (`--ros2-topic`): the forward topics, from
    /// `ros2.json`; the report then speaks of messages, publishers and
    /// subscribers. Absent for ITP frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Ros2Topics>,
    /// A run of several streams (`--streams N`): each stream and the
    /// total; the fields above are then stream 0's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub streams: Option<RunStreams>,
}

/// The forward topics of a ROS 2 run, as its `ros2.json` says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Ros2Topics {
    pub from: String,
    pub to: String,
    #[serde(rename = "type")]
    pub type_name: String,
    /// Messages missing from the publishers' sequences before the
    /// emulator: lost on the DDS hop or by the reader's history.
    pub lost_before_ingress: u64,
    /// Messages the publishers sent before the emulator heard from them.
    pub sent_before_emulator: u64,
}

/// One stretch of a run under one condition: a phase of the run's
/// timeline (its own scenario's, or one a live switch brought in) while
/// faults were on, or a pause (every frame passed untouched). A phase a
/// pause interrupted is two stretches. Computed from the trace (each
/// frame's ingress time and fate), the run's scenario and its control
/// events, exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseFigures {
    /// The phase of the run's timeline, from 1 (as the trace's `phase`
    /// column and the stages' `phase` count them).
    pub run_phase: usize,
    /// The scenario the phase comes from, and its phase there (from 1).
    pub scenario: String,
    pub scenario_phase: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_name: Option<String>,
    /// Faults paused: every frame passed untouched.
    pub paused: bool,
    /// When it began and ended, ns from the run's first frame (`to_ns`
    /// absent: at the run's end).
    pub from_ns: u64,
    pub to_ns: Option<u64>,
    /// Frames that entered the emulator in it (copies not counted), and
    /// of those the ones dropped.
    pub frames: u64,
    pub dropped: u64,
    /// dropped / frames, with its 95% interval (batch means over the
    /// stretch's frames in order).
    pub loss_rate: f64,
    pub loss_rate_ci95: [f64; 2],
    /// The models' loss in bursts longer than the stretch likely met,
    /// included in the upper end of `loss_rate_ci95`; absent where no
    /// stage has such bursts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_rate_unseen_model: Option<f64>,
    /// The phase's long-run loss by its model, where it has exactly one
    /// stage that drops and its model's loss is known (0 when paused).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_rate_model: Option<f64>,
    /// The delays seen and drawn in it against the phase's own delay law.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_check: Option<DelayCheck>,
}

/// One stream of a run of several, as the run report gives it (its full
/// report is `report_json`, in its directory).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunStream {
    pub stream: usize,
    pub run_id: String,
    pub scenario: String,
    pub seed: u64,
    pub frames: FrameAccount,
    pub loss_rate: Option<f64>,
    pub loss_rate_ci95: Option<[f64; 2]>,
    pub release_lateness_ns: Option<Summary>,
    pub end_to_end_extra_ns: Option<Summary>,
    pub added_over_direct_ns: Option<BTreeMap<String, i64>>,
    pub faults: Vec<String>,
    pub report_json: PathBuf,
}

/// The streams' frames summed.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamsTotal {
    pub sent: u64,
    pub entered: u64,
    pub delivered: u64,
    pub received: u64,
    pub duplicated: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    /// Every stream balanced.
    pub balanced: bool,
    /// Dropped over entered, all streams together.
    pub loss_rate: f64,
    /// The highest of the streams' release lateness p99, ns.
    pub release_lateness_p99_max_ns: Option<u64>,
}

/// `streams` of the run report: each stream and the total.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunStreams {
    pub streams: Vec<RunStream>,
    pub total: StreamsTotal,
}

