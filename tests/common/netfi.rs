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

/// `netfi ui --port 0 --out OUT ARGS` started, and the URL it says it
/// serves on (its first line: `netfi ui on URL`).
pub fn ui(out: &std::path::Path, args: &[&str]) -> (std::process::Child, String) {
    use std::io::BufRead;
    let mut child = netfi()
        .args(["ui", "--port", "0", "--out"])
        .arg(out)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("starting netfi ui");
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let url = line.trim().strip_prefix("netfi ui on ").unwrap_or_else(|| panic!("unexpected first line `{line}`")).to_string();
    (child, url)
}

/// The flags that pin a test's emulator: the last core, where there are
/// two or more; else `--no-pin`.
pub fn emulator_pin() -> Vec<String> {
    let cores = core_affinity::get_core_ids().map_or(1, |c| c.len());
    if cores >= 2 {
        vec!["--core".into(), (cores - 1).to_string()]
    } else {
        vec!["--no-pin".into()]
    }
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
