//! The emulator's UDP bridge with real processes and real sockets on
//! loopback (and, where the machine allows, in network namespaces): a
//! binary of its own, like the other real-process tests, so its
//! busy-waiting emulator never competes with the CPU-heavy tiers.
//!
//! Every test that runs an emulator holds [`ONE_RUN_AT_A_TIME`]: a 2-core
//! machine has room for one pinned, busy-waiting emulator at a time.

#[path = "../common/netfi.rs"]
mod netfi_bin;
use std::sync::Mutex;

mod bridge;
mod foreign;
mod memory;
mod netns;
mod tools;

pub(crate) static ONE_RUN_AT_A_TIME: Mutex<()> = Mutex::new(());
