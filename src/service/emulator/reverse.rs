//! The reverse paths a lane may have, and what opening one needs. Each
//! reverse channel is a file of its own with an `open` that returns its
//! path when the stream's arguments and transports call for it; a lane
//! opens every one in [`OPENERS`], in the order it polls them. A new
//! channel is one file and one line here.

pub use crate::service::emulator::opening::{OpenError, Opening, PathPlan};
use crate::service::emulator::path::Reverse;

/// Opens a reverse path if the stream calls for it.
pub type Opener = fn(&Opening) -> Result<Option<Box<dyn Reverse>>, OpenError>;

/// Every reverse channel, in the order a lane polls them.
pub const OPENERS: &[Opener] = &[super::feedback::open, super::video::open, super::udp_return::open];

/// Opens every reverse path `o` calls for.
pub fn open_all(o: &Opening) -> Result<Vec<Box<dyn Reverse>>, OpenError> {
    OPENERS.iter().filter_map(|open| open(o).transpose()).collect()
}
