//! What a user gets from `netfi completions`, `netfi man`, and times with
//! units on the command line and in scenario files.

use crate::common::machine;
use crate::common::scratch::Scratch;
use crate::common::netfi::{netfi, Outcome};

#[test]
fn completions_cover_the_commands_and_their_flags() {
    let _machine = machine::not_beside_a_run();
    for shell in ["bash", "zsh", "fish"] {
        let out = netfi().args(["completions", shell]).output().unwrap();
        assert!(out.status.success(), "{shell}: {}", String::from_utf8_lossy(&out.stderr));
        let script = String::from_utf8_lossy(&out.stdout);
        for word in ["scenario", "export", "duration-s", "return-scenario"] {
            assert!(script.contains(word), "{shell} completion lacks `{word}`");
        }
    }
    let bad = netfi().args(["completions", "cmd.exe"]).output().unwrap();
    assert!(!bad.status.success());
}

#[test]
fn man_writes_a_page_per_command() {
    let _machine = machine::not_beside_a_run();
    let dir = std::env::temp_dir().join(format!("netfi-man-{}", std::process::id()));
    netfi().args(["man", "--dir"]).arg(&dir).ok();
    for page in ["netfi.1", "netfi-run.1", "netfi-scenario-check.1", "netfi-export-netem.1"] {
        let text = std::fs::read_to_string(dir.join(page)).unwrap_or_else(|e| panic!("{page}: {e}"));
        assert!(text.contains(".TH"), "{page} is not a roff page");
    }
    let run = std::fs::read_to_string(dir.join("netfi-run.1")).unwrap();
    assert!(run.contains("duration"), "netfi-run.1 does not describe --duration-s");
}

#[test]
fn times_take_units_and_bad_ones_are_named() {
    let _machine = machine::not_beside_a_run();
    let dir = Scratch::new("units");
    let file = dir.join("slots.toml");
    std::fs::write(&file, "name = \"units\"\nseed = 1\n[[stage]]\nmodel = \"slot\"\nmin_ms = \"2000us\"\nmax_ms = \"0.006s\"\n").unwrap();
    let out = netfi().args(["scenario", "show"]).arg(&file).ok();
    let shown = String::from_utf8_lossy(&out.stdout);
    assert!(shown.contains("min_ms = 2.0") && shown.contains("max_ms = 6.0"), "{shown}");
    std::fs::write(&file, "name = \"units\"\nseed = 1\n[[stage]]\nmodel = \"slot\"\nmin_ms = 2\nmax_ms = \"6 parsecs\"\n").unwrap();
    let out = netfi().args(["scenario", "show"]).arg(&file).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("slots.toml:6") && err.contains("`max_ms`") && err.contains("not a duration"), "{err}");
    // A phase's start too.
    std::fs::write(&file, "name = \"t\"\n[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_s = \"1.5min\"\npreset = \"PLM-2\"\n").unwrap();
    let out = netfi().args(["scenario", "show"]).arg(&file).ok();
    assert!(String::from_utf8_lossy(&out.stdout).contains("start_ms = 90000.0"), "{}", String::from_utf8_lossy(&out.stdout));
    std::fs::write(&file, "name = \"t\"\n[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_s = \"soon\"\npreset = \"PLM-2\"\n").unwrap();
    let out = netfi().args(["scenario", "show"]).arg(&file).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("slots.toml:5") && err.contains("`start_s`") && err.contains("not a duration"), "{err}");
    // On the command line: a unit is read, a bad one refused before anything runs.
    let out = netfi().args(["run", "Normal", "--duration", "3 fortnights"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("\"3 fortnights\" is not a duration"), "{err}");
}
