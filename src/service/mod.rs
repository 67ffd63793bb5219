//! The real-time services: console, emulator and simulator loops, and the
//! runner that starts all three. Unlike the sans-IO core these read the
//! clock, pin cores and talk to transports — through the [`ports`] traits,
//! so the loops do not depend on which transport carries the frames.

pub mod args;
pub mod console;
pub mod emulator;
pub mod ipc;
pub mod ports;
pub mod report;
pub mod run;
pub mod signals;
pub mod simulator;
