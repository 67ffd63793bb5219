//! The return path: what the robot sends back to the console, through a
//! scenario of its own (`--return-scenario`, default Normal: nothing
//! injected). Its flags are one group whatever the transport; the path is
//! the transport's: with iceoryx2 on both sides, the robot's feedback
//! samples (`iceoryx2`, the path `feedback`); with UDP on both sides, what
//! the robot sends to the emulator's egress socket, relayed out of its
//! ingress socket (`udp`, the path `return`). ROS 2 lanes carry theirs on a
//! return topic of their own (`--ros2-return`), with these flags too. The
//! run report's feedback section joins the iceoryx2 path with the console's
//! view of it (`section`).

pub mod iceoryx2;
pub mod section;
pub mod udp;

pub use iceoryx2::{Feedback, FEEDBACK, FEEDBACK_OUT};
pub use section::{ConsoleFeedback, FeedbackExtra, FeedbackSection, ReturnExtra};
pub use udp::UdpReturn;

use super::declare::{ChannelOpen, LaneShape, NoEndArgs, ReverseChannel, Sources, Want};
use crate::flags::{Argv, Render};
use crate::service::emulator::opening::{Opening, PathPlan};
use crate::service::emulator::path::Reverse;
use crate::service::seeds;
use crate::transport::ipc::Iceoryx2;
use crate::transport::udp::Udp;
use clap::Args;

/// What comes back from the robot: `netfi run` and `netfi emulator`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Args)]
pub struct ReturnArgs {
    /// Pass the robot's feedback back to the console through this scenario
    /// (file or preset; default Normal: nothing injected).
    #[arg(long, value_name = "SCENARIO")]
    pub return_scenario: Option<String>,
    /// Seed of the return scenario (default: the file's, else derived from
    /// the run's seed; printed).
    #[arg(long)]
    pub return_seed: Option<u64>,
    /// No feedback path: the robot's feedback is not carried back to the
    /// console (iceoryx2 on both sides).
    #[arg(long, conflicts_with_all = ["return_scenario", "return_seed"])]
    pub no_feedback: bool,
}

impl Render for ReturnArgs {
    fn render(&self, a: &mut Argv) {
        a.opt("--return-scenario", self.return_scenario.as_ref()).opt("--return-seed", self.return_seed).switch("--no-feedback", self.no_feedback);
    }
}

/// The return path's flags that do not fit the lane.
#[derive(Debug, thiserror::Error)]
pub enum ReturnArgsError {
    /// `--no-feedback` with a scenario or seed for the feedback.
    #[error("--no-feedback cannot be combined with --return-scenario or --return-seed")]
    NoFeedbackWithReturn,
    /// `--no-feedback` over UDP.
    #[error("--no-feedback applies to the iceoryx2 feedback loop (iceoryx2 on both sides)")]
    NoFeedbackNeedsIceoryx2,
    /// Return options with one UDP side.
    #[error("--return-scenario, --return-to and --return-seed apply to the return path, which needs UDP on both sides (or iceoryx2 on both, for the feedback loop)")]
    ReturnNeedsBothSides,
    /// `--no-return` with return options.
    #[error("--no-return cannot be combined with --return-scenario, --return-to or --return-seed")]
    NoReturnWithReturn,
}

/// Why the return path's ports could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum ReturnOpenError {
    #[error("opening the emulator → console feedback port: {0}")]
    FeedbackOut(#[source] crate::transport::PublisherOpenError),
    #[error("opening the robot → emulator feedback port: {0}")]
    FeedbackIn(#[source] crate::transport::SubscriberOpenError),
    #[error("opening the return path")]
    ReturnPort(#[source] crate::transport::udp::UdpOpenError),
}

/// The return path, declared.
pub struct Return;

impl ReverseChannel for Return {
    type Args = ReturnArgs;
    type EndArgs = NoEndArgs;

    fn end_args(_args: &ReturnArgs) -> NoEndArgs {
        NoEndArgs {}
    }

    type ArgsError = ReturnArgsError;

    /// The feedback loop needs iceoryx2 on both sides, the UDP return path
    /// UDP on both.
    fn check(a: &ReturnArgs, lane: &LaneShape) -> Result<(), ReturnArgsError> {
        let given = a.return_scenario.is_some() || a.return_seed.is_some();
        if lane.both::<Iceoryx2>() {
            return match a.no_feedback && given {
                true => Err(ReturnArgsError::NoFeedbackWithReturn),
                false => Ok(()),
            };
        }
        if a.no_feedback {
            return Err(ReturnArgsError::NoFeedbackNeedsIceoryx2);
        }
        if given && !lane.both::<Udp>() {
            return Err(ReturnArgsError::ReturnNeedsBothSides);
        }
        if given && lane.transports.udp.no_return {
            return Err(ReturnArgsError::NoReturnWithReturn);
        }
        Ok(())
    }

    fn want(a: &ReturnArgs, lane: &LaneShape) -> Option<Want> {
        let want = |name, tag, queue_capacity| Want {
            name,
            flag: "--return-scenario",
            scenario: a.return_scenario.clone(),
            seed: a.return_seed,
            tag,
            queue_capacity,
        };
        if lane.both::<Iceoryx2>() && !a.no_feedback {
            return Some(want(iceoryx2::NAME, seeds::FEEDBACK_TAG, crate::service::link::DEFAULT_QUEUE_CAPACITY));
        }
        if lane.both::<Udp>() && !lane.transports.udp.no_return {
            return Some(want(crate::transport::udp::RETURN_PATH, seeds::RETURN_TAG, crate::transport::udp::RAW_DEFAULT_QUEUE_CAPACITY));
        }
        None
    }

    fn seed(a: &mut ReturnArgs) -> &mut Option<u64> {
        &mut a.return_seed
    }

    type OpenError = ReturnOpenError;

    fn open(a: &ReturnArgs, want: &Want, plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<ReturnOpenError>> {
        match want.name {
            iceoryx2::NAME => iceoryx2::open(plan, o),
            _ => udp::open(a, plan, o),
        }
    }

    const PORTS: &'static [crate::transport::Port] = &[FEEDBACK, FEEDBACK_OUT];

    type Section = FeedbackSection;

    fn section(s: Sources) -> Option<FeedbackSection> {
        section::join(s)
    }

    fn text(s: &FeedbackSection) -> String {
        s.to_text()
    }

    fn faults(s: &FeedbackSection) -> Vec<String> {
        s.faults()
    }
}
