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
use crate::service::channel::relay::{Relay, Relayed};
use crate::service::emulator::path::Reverse;
use super::ReturnOpenError;
use crate::service::channel::declare::ChannelOpen;
use crate::service::emulator::opening::{Opening, PathPlan};
use crate::service::link::Carried;
use crate::transport::{FramePublisher, FrameSubscriber, Port, Role};

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

impl Relayed for FeedbackSample {
    const NAME: &'static str = NAME;
    const TRACE_FILE: &'static str = "trace_feedback.csv";

    fn end_marker(sent: u64) -> FeedbackSample {
        FeedbackSample::end_marker(sent)
    }

    #[inline]
    fn is_end(&self) -> bool {
        FeedbackSample::is_end(self)
    }

    #[inline]
    fn sender_index(&self) -> u64 {
        self.robot_index
    }

    #[inline]
    fn send_ns(&self) -> u64 {
        self.send_ns
    }

    #[inline]
    fn sequence(&self) -> Option<u32> {
        Some(self.sequence)
    }

    #[inline]
    fn taken(&mut self, ingress_index: u64, ingress_ns: u64) {
        self.ingress_index = ingress_index;
        self.ingress_ns = ingress_ns;
    }

    #[inline]
    fn released(&mut self, scheduled_ns: u64, release_ns: impl FnOnce() -> u64) -> u64 {
        self.release_sched_ns = scheduled_ns;
        self.injected_delay_ns = scheduled_ns - self.ingress_ns;
        self.release_ns = release_ns();
        self.release_ns
    }
}

/// The feedback direction's ports: the robot's iceoryx2 ports, or any
/// source and sink of feedback samples (tests drive in-memory ones).
pub type Feedback<S = FrameSubscriber<FeedbackSample>, K = FramePublisher<FeedbackSample>> = Relay<FeedbackSample, S, K>;

/// The feedback path of a lane with iceoryx2 on both sides, as `plan`
/// settled it.
pub fn open(plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<ReturnOpenError>> {
    let node = o.sessions.iceoryx2.as_ref().expect("the feedback path is asked for with iceoryx2 on both sides");
    let sink = node.publisher_of::<FeedbackSample>(FEEDBACK_OUT).map_err(|cause| ChannelOpen::Own(ReturnOpenError::FeedbackOut(cause)))?;
    let source = node.subscriber_of::<FeedbackSample>(FEEDBACK).map_err(|cause| ChannelOpen::Own(ReturnOpenError::FeedbackIn(cause)))?;
    Ok(Box::new(plan.open(Feedback::new(source, sink), o.expected_frames, o.out_dir)?))
}
