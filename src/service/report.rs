//! The run report: the three services' own reports joined into one account
//! of every frame, with the overhead histograms and the host's steal time.

use crate::check::StageReport;
use crate::host::Steal;
use crate::metrics::{fmt_ns, Summary};
use crate::scenario::{self, Scenario};
use crate::service::console::ConsoleReport;
use crate::service::schema::FeedbackExtra;
use crate::service::schema::VideoExtra;
use crate::service::schema::{EmulatorProcess, EmulatorReport, PathReport, PeerEvent, WithPaths};
use crate::service::plan::Plan;
use crate::service::simulator::SimulatorReport;
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

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

impl RunStream {
    /// Stream `k`'s line of its own report.
    pub fn of(k: usize, r: &RunReport) -> RunStream {
        RunStream {
            stream: k,
            run_id: r.run_id.clone(),
            scenario: r.scenario.clone(),
            seed: r.seed,
            frames: r.frames.clone(),
            loss_rate: r.loss_rate,
            loss_rate_ci95: r.loss_rate_ci95,
            release_lateness_ns: r.overhead_ns.release_lateness,
            end_to_end_extra_ns: r.overhead_ns.end_to_end_extra,
            added_over_direct_ns: r.overhead_ns.added_over_direct.clone(),
            faults: r.faults.clone(),
            report_json: r.files.report_json.clone(),
        }
    }
}

impl RunStreams {
    /// The streams' lines and their total.
    pub fn of(streams: Vec<RunStream>) -> RunStreams {
        let mut t = StreamsTotal { balanced: true, ..StreamsTotal::default() };
        for s in &streams {
            let f = &s.frames;
            t.sent += f.sent.unwrap_or(0);
            t.entered += f.entered.unwrap_or(0);
            t.delivered += f.delivered.unwrap_or(0);
            t.received += f.received.unwrap_or(0);
            t.duplicated += f.duplicated.unwrap_or(0);
            t.held_at_end += f.held_at_end.unwrap_or(0);
            for (k, v) in &f.dropped {
                *t.dropped.entry(k.clone()).or_default() += v;
            }
            t.balanced &= f.balanced;
        }
        let dropped: u64 = t.dropped.values().sum();
        t.loss_rate = if t.entered > 0 { dropped as f64 / t.entered as f64 } else { 0.0 };
        t.release_lateness_p99_max_ns = streams.iter().filter_map(|s| s.release_lateness_ns.map(|p| p.p99)).max();
        RunStreams { streams, total: t }
    }

    /// The table of streams, for the text report.
    pub fn to_text(&self) -> String {
        let opt = |v: Option<u64>| v.map_or("?".to_string(), |x| x.to_string());
        let mut s = format!("streams    {} (the figures above are stream 0's)\n", self.streams.len());
        s += "  stream  scenario          sent  entered  delivered  received  dropped  held  loss     lateness p99  balanced\n";
        for st in &self.streams {
            let f = &st.frames;
            s += &format!(
                "  {:<6}  {:<16} {:>6} {:>8} {:>10} {:>9} {:>8} {:>5}  {:<7.4}  {:>12}  {}\n",
                st.stream,
                st.scenario,
                opt(f.sent),
                opt(f.entered),
                opt(f.delivered),
                opt(f.received),
                f.dropped.values().sum::<u64>(),
                opt(f.held_at_end),
                st.loss_rate.unwrap_or(f64::NAN),
                st.release_lateness_ns.map_or("?".into(), |p| crate::metrics::fmt_ns(p.p99)),
                if f.balanced { "yes" } else { "NO" }
            );
        }
        let t = &self.total;
        s += &format!(
            "  total   {:<16} {:>6} {:>8} {:>10} {:>9} {:>8} {:>5}  {:<7.4}  {:>12}  {}\n",
            "",
            t.sent,
            t.entered,
            t.delivered,
            t.received,
            t.dropped.values().sum::<u64>(),
            t.held_at_end,
            t.loss_rate,
            t.release_lateness_p99_max_ns.map_or("?".into(), crate::metrics::fmt_ns),
            if t.balanced { "yes" } else { "NO" }
        );
        s
    }
}

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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Files {
    pub out_dir: PathBuf,
    pub scenario: PathBuf,
    pub trace: Option<PathBuf>,
    pub decision_hlog: Option<PathBuf>,
    pub lateness_hlog: Option<PathBuf>,
    pub end_to_end_hlog: Option<PathBuf>,
    pub report_json: PathBuf,
    /// The emulator's video trace (`trace_video.csv`), when the run has video.
    #[serde(default)]
    pub video_trace: Option<PathBuf>,
    /// The console's record of the video it received (`video_received.csv`).
    #[serde(default)]
    pub video_received: Option<PathBuf>,
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

/// The feedback loop robot → emulator → console: what the return scenario
/// did, every feedback sample accounted for, and the round trip.
///
/// `sent_by_robot = entered`, `entered + duplicated = delivered + dropped +
/// held_at_end`, `delivered = received_by_console`: `balanced`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeedbackSection {
    pub return_scenario: String,
    pub seed: u64,
    pub sent_by_robot: Option<u64>,
    pub entered: u64,
    pub delivered: u64,
    /// Copies made by `duplicate` stages of the return scenario.
    #[serde(default)]
    pub duplicated: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    pub received_by_console: Option<u64>,
    pub balanced: bool,
    pub loss_rate: f64,
    pub loss_rate_ci95: [f64; 2],
    pub injected_delay_ns: Summary,
    /// Command sent → the robot's feedback naming it received, at the console.
    pub round_trip_ns: Option<Summary>,
    /// The emulator's own share of each round trip (both directions).
    pub emulator_share_ns: Option<Summary>,
    /// The robot's position (from its feedback) against the console's,
    /// per arm, mm: at the last feedback, and the most seen.
    pub divergence_final_mm: Option<[f64; 2]>,
    pub divergence_max_mm: Option<[f64; 2]>,
}

impl FeedbackSection {
    /// Joins the emulator's feedback path, the console's view of it and
    /// the robot's own count of what it sent (`robot_sent`, from its
    /// report): that count stands where the robot's end marker did not
    /// reach the emulator before it stopped waiting for it.
    pub fn join(
        e: &PathReport<FeedbackExtra>,
        c: Option<&crate::service::console::ConsoleFeedback>,
        robot_sent: Option<u64>,
    ) -> FeedbackSection {
        let received_by_console = c.map(|c| c.received);
        let sent_by_robot = e.extra.sent_by_robot.or(robot_sent);
        let a = &e.account;
        let balanced = sent_by_robot == Some(a.entered) && a.closes() && received_by_console == Some(a.delivered);
        FeedbackSection {
            return_scenario: e.scenario.clone(),
            seed: e.seed,
            sent_by_robot,
            entered: a.entered,
            delivered: a.delivered,
            duplicated: a.duplicated,
            dropped: a.dropped.clone(),
            held_at_end: a.held_at_end,
            received_by_console,
            balanced,
            loss_rate: e.measures.loss_rate,
            loss_rate_ci95: e.measures.loss_rate_ci95,
            injected_delay_ns: e.measures.injected_delay_ns,
            round_trip_ns: c.map(|c| c.round_trip_ns).filter(|s| s.count > 0),
            emulator_share_ns: c.map(|c| c.emulator_share_ns).filter(|s| s.count > 0),
            divergence_final_mm: c.map(|c| c.divergence_final_mm),
            divergence_max_mm: c.map(|c| c.divergence_max_mm),
        }
    }

    fn to_text(&self) -> String {
        let opt = |v: Option<u64>| v.map_or("?".to_string(), |x| x.to_string());
        let dropped: Vec<String> = self.dropped.iter().map(|(k, v)| format!("{v} by {k}")).collect();
        let mut s = format!(
            "feedback   return scenario {} (seed {}): sent by robot {}  entered {}  delivered {}  received {}  held at end {}; dropped {}\n",
            self.return_scenario,
            self.seed,
            opt(self.sent_by_robot),
            self.entered,
            self.delivered,
            opt(self.received_by_console),
            self.held_at_end,
            if dropped.is_empty() { "none".into() } else { dropped.join(", ") }
        );
        if self.duplicated > 0 {
            s += &format!("  duplicated {} copies made (delivered may exceed entered by these)\n", self.duplicated);
        }
        s += &format!(
            "  accounting {}; loss {:.4}, 95% CI [{:.4}, {:.4}]\n",
            if self.balanced { "balanced" } else { "NOT balanced" },
            self.loss_rate,
            self.loss_rate_ci95[0],
            self.loss_rate_ci95[1]
        );
        s += &format!("  round trip        {}\n", line(&self.round_trip_ns));
        s += &format!("  emulator's share  {}\n", line(&self.emulator_share_ns));
        if let (Some(f), Some(m)) = (self.divergence_final_mm, self.divergence_max_mm) {
            s += &format!("  live divergence   arm 0 final {:.2} mm (max {:.2}), arm 1 final {:.2} mm (max {:.2})\n", f[0], m[0], f[1], m[1]);
        }
        s
    }
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

impl Provenance {
    /// This process's version, command line and host name; `started` is the
    /// wall-clock time the run began.
    pub fn capture(started: std::time::SystemTime, seed: u64) -> Provenance {
        let words: Vec<String> = std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect();
        // Only a word with a NUL byte cannot be quoted; an argument never has one.
        let command_line = shlex::try_join(words.iter().map(String::as_str)).unwrap_or_else(|_| words.join(" "));
        Provenance {
            version: env!("CARGO_PKG_VERSION").to_string(),
            command_line,
            started_utc: humantime::format_rfc3339_seconds(started).to_string(),
            seed,
            host: host_name(),
        }
    }

    fn to_text(&self) -> String {
        format!("provenance netfi {} on {}, started {} (seed {})
  command  {}
", self.version, self.host, self.started_utc, self.seed, self.command_line)
    }
}

/// The host's name (`gethostname`), or `unknown`.
fn host_name() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: the buffer is writable for its whole length; the name is
    // NUL-terminated within it unless truncated, which the search below allows for.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    let len = buf.iter().position(|b| *b == 0).unwrap_or(buf.len());
    if rc != 0 || len == 0 {
        return "unknown".into();
    }
    String::from_utf8_lossy(&buf[..len]).into_owned()
}

/// The report of one `netfi run`.
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
    pub frames: FrameAccount,
    pub loss_rate: Option<f64>,
    pub loss_rate_ci95: Option<[f64; 2]>,
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
    /// The feedback loop, when it was open.
    #[serde(default)]
    pub feedback: Option<FeedbackSection>,
    /// The video stream, when the run has one (`--video-mbps`).
    #[serde(default)]
    pub video: Option<crate::service::video::VideoSection>,
    pub processes: Vec<ProcessEnd>,
    /// What went wrong: dead processes, frames lost between processes.
    pub faults: Vec<String>,
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
    /// A run of several streams (`--streams N`): each stream and the
    /// total; the fields above are then stream 0's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub streams: Option<RunStreams>,
}

/// Joins the services' reports.
pub fn account(console: Option<&ConsoleReport>, emulator: Option<&EmulatorProcess>, simulator: Option<&SimulatorReport>) -> FrameAccount {
    let sent = console.map(|c| c.frames_sent).or_else(|| emulator.and_then(|e| e.frames.sent_by_console));
    let entered = emulator.map(|e| e.frames.account.entered);
    let delivered = emulator.map(|e| e.frames.account.delivered);
    let received = simulator.map(|s| s.received);
    let duplicated = emulator.map(|e| e.frames.account.duplicated);
    let held_at_end = emulator.map(|e| e.frames.account.held_at_end);
    let dropped = emulator.map(|e| e.frames.account.dropped.clone()).unwrap_or_default();
    let lost_before_emulator = sent.zip(entered).map(|(s, e)| s.saturating_sub(e));
    let lost_after_emulator = delivered.zip(received).map(|(d, r)| d.saturating_sub(r));
    let emulator_closes = match (entered, delivered, held_at_end) {
        (Some(e), Some(d), Some(h)) => e + duplicated.unwrap_or(0) == d + dropped.values().sum::<u64>() + h,
        _ => false,
    };
    let balanced = emulator_closes && lost_before_emulator == Some(0) && lost_after_emulator == Some(0) && sent == entered && delivered == received;
    let corruption = emulator.filter(|e| e.frames.account.corrupted > 0).map(|e| {
        let (f, a) = (&e.frames, &e.frames.account);
        let caught = simulator.map(|s| s.bad_checksum.saturating_sub(f.bad_checksum_passed).min(a.corrupted_delivered));
        Corruption { corrupted: a.corrupted, delivered: a.corrupted_delivered, caught, passed: caught.map(|c| a.corrupted_delivered - c) }
    });
    FrameAccount { sent, entered, delivered, received, duplicated, dropped, held_at_end, lost_before_emulator, lost_after_emulator, balanced, corruption }
}

/// `a − b` for the main percentiles.
pub fn difference(a: &Summary, b: &Summary) -> BTreeMap<String, i64> {
    crate::metrics::difference(a, b, &["p50", "p90", "p99", "p999"])
}

fn line(p: &Option<Summary>) -> String {
    match p {
        Some(p) => format!(
            "p50 {}  p90 {}  p99 {}  p99.9 {}  p99.99 {}  max {}",
            fmt_ns(p.p50),
            fmt_ns(p.p90),
            fmt_ns(p.p99),
            fmt_ns(p.p999),
            fmt_ns(p.p9999),
            fmt_ns(p.max)
        ),
        None => "unavailable".into(),
    }
}

impl RunReport {
    /// The report as a person reads it.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let opt = |v: Option<u64>| v.map_or("?".to_string(), |x| x.to_string());
        let f = &self.frames;
        s += &format!("netfi run {}: scenario {} (seed {}), {:.2} s\n", self.run_id, self.scenario, self.seed, self.duration_s);
        if let Some(p) = &self.provenance {
            s += &p.to_text();
        }
        s += &format!(
            "frames     sent {}  entered {}  delivered {}  received {}  held at end {}\n",
            opt(f.sent),
            opt(f.entered),
            opt(f.delivered),
            opt(f.received),
            opt(f.held_at_end)
        );
        if let Some(n) = f.duplicated.filter(|n| *n > 0) {
            s += &format!("duplicated {n} copies made (each delivered, dropped or held like a frame: delivered may exceed entered by these)\n");
        }
        let dropped: Vec<String> = f.dropped.iter().map(|(k, v)| format!("{v} by {k}")).collect();
        s += &format!("dropped    {}\n", if dropped.is_empty() { "none".into() } else { dropped.join(", ") });
        if let Some(c) = &f.corruption {
            s += &format!(
                "corrupted  {} queued with flipped bits, {} delivered: {} caught by the robot's checksum, {} passed (the checksum does not cover pactyp, version, the rotations or the grasp byte: a flip there is applied)\n",
                c.corrupted,
                c.delivered,
                opt(c.caught),
                opt(c.passed)
            );
        }
        s += &format!(
            "accounting {}\n",
            if f.balanced {
                "balanced: every frame that entered (and every copy made) was delivered, dropped by the scenario, or held at the end".to_string()
            } else {
                format!("NOT balanced (lost before emulator {}, after emulator {})", opt(f.lost_before_emulator), opt(f.lost_after_emulator))
            }
        );
        if let (Some(l), Some([lo, hi])) = (self.loss_rate, self.loss_rate_ci95) {
            s += &format!("loss       {:.4} realized, 95% CI [{lo:.4}, {hi:.4}]\n", l);
        }
        for st in &self.stages {
            let model = match (st.loss_rate_model, st.delay_ms_model) {
                (_, Some(d)) => format!("model mean delay {d:.3} ms"),
                (Some(l), None) => format!("model loss {l:.4}"),
                _ => String::new(),
            };
            s += &format!("  phase {} stage {} {:<14} reached {:>9} dropped {:>9} ({:.4})  {model}\n", st.phase, st.stage, st.label, st.reached, st.dropped, st.loss_rate);
        }
        s += &links_text(&self.links);
        if let Some(d) = &self.injected_delay_ns {
            s += &format!("delay      injected mean {:.3} ms; {}\n", d.mean / 1e6, line(&self.injected_delay_ns));
        }
        s += "overhead (what netfi itself adds)\n";
        s += &format!("  ingress wait      {}\n", line(&self.overhead_ns.ingress_wait));
        s += &format!("  decision          {}\n", line(&self.overhead_ns.decision));
        s += &format!("  release lateness  {}\n", line(&self.overhead_ns.release_lateness));
        s += &format!("  end-to-end extra  {}\n", line(&self.overhead_ns.end_to_end_extra));
        s += &format!("  direct hop        {}\n", line(&self.overhead_ns.direct_hop));
        if let Some(a) = &self.overhead_ns.added_over_direct {
            s += &format!("  added over direct p50 {} ns  p99 {} ns  p99.9 {} ns\n", a["p50"], a["p99"], a["p999"]);
            if a.values().any(|v| *v < 0) {
                s += "    (each a difference of the two lines above at that percentile, not a per-frame figure: negative\n     where the direct hop's own tail is longer; release lateness is the emulator's per-frame cost)\n";
            }
        }
        if let Some(b) = self.emulator.as_ref().and_then(|e| e.busy.as_ref()) {
            s += &busy_text(b);
        }
        if let Some(dc) = &self.delay_check {
            s += &format!("delay law  {} frames; quantile  model  [95% band]  drawn  seen  seen−drawn\n", dc.frames);
            for q in &dc.quantiles {
                let model = match (q.model_ms, q.model_band_ms) {
                    (Some(m), Some([lo, hi])) => format!("{m:9.3} [{lo:.3}, {hi:.3}]"),
                    _ => "-".into(),
                };
                s += &format!("  q{:<5} {model}  {:9.3} ms  {:9.3} ms  {:+8.1} µs\n", q.q, q.injected_ms, q.seen_ms, q.seen_minus_injected_us);
            }
        }
        if let Some(k) = &self.kinematics {
            s += &kinematics_text(k);
        }
        if let Some(fb) = &self.feedback {
            s += &fb.to_text();
        }
        if let Some(v) = &self.video {
            s += &v.to_text();
        }
        s += &format!("host steal {} ms ({:.3}% of CPU time)\n", self.steal.ms, self.steal.fraction * 100.0);
        for p in &self.processes {
            s += &format!("process    {:<9} pid {:<7} core {:<5} {}\n", p.role, p.pid, p.core.map_or("-".into(), |c| c.to_string()), p.status);
        }
        if let Some(i) = self.emulator.as_ref().and_then(|e| e.isolation.as_ref()) {
            s += &format!("isolation  {i}
");
        }
        for e in &self.peer_events {
            s += &format!("peer       t={:.3}s {} connected: {}\n", e.t_s, e.peer, e.connected);
        }
        for e in &self.events {
            s += &format!("control    t={:.3}s {}\n", e.t_s, e.what);
        }
        for fault in &self.faults {
            s += &format!("FAULT      {fault}\n");
        }
        s += &format!("files      {}\n", self.files.out_dir.display());
        if let Some(t) = &self.files.trace {
            s += &format!("  trace     {}\n", t.display());
        }
        for h in [&self.files.decision_hlog, &self.files.lateness_hlog, &self.files.end_to_end_hlog].into_iter().flatten() {
            s += &format!("  histogram {}\n", h.display());
        }
        for v in [&self.files.video_trace, &self.files.video_received].into_iter().flatten() {
            s += &format!("  video     {}\n", v.display());
        }
        s += &format!("  report    {}\n", self.files.report_json.display());
        if let Some(st) = &self.streams {
            s += &st.to_text();
        }
        s
    }
}

/// The emulator loop's time on frames, as a line of the overhead part.
fn busy_text(b: &crate::service::schema::LoopBusy) -> String {
    let (per, cap) = match (b.busy_ns_per_frame, b.capacity_frames_per_s) {
        (Some(p), Some(c)) => (format!("{p:.0} ns a frame"), format!("{c:.0} frames/s")),
        _ => ("-".into(), "-".into()),
    };
    let mut s = format!(
        "  emulator loop     {} of {} turns busy, {:.3} ms on {} frames: {per}, capacity {cap} (busy time is an upper bound on the cost)\n",
        b.busy_turns,
        b.turns,
        b.busy_ns as f64 / 1e6,
        b.frames
    );
    if let (Some(p), Some(c)) = (b.short_turns_ns_per_frame, b.short_turns_capacity_frames_per_s) {
        s += &format!(
            "    without the {} turns over 200 µs ({:.3} ms; the core most likely lost): {p:.0} ns a frame, capacity {c:.0} frames/s\n",
            b.long_turns,
            b.long_ns as f64 / 1e6
        );
    }
    s
}

/// The kinematics as lines: per arm, the motion length on each side and the
/// divergence; clutch activations; stalls at the robot.
/// The link stages' lines of the text report.
fn links_text(links: &[crate::check::LinkReport]) -> String {
    let mut s = String::new();
    for l in links {
        s += &format!(
            "  link phase {} {:<14} utilisation {:.3} ({:.0} of {:.0} bit/s); queue max {} packets, {} bytes; time at stage p50 {:.3} ms p99 {:.3} ms max {:.3} ms; {} of {} frames dropped for the queue\n",
            l.phase,
            l.label,
            l.utilisation,
            l.carried_bit_s,
            l.capacity_bit_s,
            l.queue_packets_max,
            l.queue_bytes_max,
            l.delay_ms.p50,
            l.delay_ms.p99,
            l.delay_ms.max,
            l.frames_dropped,
            l.frames + l.frames_dropped
        );
    }
    s
}

fn kinematics_text(k: &serde_json::Value) -> String {
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let mut s = String::new();
    for arm in 0..2 {
        s += &format!(
            "kinematics arm {arm}: motion console {:.1} mm, robot {:.1} mm; divergence final {:.2} mm, max {:.2} mm\n",
            f(&k["console"]["length_mm"][arm]),
            f(&k["robot"]["length_mm"][arm]),
            f(&k["divergence"][arm]["final_mm"]),
            f(&k["divergence"][arm]["max_mm"]),
        );
    }
    let st = &k["robot"]["stalls"];
    s += &format!(
        "           clutch activations console {} robot {}; robot stalls {} (longest {:.1} ms, total {:.1} ms)\n",
        k["console"]["clutch_activations"],
        k["robot"]["clutch_activations"],
        st["count"],
        f(&st["longest_ns"]) / 1e6,
        f(&st["total_ns"]) / 1e6,
    );
    s
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Option<T> {
    let bytes = std::fs::read(path).ok()?;
    serde_json::from_slice(&bytes).ok()
}

impl RunReport {
    /// Joins what the services left in the run's output directory into the
    /// run's report. `faults` holds what the runner saw go wrong (dead
    /// processes); the report adds missing reports, lost frames, an
    /// interruption and a trace that could not be joined.
    pub fn assemble(plan: &Plan, duration_s: f64, steal: Steal, processes: Vec<ProcessEnd>, mut faults: Vec<String>, interrupted: bool) -> RunReport {
        let out = &plan.out;
        let console: Option<ConsoleReport> = read_json(&out.join("console.json"));
        let emulator: Option<EmulatorReport> = read_json(&out.join("emulator.json"));
        let simulator: Option<SimulatorReport> = read_json(&out.join("simulator.json"));
        for (role, missing) in [("console", console.is_none()), ("emulator", emulator.is_none()), ("simulator", simulator.is_none())] {
            if missing {
                faults.push(format!("no report from the {role}"));
            }
        }
        let (shaping, emulator) = match emulator {
            Some(EmulatorReport { shaping, process }) => (Some(shaping), Some(process)),
            None => (None, None),
        };
        let frames = account(console.as_ref(), emulator.as_deref(), simulator.as_ref());
        let feedback = emulator
            .as_ref()
            .and_then(|e| e.path::<FeedbackExtra>("feedback"))
            .map(|f| FeedbackSection::join(&f, console.as_ref().and_then(|c| c.feedback.as_ref()), simulator.as_ref().map(|s| s.feedback_sent)));
        let video_path = emulator.as_ref().and_then(|e| e.path::<VideoExtra>("video"));
        if let Some(f) = feedback.as_ref().filter(|f| !f.balanced) {
            faults.push(format!(
                "feedback not balanced: robot sent {:?}, {} entered, {} delivered, console received {:?}",
                f.sent_by_robot, f.entered, f.delivered, f.received_by_console
            ));
        }
        let video = crate::service::video::VideoSection::join(
            video_path.as_ref(),
            console.as_ref().and_then(|c| c.video.as_ref()),
            simulator.as_ref().and_then(|s| s.camera.as_ref()),
        );
        if let Some(v) = video.as_ref().filter(|v| !v.balanced) {
            faults.push(format!("video not balanced: {:?}, dropped {:?}, held at end {}", v.frames, v.dropped, v.held_at_end));
        }
        if let Some(n) = frames.lost_before_emulator.filter(|n| *n > 0) {
            faults.push(format!("{n} frames sent by the console never entered the emulator"));
        }
        if let Some(n) = frames.lost_after_emulator.filter(|n| *n > 0) {
            faults.push(format!("{n} frames released by the emulator never reached the simulator"));
        }
        if interrupted {
            faults.push("interrupted (Ctrl-C / SIGTERM)".into());
        }
        // The trace: the emulator's rows joined with the simulator's receive times.
        let mut delays = Delays::default();
        let trace = merge_trace(out, &mut delays).unwrap_or_else(|e| {
            faults.push(format!("trace not written: {e:#}"));
            None
        });
        let e = shaping.as_ref();
        let end_to_end_extra = simulator.as_ref().map(|s| s.end_to_end_extra_ns).filter(|p| p.count > 0);
        let direct_hop = simulator.as_ref().map(|s| s.direct_hop_ns).filter(|p| p.count > 0);
        let overhead_ns = Overhead {
            ingress_wait: e.map(|e| e.link.ingress_wait_ns),
            decision: e.map(|e| e.link.decision_ns),
            release_lateness: e.map(|e| e.link.release_lateness_ns),
            added_over_direct: end_to_end_extra.as_ref().zip(direct_hop.as_ref()).map(|(a, b)| difference(a, b)),
            end_to_end_extra,
            direct_hop,
        };
        RunReport {
            provenance: None,
            delay_check: delay_check(&plan.spec, plan.seed, delays),
            run_id: plan.run_id.clone(),
            scenario: plan.spec.name.clone(),
            seed: plan.seed,
            duration_s,
            frames,
            loss_rate: e.map(|e| e.link.loss_rate),
            loss_rate_ci95: e.map(|e| e.link.loss_rate_ci95),
            stages: e.map(|e| e.link.stages.clone()).unwrap_or_default(),
            links: e.map(|e| e.link.links.clone()).unwrap_or_default(),
            injected_delay_ns: e.map(|e| e.link.injected_delay_ns),
            overhead_ns,
            kinematics: simulator.as_ref().and_then(|s| s.kinematics.clone()),
            feedback,
            video,
            processes,
            faults,
            peer_events: e.map(|e| e.peer_events.clone()).unwrap_or_default(),
            events: e.map(|e| e.events.clone()).unwrap_or_default(),
            steal,
            files: Files {
                out_dir: out.clone(),
                scenario: plan.scenario_path.clone(),
                trace,
                decision_hlog: e.and_then(|e| e.decision_hlog.clone()),
                lateness_hlog: e.and_then(|e| e.lateness_hlog.clone()),
                end_to_end_hlog: simulator.as_ref().and_then(|s| s.end_to_end_hlog.clone()),
                report_json: out.join("report.json"),
                video_trace: video_path.as_ref().map(|v| v.trace_path.clone()),
                video_received: console.as_ref().and_then(|c| c.video.as_ref()).and_then(|v| v.received_csv.clone()),
            },
            console,
            emulator,
            simulator,
            streams: None,
        }
    }
}

/// Per delivered and received frame: the injected delay and the delay the
/// simulator saw (receive − console send), in ns.
#[derive(Debug, Default)]
struct Delays {
    injected: Vec<u64>,
    seen: Vec<u64>,
}

/// The simulator's receive times (`received.csv`), by ingress index: the
/// first receipt of each index, and the further ones of indices received
/// more than once (copies, docs/spec.md §3.8), each with the release time
/// it was scheduled for, which tells a copy's receipt from its original's.
#[derive(Debug, Default)]
struct Receipts {
    /// `(recv_ns, release_sched_ns)` by ingress index; `recv_ns` 0: none.
    first: Vec<(u64, u64)>,
    more: BTreeMap<u64, Vec<(u64, u64)>>,
}

impl Receipts {
    fn read(path: &Path) -> Result<Receipts> {
        let mut r = Receipts::default();
        let Ok(f) = std::fs::File::open(path) else { return Ok(r) };
        for line in std::io::BufReader::new(f).lines().skip(1) {
            let line = line.with_context(|| format!("reading {}", path.display()))?;
            let mut it = line.split(',').map(str::parse::<u64>);
            let (Some(Ok(i)), Some(Ok(t))) = (it.next(), it.next()) else { continue };
            let sched = it.next().and_then(Result::ok).unwrap_or(0);
            let i = i as usize;
            if r.first.len() <= i {
                r.first.resize(i + 1, (0, 0));
            }
            if r.first[i].0 == 0 {
                r.first[i] = (t, sched);
            } else {
                r.more.entry(i as u64).or_default().push((t, sched));
            }
        }
        Ok(r)
    }

    /// Takes the receipt of the row of `index` scheduled for `sched`: one
    /// scheduled then (a `received.csv` without that column matches any),
    /// or else any left for that index.
    fn take(&mut self, index: usize, sched: Option<u64>) -> Option<u64> {
        let matches = |r: &(u64, u64)| r.1 == 0 || sched.is_none_or(|s| s == r.1);
        let first = *self.first.get(index).filter(|f| f.0 != 0)?;
        let more = self.more.get_mut(&(index as u64));
        if !matches(&first) {
            if let Some(m) = more {
                if let Some(k) = m.iter().position(matches) {
                    return Some(m.remove(k).0);
                }
            }
        }
        // The first receipt goes; the next one, if any, takes its place.
        let next = self.more.get_mut(&(index as u64)).and_then(|m| (!m.is_empty()).then(|| m.remove(0)));
        self.first[index] = next.unwrap_or((0, 0));
        Some(first.0)
    }
}

/// Joins `trace_emulator.csv` with `received.csv` into `trace.csv`, and
/// collects the delays of the frames that made it through.
fn merge_trace(out: &Path, delays: &mut Delays) -> Result<Option<PathBuf>> {
    let emu = out.join("trace_emulator.csv");
    if !emu.exists() {
        return Ok(None);
    }
    let mut recv = Receipts::read(&out.join("received.csv"))?;
    let path = out.join("trace.csv");
    let named = |p: &Path| format!("writing {}", p.display());
    let mut w = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&path).with_context(|| named(&path))?);
    let reading = || format!("reading {}", emu.display());
    for (n, line) in std::io::BufReader::new(std::fs::File::open(&emu).with_context(reading)?).lines().enumerate() {
        let line = line.with_context(reading)?;
        if n == 0 {
            writeln!(w, "{line}").with_context(|| named(&path))?;
            continue;
        }
        let mut cols: Vec<&str> = line.split(',').collect();
        let index: usize = cols[0].parse().unwrap_or(usize::MAX);
        // Columns: 3 send_ns, 5 fate, 9 delay_ns, 10 release_sched_ns (see `trace`).
        let sched = cols.get(10).and_then(|x| x.parse::<u64>().ok());
        let received = if cols.get(5) == Some(&"delivered") { recv.take(index, sched) } else { None };
        match received {
            Some(t) => {
                let t_text = t.to_string();
                if let Some(c) = cols.get_mut(crate::trace::RECV_COLUMN) {
                    *c = &t_text;
                }
                writeln!(w, "{}", cols.join(",")).with_context(|| named(&path))?;
                if let (Some(Ok(send)), Some(Ok(delay))) = (cols.get(3).map(|x| x.parse::<u64>()), cols.get(9).map(|x| x.parse::<u64>())) {
                    delays.injected.push(delay);
                    delays.seen.push(t.saturating_sub(send));
                }
            }
            None => writeln!(w, "{line}").with_context(|| named(&path))?,
        }
    }
    // A failed flush (a full disk) is an error too, not a cut file.
    w.flush().with_context(|| named(&path))?;
    std::fs::remove_file(&emu).with_context(|| format!("removing {}", emu.display()))?;
    Ok(Some(path))
}

/// Quantiles of the delays the simulator saw against the delays the
/// emulator drew and, when the scenario is a single `reorder` delay stage
/// (possibly behind loss stages), against the model's analytic law.
fn delay_check(spec: &scenario::ScenarioSpec, seed: u64, mut d: Delays) -> Option<DelayCheck> {
    let n = d.seen.len();
    if n < 100 || d.injected.iter().all(|x| *x == 0) {
        return None;
    }
    d.injected.sort_unstable();
    d.seen.sort_unstable();
    let model = Scenario::new(spec, seed).ok().and_then(|sc| {
        let [phase] = sc.phases() else { return None };
        let delays: Vec<_> = phase.stages().iter().filter_map(|s| match s.model() {
            crate::model::AnyModel::Delay(m) => Some(m.clone()),
            _ => None,
        }).collect();
        match delays.as_slice() {
            [one] if one.may_reorder() || one.cdf_ms(one.mean_ms_exact()) >= 0.0 => Some(one.clone()),
            _ => None,
        }
    });
    // Dvoretzky–Kiefer–Wolfowitz: with 95% confidence the empirical
    // distribution is within ε of the true one everywhere.
    let eps = ((2.0f64 / 0.05).ln() / (2.0 * n as f64)).sqrt();
    let pick = |v: &[u64], q: f64| v[((q * n as f64) as usize).min(n - 1)] as f64 / 1e6;
    let quantiles: Vec<DelayQuantile> = [0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99]
        .into_iter()
        .map(|q| {
            let (injected_ms, seen_ms) = (pick(&d.injected, q), pick(&d.seen, q));
            let model_ms = model.as_ref().map(|m| m.quantile_ms(q));
            let model_band_ms = model.as_ref().map(|m| [m.quantile_ms((q - eps).max(1e-9)), m.quantile_ms((q + eps).min(1.0 - 1e-9))]);
            DelayQuantile { q, model_ms, model_band_ms, injected_ms, seen_ms, seen_minus_injected_us: (seen_ms - injected_ms) * 1e3 }
        })
        .collect();
    let worst = quantiles.iter().map(|x| x.seen_minus_injected_us.abs()).fold(0.0, f64::max);
    let injected_within_model_band = model.as_ref().map(|_| {
        quantiles.iter().all(|x| x.model_band_ms.is_some_and(|[lo, hi]| lo <= x.injected_ms && x.injected_ms <= hi))
    });
    Some(DelayCheck { frames: n as u64, dkw_epsilon: eps, quantiles, max_abs_seen_minus_injected_us: worst, injected_within_model_band })
}
