//! The real-time services: console, emulator and simulator loops, and the
//! runner that starts all three. Unlike the sans-IO core these read the
//! clock, pin cores and talk to transports — through the [`ports`] traits,
//! so the loops do not depend on which transport carries the frames.

pub mod emulator;
pub mod ports;
pub mod signals;
