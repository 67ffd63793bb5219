//! The emulator's UDP bridge with real processes and real sockets on
//! loopback (and, where the machine allows, in network namespaces).
//!
//! Every test that runs an emulator holds [`crate::common::machine::alone`]:
//! a 2-core machine has room for one pinned, busy-waiting emulator at a
//! time, and it must not compete with the CPU-heavy tiers.

mod bridge;
mod foreign;
mod memory;
mod netns;
mod tools;
