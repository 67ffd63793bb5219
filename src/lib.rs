//! netfi: a network fault injector for teleoperation.
//!
//! The sans-IO core (`frame`, `model`, `scenario`, `scheduler`, `injector`,
//! `check`) never reads a clock or touches a socket, file or thread: time is
//! passed in as nanoseconds, so the same code runs in simulated time (tests,
//! Monte Carlo) and in the real-time emulator.

pub mod model;
pub mod capture;
pub mod frame;
pub mod sample;
pub mod transport;
