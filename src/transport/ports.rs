//! What a service needs from a transport: a non-blocking source of samples
//! and a sink, generic over the sample (ITP frames by default; a reverse
//! channel's own sample, such as the robot's feedback). The iceoryx2 ports
//! (here), the UDP source and sink ([`super::udp::frames`]) and the
//! in-memory [`MemoryPort`] implement them, so the service loops are
//! written once.

use crate::sample::FrameSample;
use crate::transport::ipc::IpcPayload;
use crate::transport::{FramePublisher, FrameSendError, FrameSubscriber};
use std::net::SocketAddr;

/// A transport failure while receiving or sending, as text naming the port.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{port}: {message}")]
pub struct PortError {
    /// The port, as a person names it (`udp://…`, `netfi/<run>/<channel>`).
    pub port: String,
    /// What went wrong.
    pub message: String,
}

/// A non-blocking source of samples of type `T`.
pub trait FrameSource<T = FrameSample> {
    /// Copies the next waiting sample into `out`; `Ok(false)` if none waits.
    fn try_recv(&mut self, out: &mut T) -> Result<bool, PortError>;

    /// How many senders are connected now, where the transport knows
    /// (`None` otherwise). Called off the hot path.
    fn peers(&mut self) -> Option<usize> {
        None
    }

    /// The emulator dropped `sample` (any cause) and will never send it:
    /// a source that keeps payloads outside the sample frees them here.
    #[inline]
    fn dropped(&mut self, _sample: &T) {}

    /// The address the latest sample came from, where the transport has
    /// addresses: where a reply to the sender goes.
    #[inline]
    fn sender(&self) -> Option<SocketAddr> {
        None
    }

    /// Who sends on this source now, as people name them, where the
    /// transport knows: for reports of bad input. Off the hot path.
    fn senders(&mut self) -> Vec<String> {
        Vec::new()
    }
}

/// A sink of samples of type `T`.
pub trait FrameSink<T = FrameSample> {
    /// Sends `sample`, after `stamp` has had the last word on it (so times
    /// can be stamped as late as possible). Returns the number of receivers
    /// it reached, where the transport knows.
    fn send_with(&mut self, sample: &T, stamp: impl FnOnce(&mut T)) -> Result<Option<usize>, PortError>;

    /// How many receivers are connected now, where the transport knows.
    fn peers(&mut self) -> Option<usize> {
        None
    }

    /// Samples sent while no receiver was connected (they went nowhere),
    /// where the transport knows; 0 otherwise.
    fn unsubscribed(&self) -> u64 {
        0
    }
}

/// An in-memory port for tests: a queue that is a source at its front and
/// a sink at its back. Reserve its capacity up front and it allocates
/// nothing per sample.
#[derive(Debug)]
pub struct MemoryPort<T = FrameSample> {
    /// The samples waiting, oldest first.
    pub queue: std::collections::VecDeque<T>,
}

impl<T> Default for MemoryPort<T> {
    fn default() -> Self {
        MemoryPort { queue: std::collections::VecDeque::new() }
    }
}

impl<T> MemoryPort<T> {
    /// An empty port with room for `samples` without growing.
    pub fn with_capacity(samples: usize) -> MemoryPort<T> {
        MemoryPort { queue: std::collections::VecDeque::with_capacity(samples) }
    }
}

impl<T: Copy> FrameSource<T> for MemoryPort<T> {
    fn try_recv(&mut self, out: &mut T) -> Result<bool, PortError> {
        match self.queue.pop_front() {
            Some(s) => {
                *out = s;
                Ok(true)
            }
            None => Ok(false),
        }
    }
}

impl<T: Copy> FrameSink<T> for MemoryPort<T> {
    fn send_with(&mut self, sample: &T, stamp: impl FnOnce(&mut T)) -> Result<Option<usize>, PortError> {
        let mut s = *sample;
        stamp(&mut s);
        self.queue.push_back(s);
        Ok(Some(1))
    }
}

impl<T: IpcPayload> FrameSource<T> for FrameSubscriber<T> {
    fn senders(&mut self) -> Vec<String> {
        self.publishers()
    }

    #[inline]
    fn try_recv(&mut self, out: &mut T) -> Result<bool, PortError> {
        match FrameSubscriber::try_recv(self) {
            Ok(Some(s)) => {
                *out = s;
                Ok(true)
            }
            Ok(None) => Ok(false),
            Err(e) => Err(PortError { port: self.run_id().resource_name(self.channel()), message: e.to_string() }),
        }
    }

    fn peers(&mut self) -> Option<usize> {
        Some(self.peers_connected())
    }
}

impl<T: IpcPayload> FrameSink<T> for FramePublisher<T> {
    #[inline]
    fn send_with(&mut self, sample: &T, stamp: impl FnOnce(&mut T)) -> Result<Option<usize>, PortError> {
        FramePublisher::send_from(self, sample, stamp)
            .map(Some)
            .map_err(|e: FrameSendError| PortError { port: self.run_id().resource_name(self.channel()), message: e.to_string() })
    }

    fn peers(&mut self) -> Option<usize> {
        Some(self.peers_connected())
    }

    fn unsubscribed(&self) -> u64 {
        self.stats().unsubscribed
    }
}
