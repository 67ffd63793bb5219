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
    fn layout_offsets_are_pinned() {
        assert_eq!(core::mem::offset_of!(FrameSample, send_ns), 0);
        assert_eq!(core::mem::offset_of!(FrameSample, len), 56);
        assert_eq!(core::mem::offset_of!(FrameSample, wire), 64);
    }
}
