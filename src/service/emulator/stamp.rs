//! The release of a sample that carries its own stamps (ITP frames,
//! feedback): written once for every channel whose sink sends a copy of
//! the held sample that the release may still stamp.

use crate::sample::{FeedbackSample, FrameSample, ReleaseStamps};
use crate::transport::{FeedbackEgress, FrameSink, PortError};

/// A sink that sends a copy of a sample after a closure has had the last
/// word on it.
pub trait StampingSink<S> {
    /// Sends `sample` as `stamp` leaves it.
    fn send_stamped(&mut self, sample: &S, stamp: impl FnOnce(&mut S)) -> Result<(), PortError>;
}

impl<K: FrameSink> StampingSink<FrameSample> for K {
    #[inline]
    fn send_stamped(&mut self, sample: &FrameSample, stamp: impl FnOnce(&mut FrameSample)) -> Result<(), PortError> {
        self.send_with(sample, stamp).map(drop)
    }
}

impl StampingSink<FeedbackSample> for FeedbackEgress {
    #[inline]
    fn send_stamped(&mut self, sample: &FeedbackSample, stamp: impl FnOnce(&mut FeedbackSample)) -> Result<(), PortError> {
        self.send_with(sample, stamp).map(drop)
    }
}

/// Sends `item` onto `sink` stamped with its scheduled release time, its
/// injected delay and, read by `stamp` immediately before the send, its
/// actual release time; that time, or the time of the failure and why.
#[inline]
pub fn release_stamped<S: ReleaseStamps>(
    sink: &mut impl StampingSink<S>,
    item: &S,
    scheduled_ns: u64,
    stamp: impl FnOnce() -> u64,
) -> Result<u64, (u64, PortError)> {
    let mut release_ns = 0;
    let sent = sink.send_stamped(item, |s| {
        s.stamp_scheduled(scheduled_ns);
        release_ns = stamp();
        s.stamp_released(release_ns);
    });
    match sent {
        Ok(()) => Ok(release_ns),
        Err(e) => Err((crate::clock::now_ns(), e)),
    }
}
