//! The reverse channels: what comes back from the robot's side, each a
//! folder declaring itself once ([`ReverseChannel`]: its flags, the path it
//! asks for on a lane and its seed's rule, how that path opens, its
//! iceoryx2 ports, its section of the run report), and listed once below.
//! The runner resolves and seeds each path the list gives, the emulator
//! opens them in its order, and the run report joins each section; none of
//! them names a channel. A new channel is a folder and a line here.
//!
//! | folder | what |
//! |---|---|
//! | `feedback` | the return path: the robot's feedback over iceoryx2, what the robot sends back over UDP |
//! | `video` | a camera's video, robot → console |
//! | `haptic` | force readings, robot → console (test builds only) |

pub mod declare;
pub mod feedback;
#[cfg(debug_assertions)]
pub mod haptic;
pub mod relay;
pub mod video;

pub use declare::{ChannelOpen, LaneShape, NoEndArgs, ReverseChannel, Sources, Want};

declare::channels! {
    /// The return path (`--return-scenario`, `--return-seed`, `--no-feedback`).
    feedback: feedback::Return,
    /// The video stream (`--video-mbps`, …).
    video: video::Video,
    /// A haptic force channel, in test builds (`--haptic`).
    [cfg(debug_assertions)] haptic: haptic::Haptic,
}
