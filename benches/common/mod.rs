//! What the benchmark programs share: their common flags and placement
//! (`args`), the host around a measurement (`host`), percentile tables
//! (`table`), the results directory (`out`), the `netfi` binaries as
//! processes (`process`), the benchmark's own ends of a chain (`ends`), the
//! loop that drives them (`drive`) and an interval of a real emulator
//! between them (`chain`).
//!
//! A program takes it in with `#[path = "common/mod.rs"] mod common;`. The
//! modules here use one another only in that order (a module names only
//! those before it) and nothing of a program, so there is no circle; each
//! program uses a part of them. `cpu_time.rs` (the thread's CPU time, and
//! criterion's measurement by it) stands apart: the criterion benchmarks
//! take it in alone.
#![allow(dead_code)]

pub mod args;
pub mod host;
pub mod table;
pub mod out;
pub mod process;
pub mod ends;
pub mod drive;
pub mod chain;
