//! The video stream of a run (`netfi run --video-mbps R`): a synthetic
//! camera on the robot side (a thread of the simulator) publishes one
//! variable-size frame every period on `netfi/<run>/video`; the emulator
//! passes each through a path of its own ([`path`]),
//! shaped by `--video-scenario` (default `Normal`), and releases survivors
//! on `netfi/<run>/video_out`, where the console (a thread of its own)
//! measures each frame's delay, whether it arrived whole, and the freezes
//! ([`crate::video`]). Here: the channel's declaration, its flags, the
//! emulator's path, the camera, the receiver, and the run report's
//! section.

mod args;
mod camera;
pub mod path;
mod receiver;
mod section;

pub use args::{VideoArgs, VideoArgsError, MAX_VIDEO_MAX_BYTES};
pub use path::{VideoExtra, VideoPorts};
pub use camera::{camera, CameraReport};
pub use receiver::{receiver, ReceivedVideo, RECEIVED_CSV};
pub use section::VideoSection;

use crate::durable::DurableError;
use crate::transport::ipc::video::VideoOpenError;
use crate::transport::open::NodeError;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use super::declare::{ChannelOpen, LaneShape, ReverseChannel, Sources, Want};
use crate::service::emulator::opening::{Opening, PathPlan};
use crate::service::emulator::path::Reverse;
use crate::service::schema::run::Files;
use crate::transport::ipc::video::{VIDEO, VIDEO_HELD_FRAMES, VIDEO_OUT};
use crate::transport::ipc::Iceoryx2;

/// The name of the video path: its key in `emulator.json`'s paths.
pub const NAME: &str = "video";

/// The video stream, declared.
pub struct Video;

impl ReverseChannel for Video {
    type Args = VideoArgs;
    type EndArgs = VideoArgs;

    fn end_args(args: &VideoArgs) -> VideoArgs {
        args.clone()
    }

    type ArgsError = VideoArgsError;

    /// The flags themselves; iceoryx2 on both sides (the video channels
    /// are iceoryx2's); one stream (the video path is stream 0's).
    fn check(a: &VideoArgs, lane: &LaneShape) -> Result<(), VideoArgsError> {
        a.validate()?;
        if a.on() && !lane.both::<Iceoryx2>() {
            return Err(VideoArgsError::NeedsIceoryx2);
        }
        if a.on() && lane.streams > 1 {
            return Err(VideoArgsError::OneStream { streams: lane.streams });
        }
        Ok(())
    }

    fn want(a: &VideoArgs, lane: &LaneShape) -> Option<Want> {
        (a.on() && lane.both::<Iceoryx2>()).then(|| Want {
            name: NAME,
            flag: "--video-scenario",
            scenario: a.video_scenario.clone(),
            seed: a.video_seed,
            tag: crate::service::seeds::VIDEO_TAG,
            queue_capacity: VIDEO_HELD_FRAMES - 1,
        })
    }

    fn seed(a: &mut VideoArgs) -> &mut Option<u64> {
        &mut a.video_seed
    }

    type OpenError = path::VideoPortError;

    fn open(a: &VideoArgs, _want: &Want, plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<path::VideoPortError>> {
        path::open(a, plan, o)
    }

    const PORTS: &'static [crate::transport::Port] = &[VIDEO, VIDEO_OUT];

    type Section = VideoSection;

    fn section(s: Sources) -> Option<VideoSection> {
        let e = s.emulator.and_then(|e| e.path::<VideoExtra>(NAME));
        VideoSection::join(e.as_ref(), s.console.and_then(|c| c.video.as_ref()), s.simulator.and_then(|s| s.camera.as_ref()))
    }

    fn text(s: &VideoSection) -> String {
        s.to_text()
    }

    fn faults(s: &VideoSection) -> Vec<String> {
        s.fault().into_iter().collect()
    }

    /// The emulator's video trace, and the console's record of what it
    /// received.
    fn files(_s: &VideoSection, sources: Sources, files: &mut Files) {
        let e = sources.emulator.and_then(|e| e.path::<VideoExtra>(NAME));
        files.video_trace = e.map(|v| v.trace_path);
        files.video_received = sources.console.and_then(|c| c.video.as_ref()).and_then(|v| v.received_csv.clone());
    }
}

/// Why the camera or the console's video receiver failed.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// The video flags were refused.
    #[error(transparent)]
    Args(#[from] VideoArgsError),
    /// This process's iceoryx2 node could not be opened.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// A video port could not be opened.
    #[error("opening the {direction} video port: {source}")]
    Port {
        /// Which port: `robot → emulator` or `emulator → console`.
        direction: &'static str,
        /// What iceoryx2 said.
        #[source]
        source: VideoOpenError,
    },
    /// `video_received.csv` could not be written whole.
    #[error(transparent)]
    File(#[from] DurableError),
    /// The thread could not be started.
    #[error("starting the video thread: {0}")]
    Spawn(#[source] std::io::Error),
    /// The thread panicked.
    #[error("the video thread panicked")]
    Panicked,
}

/// A thread that runs until told to stop, then hands back its report.
pub struct Worker<R> {
    stop: Arc<AtomicBool>,
    handle: std::thread::JoinHandle<Result<R, VideoError>>,
}

impl<R> Worker<R> {
    /// Tells the thread to stop and waits for its report.
    pub fn finish(self) -> Result<R, VideoError> {
        self.stop.store(true, Ordering::Relaxed);
        self.handle.join().map_err(|_| VideoError::Panicked)?
    }
}

fn spawn<R: Send + 'static>(name: &str, f: impl FnOnce(Arc<AtomicBool>) -> Result<R, VideoError> + Send + 'static) -> Result<Worker<R>, VideoError> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let handle = std::thread::Builder::new().name(name.into()).spawn(move || f(s)).map_err(VideoError::Spawn)?;
    Ok(Worker { stop, handle })
}
