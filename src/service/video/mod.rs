//! The video stream of a run (`netfi run --video-mbps R`): a synthetic
//! camera on the robot side (a thread of the simulator) publishes one
//! variable-size frame every period on `netfi/<run>/video`; the emulator
//! passes each through a path of its own ([`super::emulator::video`]),
//! shaped by `--video-scenario` (default `Normal`), and releases survivors
//! on `netfi/<run>/video_out`, where the console (a thread of its own)
//! measures each frame's delay, whether it arrived whole, and the freezes
//! ([`crate::video`]). Here: the flags, the camera, the receiver, and the
//! run report's section.

mod args;
mod camera;
mod receiver;
mod section;

pub use args::{VideoArgs, VideoArgsError, MAX_VIDEO_MAX_BYTES};
pub use camera::{camera, CameraReport};
pub use receiver::{receiver, ReceivedVideo, RECEIVED_CSV};
pub use section::VideoSection;

use crate::durable::DurableError;
use crate::transport::ipc::video::VideoOpenError;
use crate::transport::open::NodeError;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

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
