//! netfi: a network fault injector for teleoperation.
//!
//! The sans-IO core (`frame`, `model`, `scenario`, `scheduler`, `injector`,
//! `check`, `stats`, `motion`, `kinematics`, and `fit` but for its thin
//! threading layer `fit::run`) never reads a clock or touches a socket, file
//! or thread: time is passed in as nanoseconds, so the same code runs in
//! simulated time (tests, Monte Carlo) and in the real-time emulator.
//! `transport` is the only module that touches iceoryx2; `service` holds the
//! real-time loops that wire the core to it; `load` reads scenario files for
//! the core's parser. `tests/purity/` checks that the core names no clock,
//! file, thread, socket or iceoryx2.

// Errors carry what they concern (a flag, a file, a topic, a stream) and
// are made only on the way out of a start-up or finishing step, never per
// frame: their size costs nothing that matters.
#![allow(clippy::result_large_err)]

pub mod capture;
pub mod check;
pub mod fit;
pub mod flags;
pub mod frame;
pub mod injector;
pub mod kinematics;
pub mod model;
pub mod motion;
pub mod ros2msg;
pub mod sample;
pub mod scenario;
pub mod scheduler;
pub mod stats;
pub mod video;

pub mod clock;
pub mod durable;
pub mod host;
pub mod html;
pub mod load;
pub mod metrics;
#[cfg(test)]
mod scratch;
pub mod service;
pub mod study;
pub mod trace;
pub mod transport;
pub mod ui;
