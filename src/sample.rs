//! The fixed-size shared-memory sample that carries one ITP frame between the
//! console, the emulator and the simulator on one host (docs/spec.md §2),
//! and the bridge between it and the ITP codec of [`crate::frame`], which
//! knows nothing of shared memory.
//!
//! Layout is `#[repr(C)]`, pinned by a compile-time size assertion, and
//! published under a stable iceoryx2 type name: bump the `.vN` suffix of
//! [`FrameSample::TYPE_NAME`] whenever the layout changes, so processes built
//! from different layouts refuse to connect instead of misreading each other.

use crate::frame::{FrameError, ItpFrame, ItpView};
pub use crate::frame::ITP_FRAME_LEN;
use iceoryx2::prelude::ZeroCopySend;

/// A fixed-size sample a port carries: `#[repr(C)]`, shareable as it is,
/// with a stable type name (peers refuse a port of another) and an all-zero
/// value to loan with. A channel that carries a sample of its own
/// implements this beside it.
pub trait Payload: ZeroCopySend + Copy + core::fmt::Debug + 'static {
    /// An all-zero sample.
    const ZERO: Self;
    /// The type name peers must agree on.
    const TYPE_NAME: &'static str;
}

impl Payload for FrameSample {
    const ZERO: Self = FrameSample::ZERO;
    const TYPE_NAME: &'static str = FrameSample::TYPE_NAME;
}

impl Payload for FeedbackSample {
    const ZERO: Self = FeedbackSample::ZERO;
    const TYPE_NAME: &'static str = FeedbackSample::TYPE_NAME;
}

/// One frame in shared memory: the 124 wire bytes plus the metadata the
/// injector and the simulator need. All times are CLOCK_MONOTONIC ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("netfi::FrameSample.v1")]
#[repr(C)]
pub struct FrameSample {
    /// Console send time, stamped just before publishing.
    pub send_ns: u64,
    /// The console's own send counter for this run (0, 1, 2, ...); gaps tell
    /// the emulator that frames were lost before they reached it.
    pub console_index: u64,
    /// Assigned by the emulator when the frame enters it (0, 1, 2, ...).
    pub ingress_index: u64,
    /// Time the emulator took the frame off the console port.
    pub ingress_ns: u64,
    /// Delay the scenario injected (scheduled release − ingress).
    pub injected_delay_ns: u64,
    /// Scheduled release time (ingress + injected delay).
    pub release_sched_ns: u64,
    /// Actual release time, stamped just before publishing to the simulator.
    pub release_ns: u64,
    /// Number of valid bytes in `wire` (124 for ITP).
    pub len: u32,
    /// Control bits: [`FrameSample::FLAG_END`]; zero for frames.
    pub flags: u32,
    /// The ITP frame as it travels on the wire (little-endian, packed).
    pub wire: [u8; ITP_FRAME_LEN],
    /// Keeps the size a multiple of 8 explicitly, so nothing is implicit.
    pub _pad: [u8; 4],
}

const _: () = assert!(core::mem::size_of::<FrameSample>() == 192);
const _: () = assert!(core::mem::align_of::<FrameSample>() == 8);

impl FrameSample {
    /// The iceoryx2 type name; must match between all processes.
    pub const TYPE_NAME: &'static str = "netfi::FrameSample.v1";

    /// The sample carries an opaque datagram kept elsewhere (the UDP bridge's
    /// raw mode): no ITP validation applies to it.
    pub const FLAG_RAW: u32 = 2;

    /// Control sample marking the end of a stream: not a frame. Its
    /// `console_index` carries the number of frames sent before it.
    pub const FLAG_END: u32 = 1;

    /// An end-of-stream marker after `frames_sent` frames.
    pub fn end_marker(frames_sent: u64) -> FrameSample {
        FrameSample { console_index: frames_sent, flags: FrameSample::FLAG_END, ..FrameSample::ZERO }
    }

    /// Whether this sample stands for an opaque datagram (raw mode).
    pub fn is_raw(&self) -> bool {
        self.flags & FrameSample::FLAG_RAW != 0
    }

    /// Whether this sample is an end-of-stream marker rather than a frame.
    pub fn is_end(&self) -> bool {
        self.flags & FrameSample::FLAG_END != 0
    }

    /// An all-zero sample (a valid initial value for loaned shared memory).
    pub const ZERO: FrameSample = FrameSample {
        send_ns: 0,
        console_index: 0,
        ingress_index: 0,
        ingress_ns: 0,
        injected_delay_ns: 0,
        release_sched_ns: 0,
        release_ns: 0,
        len: 0,
        flags: 0,
        wire: [0; ITP_FRAME_LEN],
        _pad: [0; 4],
    };

    /// The valid wire bytes.
    pub fn payload(&self) -> &[u8] {
        &self.wire[..(self.len as usize).min(ITP_FRAME_LEN)]
    }
}

/// The robot's feedback to the console, one per command it applied: its
/// integrated pose then, which command that was, and the emulator's stamps
/// of the way back (docs/interface.md). All times are CLOCK_MONOTONIC ns.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("netfi::FeedbackSample.v1")]
#[repr(C)]
pub struct FeedbackSample {
    /// Robot send time, stamped just before publishing.
    pub send_ns: u64,
    /// The robot's own feedback counter (0, 1, 2, ...); in an end marker,
    /// the number of feedback samples sent before it.
    pub robot_index: u64,
    /// `console_index` of the command this feedback answers (the last one
    /// the robot received).
    pub console_index: u64,
    /// That command's console send time, echoed.
    pub command_send_ns: u64,
    /// That command's emulator stamps, echoed: taken in, released, and the
    /// delay the forward scenario injected (zero when it came directly).
    pub command_ingress_ns: u64,
    pub command_release_ns: u64,
    pub command_injected_delay_ns: u64,
    /// Assigned by the emulator when the feedback enters it.
    pub ingress_index: u64,
    /// Time the emulator took the feedback off the robot's port.
    pub ingress_ns: u64,
    /// Delay the return scenario injected.
    pub injected_delay_ns: u64,
    /// Scheduled release time towards the console.
    pub release_sched_ns: u64,
    /// Actual release time, stamped just before publishing to the console.
    pub release_ns: u64,
    /// ITP `sequence` of the command this feedback answers.
    pub sequence: u32,
    /// Control bits: [`FeedbackSample::FLAG_END`]; zero for feedback.
    pub flags: u32,
    /// Integrated position per arm, x, y, z (ITP position units).
    pub position: [[i64; 3]; 2],
    /// Integrated rotation per arm, x, y, z (sum of the ITP rotation increments).
    pub rotation: [[f64; 3]; 2],
    /// Grasp per arm (absolute, the last command's).
    pub grasp: [i32; 2],
    /// Commands the robot has received so far (this one included).
    pub commands: u64,
}

const _: () = assert!(core::mem::size_of::<FeedbackSample>() == 216);
const _: () = assert!(core::mem::align_of::<FeedbackSample>() == 8);

impl FeedbackSample {
    /// The iceoryx2 type name; must match between all processes.
    pub const TYPE_NAME: &'static str = "netfi::FeedbackSample.v1";

    /// Control sample marking the end of the feedback stream. Its
    /// `robot_index` carries the number of feedback samples sent before it.
    pub const FLAG_END: u32 = 1;

    /// An all-zero sample.
    pub const ZERO: FeedbackSample = FeedbackSample {
        send_ns: 0,
        robot_index: 0,
        console_index: 0,
        command_send_ns: 0,
        command_ingress_ns: 0,
        command_release_ns: 0,
        command_injected_delay_ns: 0,
        ingress_index: 0,
        ingress_ns: 0,
        injected_delay_ns: 0,
        release_sched_ns: 0,
        release_ns: 0,
        sequence: 0,
        flags: 0,
        position: [[0; 3]; 2],
        rotation: [[0.0; 3]; 2],
        grasp: [0; 2],
        commands: 0,
    };

    /// An end-of-stream marker after `sent` feedback samples.
    pub fn end_marker(sent: u64) -> FeedbackSample {
        FeedbackSample { robot_index: sent, flags: FeedbackSample::FLAG_END, ..FeedbackSample::ZERO }
    }

    /// Whether this sample is an end-of-stream marker rather than feedback.
    pub fn is_end(&self) -> bool {
        self.flags & FeedbackSample::FLAG_END != 0
    }
}

impl Default for FeedbackSample {
    fn default() -> Self {
        FeedbackSample::ZERO
    }
}


impl ItpFrame {
    /// Writes the frame into a shared-memory sample's wire bytes and sets its
    /// length; the sample's metadata is left alone.
    pub fn write_to_sample(&self, sample: &mut FrameSample) {
        self.emit(&mut ItpView::new_unchecked(&mut sample.wire[..]));
        sample.len = ITP_FRAME_LEN as u32;
    }

    /// Parses the frame a shared-memory sample carries, verifying its length
    /// and checksum.
    pub fn from_sample(sample: &FrameSample) -> Result<ItpFrame, FrameError> {
        ItpFrame::parse(&sample_view(sample)?)
    }
}

/// A checked view of the frame a shared-memory sample carries; fails if the
/// sample's `len` is not one frame.
pub fn sample_view(sample: &FrameSample) -> Result<ItpView<&[u8]>, FrameError> {
    ItpView::new_checked(sample.payload())
}

impl Default for FrameSample {
    fn default() -> Self {
        FrameSample::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use iceoryx2::prelude::ZeroCopySend;

    #[test]
    fn type_name_is_stable() {
        // SAFETY: type_name only returns the attribute's string.
        assert_eq!(unsafe { FrameSample::type_name() }, FrameSample::TYPE_NAME);
    }

    #[test]
    fn sample_round_trip() {
        let f = ItpFrame { sequence: 20468, delx: [-39, 13], surgeon_mode: 1, ..ItpFrame::default() }.with_checksum();
        let mut s = FrameSample { send_ns: 42, ..FrameSample::ZERO };
        f.write_to_sample(&mut s);
        assert_eq!(s.len, 124);
        assert_eq!(s.send_ns, 42);
        assert_eq!(ItpFrame::from_sample(&s), Ok(f));
        s.len = 100;
        assert_eq!(ItpFrame::from_sample(&s), Err(FrameError::WrongLength { expected: 124, found: 100 }));
    }

    #[test]
    fn feedback_type_name_and_offsets_are_pinned() {
        // SAFETY: type_name only returns the attribute's string.
        assert_eq!(unsafe { FeedbackSample::type_name() }, FeedbackSample::TYPE_NAME);
        assert_eq!(core::mem::offset_of!(FeedbackSample, command_injected_delay_ns), 48);
        assert_eq!(core::mem::offset_of!(FeedbackSample, ingress_index), 56);
        assert_eq!(core::mem::offset_of!(FeedbackSample, release_ns), 88);
        assert_eq!(core::mem::offset_of!(FeedbackSample, sequence), 96);
        assert_eq!(core::mem::offset_of!(FeedbackSample, position), 104);
        assert_eq!(core::mem::offset_of!(FeedbackSample, rotation), 152);
        assert_eq!(core::mem::offset_of!(FeedbackSample, grasp), 200);
        assert_eq!(core::mem::offset_of!(FeedbackSample, commands), 208);
    }

    #[test]
    fn layout_offsets_are_pinned() {
        assert_eq!(core::mem::offset_of!(FrameSample, send_ns), 0);
        assert_eq!(core::mem::offset_of!(FrameSample, len), 56);
        assert_eq!(core::mem::offset_of!(FrameSample, wire), 64);
    }
}
