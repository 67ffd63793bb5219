//! The console service: streams ITP frames at a fixed rate (synthetic
//! bimanual motion) or replays a recorded capture with its original timing
//! or at a fixed rate, stamping each sample with its send time just before
//! publishing it.
//!
//! Pacing: sleeps until shortly before each frame's time, then polls the
//! clock, yielding the core on each turn (it shares a core with the
//! simulator on small machines). At rates above 20 kHz it never sleeps.
//! Each frame is also sent directly to the simulator (unless `--no-direct`),
//! stamped separately: the simulator measures the bare hop beside the
//! emulated one, in the same run, and integrates it as the console's pose.


mod feedback;
mod script;

pub use crate::service::error::{ScriptError, WaitError};

use crate::clock::{now_ns, wait_until_ns, Wait};
use crate::host::StealTimer;
use crate::metrics::{LatencyHistogram, Summary};
use crate::sample::{FeedbackSample, FrameSample, ITP_FRAME_LEN};
use crate::transport::FramePublisher;
use crate::service::args::ConsoleArgs;
use crate::transport::open_node;
use crate::transport::FrameSink;
use crate::service::signals;
use crate::transport::{Port, Role};
use crate::service::error::ServiceError;
use crate::service::schema::Ended;
use serde::{Deserialize, Serialize};
use feedback::FeedbackIn;
use script::Script;


/// The console's report, written as `console.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConsoleReport {
    pub frames_sent: u64,
    /// `synthetic` or `capture:<path>`.
    pub source: String,
    /// The capture replayed: its records, layout, and whether its content
    /// is verified (the fields that are not, without a content checksum).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capture: Option<crate::capture::CaptureNote>,
    /// Mean send rate achieved.
    pub rate_hz: f64,
    pub seed: u64,
    pub duration_s: f64,
    /// Actual send time − planned send time.
    pub send_lateness_ns: Summary,
    /// Frames the transport refused (e.g. the emulator's queue was full).
    pub send_errors: u64,
    /// Frames sent while no emulator was subscribed.
    pub sent_unsubscribed: u64,
    pub direct_sent: u64,
    /// `done`, `signal`, or `emulator_ended` (the emulator ended the
    /// feedback early: the robot died).
    pub ended_by: Ended,
    pub steal_ms: u64,
    pub steal_fraction: f64,
    /// The robot's feedback as it came back through the emulator.
    #[serde(default)]
    pub feedback: Option<ConsoleFeedback>,
    /// The video as it came back through the emulator, when the run has video.
    #[serde(default)]
    pub video: Option<crate::service::channel::video::ReceivedVideo>,
}

pub use crate::service::channel::feedback::ConsoleFeedback;

/// Waits for the emulator to subscribe to the console port.
fn wait_for_emulator(port: &crate::transport::FramePublisher, node: &crate::transport::IpcNode, args: &ConsoleArgs) -> Result<(), WaitError> {
    let deadline = now_ns() + (args.wait_for_peer_s * 1e9) as u64;
    while port.peers_connected() == 0 {
        if now_ns() > deadline {
            return Err(WaitError::NoEmulator { run_id: args.run_id.clone(), wait_s: args.wait_for_peer_s });
        }
        if signals::stop_requested() || node.termination_requested() {
            return Err(WaitError::Stopped);
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    Ok(())
}

/// After the last frame: takes the feedback still coming until the
/// emulator's feedback end marker, while an emulator publishes feedback, at
/// most `--feedback-wait-s`. How it ended.
fn wait_for_feedback(fb: &mut FeedbackIn, sent: u64, args: &ConsoleArgs, stop: &mut signals::StopCheck<impl FnMut() -> bool>) -> Ended {
    let deadline = now_ns() + (args.feedback_wait_s * 1e9) as u64;
    let mut turns = 0u64;
    loop {
        fb.poll(sent);
        if fb.sent_by_emulator.is_some() {
            return Ended::EndMarker;
        }
        if fb.port.peers_connected() == 0 {
            fb.poll(sent);
            return if fb.sent_by_emulator.is_some() { Ended::EndMarker } else { Ended::NoEmulator };
        }
        if now_ns() > deadline {
            return Ended::Timeout;
        }
        turns += 1;
        if turns % 1024 == 0 && stop.requested() {
            return Ended::Signal;
        }
        wait(args).relax();
    }
}

/// How this console waits between polls: yielding its core, or napping
/// (`--nap-us`, many consoles on few cores).
fn wait(args: &ConsoleArgs) -> Wait {
    args.nap_us.map_or(Wait::SpinYield, |us| Wait::Nap(us * 1000))
}

/// The console while it streams: its ports, its feedback, and its counts.
struct Streamer<'a> {
    args: &'a ConsoleArgs,
    port: FramePublisher,
    direct: Option<FramePublisher>,
    fb: FeedbackIn,
    lateness: LatencyHistogram,
    send_errors: u64,
    sent_unsubscribed: u64,
    direct_sent: u64,
    sent: u64,
}

/// How a stream went: how it ended, and when it started and ended.
struct Streamed {
    ended_by: Ended,
    t_start: u64,
    t_end: u64,
}

impl Streamer<'_> {
    /// Sends the `n` frames of `script` on time, each also straight to the
    /// simulator, polling the feedback meanwhile; ends early on a stop or
    /// when the emulator ended the feedback.
    fn stream(&mut self, script: &mut Script, n: u64, stop: &mut signals::StopCheck<impl FnMut() -> bool>) -> Streamed {
        let period_ns = match script {
            Script::Synthetic { period_ns, .. } => *period_ns,
            Script::Replay { period_ns, .. } => period_ns.unwrap_or(1e9 / 517.0),
        };
        // Sleep until this long before a frame's time, then poll: a VM's wake-up
        // latency is tens of µs; at ≥ 20 kHz there is no time to sleep at all.
        // A napping console sleeps up to the frame's time itself.
        let slack_ns = if period_ns < 50_000.0 { u64::MAX / 4 } else if self.args.nap_us.is_some() { 0 } else { 200_000 };
        let wait = wait(self.args);
        let t_start = now_ns() + 1_000_000;
        let mut ended_by = Ended::Done;
        let mut sample = FrameSample::ZERO;
        sample.len = ITP_FRAME_LEN as u32;
        let mut next_live = 0u64;
        for i in 0..n {
            let (offset_ns, wire) = script.frame(i);
            let target = t_start + offset_ns;
            if target > now_ns() + slack_ns && stop.requested() {
                // Only a console about to sleep checks for a stop: often enough.
                ended_by = Ended::Signal;
                break;
            }
            if self.fb.port.peers_connected() > 0 {
                // Feedback flows: poll it while waiting, so each round trip is
                // taken when the feedback arrives, not at the next frame.
                while now_ns() < target {
                    self.fb.poll(self.sent);
                    wait.relax();
                }
            } else {
                wait_until_ns(target, slack_ns, wait);
            }
            sample.wire = wire;
            sample.console_index = i;
            let send_ns = self.send(&sample);
            self.fb.sent(i, send_ns, &wire);
            self.fb.poll(self.sent);
            if self.args.live && send_ns >= next_live {
                eprintln!("{}", self.fb.live_line());
                next_live = send_ns + 1_000_000_000;
            }
            self.lateness.record(send_ns.saturating_sub(target));
            if let Some(d) = self.direct.as_mut() {
                if FrameSink::send_with(d, &sample, |s| s.send_ns = now_ns()).is_ok() {
                    self.direct_sent += 1;
                }
            }
            if self.fb.sent_by_emulator.is_some() {
                // The emulator ended the feedback early: its robot is gone.
                // Stop, so the stream ends with an end marker it will take.
                ended_by = Ended::EmulatorEnded;
                break;
            }
            if i % 1024 == 1023 && stop.requested() {
                ended_by = Ended::Signal;
                break;
            }
        }
        Streamed { ended_by, t_start, t_end: now_ns() }
    }

    /// Sends `sample` to the emulator, stamped as it goes; returns its send time.
    #[inline]
    fn send(&mut self, sample: &FrameSample) -> u64 {
        let mut send_ns = 0;
        match FrameSink::send_with(&mut self.port, sample, |s| {
            send_ns = now_ns();
            s.send_ns = send_ns;
        }) {
            Ok(Some(0)) => self.sent_unsubscribed += 1,
            Ok(_) => {}
            Err(_) => self.send_errors += 1,
        }
        self.sent += 1;
        send_ns
    }

    /// Ends the stream on both ports with the end marker.
    fn end(&mut self) {
        let end = FrameSample::end_marker(self.sent);
        let _ = FrameSink::send_with(&mut self.port, &end, |_| {});
        if let Some(d) = self.direct.as_mut() {
            let _ = FrameSink::send_with(d, &end, |_| {});
        }
    }

    /// The console's report.
    fn report(&self, source: String, seed: u64, s: &Streamed, fb_ended: Ended, steal: crate::host::Steal) -> ConsoleReport {
        let duration_s = (s.t_end.saturating_sub(s.t_start)) as f64 / 1e9;
        ConsoleReport {
            frames_sent: self.sent,
            source,
            capture: None,
            rate_hz: if duration_s > 0.0 { self.sent as f64 / duration_s } else { 0.0 },
            seed,
            duration_s,
            send_lateness_ns: self.lateness.summary(),
            send_errors: self.send_errors,
            sent_unsubscribed: self.sent_unsubscribed,
            direct_sent: self.direct_sent,
            ended_by: s.ended_by,
            steal_ms: steal.ms,
            steal_fraction: steal.fraction,
            feedback: Some(self.fb.report(fb_ended, &self.args.out, duration_s)),
            video: None,
        }
    }
}

/// Runs the console with `args`; returns its report (also `console.json`).
pub fn main(args: &ConsoleArgs) -> Result<ConsoleReport, ServiceError> {
    args.source.planned()?;
    let seed = crate::service::seeds::given_or_fresh(args.seed);
    let (mut script, capture) = Script::from_args(args, seed)?;
    let n = script.len(args.source.frames, args.source.duration_s);
    crate::service::write_pid(&args.out, "console")?;
    let node = open_node(&args.run_id, Role::Console)?;
    let port = node.publisher(Port::CONSOLE).map_err(|e| ServiceError::Publisher("console → emulator", e))?;
    let direct = if args.no_direct { None } else { Some(node.publisher(Port::DIRECT).map_err(|e| ServiceError::Publisher("console → simulator", e))?) };
    let fb_port = node.subscriber_of::<FeedbackSample>(crate::service::channel::feedback::FEEDBACK_OUT).map_err(|e| ServiceError::Subscriber("emulator → console feedback", e))?;
    let fb = FeedbackIn::new(fb_port)?;
    signals::install();
    crate::host::placement::place("console", args.pin.core, args.pin.avoid_core)?;
    // After the placement, whose CPU mask its thread inherits: off the emulator's core.
    let video = crate::service::channel::video::receiver(&args.run_id, &args.channels.video, &args.out, 2.0 * crate::service::emulator::path::GRACE_NS as f64 / 1e9)?;
    // Wait for the emulator to subscribe, so the first frames are not lost.
    wait_for_emulator(&port, &node, args)?;
    let source = match &args.source.capture {
        Some(p) => format!("capture:{}", p.display()),
        None => "synthetic".into(),
    };
    eprintln!("console: {n} frames from {source}, seed {seed}");
    // `netfi run` names a console that never gets here.
    crate::durable::write_whole(&args.out.join("console.ready"), b"").map_err(|e| ServiceError::Ready("console.ready", std::io::Error::other(e)))?;
    let mut s = Streamer { args, port, direct, fb, lateness: LatencyHistogram::new(), send_errors: 0, sent_unsubscribed: 0, direct_sent: 0, sent: 0 };
    let steal_timer = StealTimer::start();
    let mut stop = signals::StopCheck::new(64, || node.termination_requested());
    let streamed = s.stream(&mut script, n, &mut stop);
    s.end();
    let fb_ended = wait_for_feedback(&mut s.fb, s.sent, args, &mut stop);
    let video = video.map(|v| v.finish()).transpose()?;
    let report = ConsoleReport { video, capture, ..s.report(source, seed, &streamed, fb_ended, steal_timer.stop()) };
    if args.live || s.fb.received > 0 {
        eprintln!("{}", s.fb.live_line());
    }
    crate::service::write_json(&args.out.join("console.json"), &report)?;
    Ok(report)
}
