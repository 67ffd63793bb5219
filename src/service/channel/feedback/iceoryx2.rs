//! The feedback channel over iceoryx2: robot → emulator → console. The
//! robot publishes one [`FeedbackSample`] per command it received (its
//! integrated pose and which command that was) on `netfi/<run>/feedback`;
//! the emulator passes each through a path of its own, shaped by the return
//! scenario (`--return-scenario`, default `Normal`), and releases survivors
//! on `netfi/<run>/feedback_out`, where the console measures the round
//! trip. The robot ends its feedback with an end marker once it has the
//! emulator's; a robot that publishes none (or is gone) does not hold the
//! run ([`Ending::AfterForward`]).

use crate::model::ModelKind;
use crate::sample::FeedbackSample;
use crate::service::emulator::path::{Channel, Ending, Reverse, Take, GRACE_NS};
use super::{FeedbackExtra, ReturnOpenError};
use crate::service::channel::declare::ChannelOpen;
use crate::service::emulator::opening::{Opening, PathPlan};
use crate::service::link::{Arrival, Carried};
use crate::service::schema::Account;
use crate::transport::{FramePublisher, FrameSink, FrameSource, FrameSubscriber, Port, PortError, Role};

/// The feedback path's name: its key in `emulator.json`'s paths.
pub const NAME: &str = "feedback";

/// Robot → emulator: the robot's feedback, one per command it received.
pub const FEEDBACK: Port = Port::new("feedback", Role::Simulator, Role::Emulator);
/// Emulator → console: the feedback that survived the return scenario.
pub const FEEDBACK_OUT: Port = Port::new("feedback_out", Role::Emulator, Role::Console);

impl Carried for FeedbackSample {
    /// A copy of feedback is a second release of the same sample; a flip
    /// needs an ITP frame's bytes, which feedback is not.
    const UNSUPPORTED: &'static [ModelKind] = &[ModelKind::Corrupt];

    #[inline]
    fn ingress_ns(&self) -> u64 {
        self.ingress_ns
    }
}

/// The feedback direction's ports: the robot's iceoryx2 ports, or any
/// source and sink of feedback samples (tests drive in-memory ones).
pub struct Feedback<S = FrameSubscriber<FeedbackSample>, K = FramePublisher<FeedbackSample>> {
    source: S,
    sink: K,
    sample: FeedbackSample,
}

impl<S: FrameSource<FeedbackSample>, K: FrameSink<FeedbackSample>> Feedback<S, K> {
    /// The feedback channel from `source` to `sink`.
    pub fn new(source: S, sink: K) -> Feedback<S, K> {
        Feedback { source, sink, sample: FeedbackSample::ZERO }
    }

    /// The two ports.
    pub fn ports_mut(&mut self) -> (&mut S, &mut K) {
        (&mut self.source, &mut self.sink)
    }
}

impl<S: FrameSource<FeedbackSample>, K: FrameSink<FeedbackSample>> Channel for Feedback<S, K> {
    type Item = FeedbackSample;
    type Extra = FeedbackExtra;
    const NAME: &'static str = NAME;
    const TRACE_FILE: &'static str = "trace_feedback.csv";
    const ENDING: Ending = Ending::AfterForward { grace_ns: GRACE_NS };

    #[inline]
    fn take(&mut self, next_ingress_index: u64, clock: &mut impl FnMut() -> u64) -> Take<FeedbackSample> {
        let s = &mut self.sample;
        match self.source.try_recv(s) {
            Ok(true) if s.is_end() => Take::End(s.robot_index),
            Ok(true) => {
                s.ingress_index = next_ingress_index;
                s.ingress_ns = clock();
                Take::Item(*s, None, Arrival { sequence: Some(s.sequence), console_index: s.robot_index, send_ns: s.send_ns })
            }
            Ok(false) => Take::Nothing,
            Err(e) => Take::Failed(e),
        }
    }

    /// Feedback is released stamped with its scheduled and actual release
    /// times and its injected delay.
    #[inline]
    fn release(&mut self, item: &FeedbackSample, scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
        crate::service::emulator::path::release_stamped!(self.sink, item, scheduled_ns, stamp)
    }

    fn send_end(&mut self, released: u64) {
        let _ = self.sink.send_with(&FeedbackSample::end_marker(released), |_| {});
    }

    fn senders(&mut self) -> Option<usize> {
        self.source.peers()
    }

    fn unsubscribed(&self) -> u64 {
        self.sink.unsubscribed()
    }

    /// Balanced also asks that every feedback sample the robot said it sent
    /// entered.
    fn finish(&mut self, account: &Account, sent: Option<u64>) -> (FeedbackExtra, bool) {
        (FeedbackExtra { sent_by_robot: sent }, sent.is_none_or(|n| n == account.entered))
    }
}

/// The feedback path of a lane with iceoryx2 on both sides, as `plan`
/// settled it.
pub fn open(plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<ReturnOpenError>> {
    let node = o.sessions.iceoryx2.as_ref().expect("the feedback path is asked for with iceoryx2 on both sides");
    let sink = node.publisher_of::<FeedbackSample>(FEEDBACK_OUT).map_err(|cause| ChannelOpen::Own(ReturnOpenError::FeedbackOut(cause)))?;
    let source = node.subscriber_of::<FeedbackSample>(FEEDBACK).map_err(|cause| ChannelOpen::Own(ReturnOpenError::FeedbackIn(cause)))?;
    Ok(Box::new(plan.open(Feedback::new(source, sink), o.expected_frames, o.out_dir)?))
}
