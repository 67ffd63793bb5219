//! The `netfi` command line this package builds, for the tests that run it
//! as a process.

use std::process::Command;

/// The path of `netfi` as this package built it.
pub fn netfi_exe() -> &'static str {
    env!("CARGO_BIN_EXE_netfi")
}

/// `netfi`, as this package built it, ready for its arguments.
pub fn netfi() -> Command {
    Command::new(netfi_exe())
}
