//! The integration tests, one binary: a module for each area (its folder
//! under `tests/`), the helpers they share in `tests/common`. Apart from it:
//! `alloc.rs` and `udp_alloc.rs`, each a process of its own because each
//! installs a counting global allocator, and `ros2/`, a binary with its
//! own one-run-at-a-time lock.
//!
//! Tests of different modules now share a process and the machine: who
//! may run beside whom is said once, in [`common::machine`].

mod common;

mod capture_prop;
mod control;
mod export_netem;
mod fit;
mod host;
mod input_prop;
mod integration;
mod purity;
mod python;
mod release_queue;
mod report_html;
mod services;
mod statistical;
mod study;
mod transport;
mod udp;
mod ui;
