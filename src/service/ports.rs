//! What a service needs from a transport: a non-blocking source of frames
//! and a sink. iceoryx2 ports and (later) UDP sockets implement these, so the
//! service loops are written once.

use crate::sample::FrameSample;

/// A transport failure while receiving or sending, as text naming the port.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{port}: {message}")]
pub struct PortError {
    pub port: String,
    pub message: String,
}

/// A non-blocking frame source.
pub trait FrameSource {
    /// Copies the next waiting sample into `out`; `Ok(false)` if none waits.
    fn try_recv(&mut self, out: &mut FrameSample) -> Result<bool, PortError>;

    /// How many senders are connected now, where the transport knows
    /// (`None` otherwise). Called off the hot path.
    fn peers(&mut self) -> Option<usize> {
        None
    }

    /// The emulator dropped `sample` (any cause) and will never send it:
    /// a source that keeps payloads outside the sample frees them here.
    #[inline]
    fn dropped(&mut self, _sample: &FrameSample) {}
}

/// A frame sink.
pub trait FrameSink {
    /// Sends `sample`, after `stamp` has had the last word on it (so times
    /// can be stamped as late as possible). Returns the number of receivers
    /// it reached, where the transport knows.
    fn send_with(&mut self, sample: &FrameSample, stamp: impl FnOnce(&mut FrameSample)) -> Result<Option<usize>, PortError>;

    /// How many receivers are connected now, where the transport knows.
    fn peers(&mut self) -> Option<usize> {
        None
    }
}

/// An in-memory port pair for tests: a bounded queue.
#[derive(Debug, Default)]
pub struct MemoryPort {
    pub queue: std::collections::VecDeque<FrameSample>,
}

impl FrameSource for MemoryPort {
    fn try_recv(&mut self, out: &mut FrameSample) -> Result<bool, PortError> {
        match self.queue.pop_front() {
            Some(s) => {
                *out = s;
                Ok(true)
            }
            None => Ok(false),
        }
    }
}

impl FrameSink for MemoryPort {
    fn send_with(&mut self, sample: &FrameSample, stamp: impl FnOnce(&mut FrameSample)) -> Result<Option<usize>, PortError> {
        let mut s = *sample;
        stamp(&mut s);
        self.queue.push_back(s);
        Ok(Some(1))
    }
}
