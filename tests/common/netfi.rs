//! The `netfi` command line this package builds, for the tests that run it
//! as a process.

use std::process::{Command, Output};

/// The path of `netfi` as this package built it.
pub fn netfi_exe() -> &'static str {
    env!("CARGO_BIN_EXE_netfi")
}

/// `netfi`, as this package built it, ready for its arguments.
pub fn netfi() -> Command {
    Command::new(netfi_exe())
}

/// A command run to its end, as the test expects it to end (else the test
/// fails, saying how it did).
pub trait Outcome {
    /// It succeeds: its output.
    fn ok(&mut self) -> Output;
    /// It succeeds: its standard output, as JSON.
    fn json(&mut self) -> serde_json::Value;
    /// It fails: its standard error.
    fn fails(&mut self) -> String;
}

impl Outcome for Command {
    #[track_caller]
    fn ok(&mut self) -> Output {
        let o = self.output().unwrap_or_else(|e| panic!("{self:?}: {e}"));
        assert!(o.status.success(), "{self:?} failed ({}): {}", o.status, String::from_utf8_lossy(&o.stderr));
        o
    }

    #[track_caller]
    fn json(&mut self) -> serde_json::Value {
        let o = self.ok();
        serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{self:?}: not JSON ({e}): {}", String::from_utf8_lossy(&o.stdout)))
    }

    #[track_caller]
    fn fails(&mut self) -> String {
        let o = self.output().unwrap_or_else(|e| panic!("{self:?}: {e}"));
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!o.status.success(), "{self:?} succeeded; it should have failed: {stderr}");
        stderr
    }
}
