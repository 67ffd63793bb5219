//! The `netfi` command line this package builds, for the tests that run it
//! as a process.

use std::process::Command;

/// `netfi`, as this package built it, ready for its arguments.
pub fn netfi() -> Command {
    Command::new(env!("CARGO_BIN_EXE_netfi"))
}
