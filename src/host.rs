//! The host room: what netfi does to and learns from the machine it runs
//! on, and how it leaves it as it was. Not part of the sans-IO core.
//!
//! | module | what |
//! |---|---|
//! | `affinity` | CPU sets, pinning, keeping a thread off a core (a leaf) |
//! | `cpu_time` | CPU and steal time from `/proc/stat` (a leaf) |
//! | `process` | a process by pid and start time; dying with the parent; ending a run's processes (a leaf) |
//! | `private_dir` | a private directory of the user's that nobody can take first (a leaf) |
//! | `changes` | what clearing a core changed, and undoing it |
//! | `record` | the host-wide records of cleared cores and of runs' processes |
//! | `guardian` | the process that acts on a record when its owners are gone; [`guardian::RunGuard`] |
//! | `isolate` | clearing a core for the run |
//! | `placement` | where a service or the emulator's loop runs: pin, keep off, clear, SCHED_FIFO |
//!
//! Each imports only the ones above it in this table.

pub mod affinity;
pub mod changes;
pub mod cpu_time;
pub mod guardian;
pub mod isolate;
pub mod placement;
pub mod private_dir;
pub mod process;
pub mod record;

pub use affinity::{allowed_cores, cores_except, keep_thread_off_core};
pub use cpu_time::{CpuTimes, Steal, StealTimer};
