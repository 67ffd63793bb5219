//! `netfi export netem` with hostile input: the script it writes is meant to
//! run as root, so nothing taken from the command line or a scenario file
//! may run as a command. Each script is run by `sh` with a stand-in `tc`
//! that records its arguments.

use crate::common::netfi::{netfi, Outcome};
use std::path::{Path, PathBuf};
use std::process::Command;


struct Dir(PathBuf);

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn scratch(name: &str) -> Dir {
    let d = std::env::temp_dir().join(format!("netfi-export-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(d.join("bin")).unwrap();
    std::fs::create_dir_all(d.join("tables")).unwrap();
    // A `tc` that writes each argument on a line of its own.
    let tc = d.join("bin/tc");
    std::fs::write(&tc, "#!/bin/sh\nfor a in \"$@\"; do printf '%s\\n' \"$a\"; done > \"$NETFI_TC_ARGS\"\n").unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&tc, std::fs::Permissions::from_mode(0o755)).unwrap();
    Dir(d)
}

/// Runs `script` in `dir` (its working directory, where an injected
/// command would leave its mark) and returns tc's arguments.
fn run_script(dir: &Path, script: &[u8], table_dir: Option<&Path>) -> Vec<String> {
    let path = dir.join("netem.sh");
    std::fs::write(&path, script).unwrap();
    let mut cmd = Command::new("sh");
    cmd.arg(&path)
        .current_dir(dir)
        .env("PATH", format!("{}:{}", dir.join("bin").display(), std::env::var("PATH").unwrap_or_default()))
        .env("NETFI_TC_ARGS", dir.join("tc.args"))
        .env_remove("TC_LIB_DIR");
    if let Some(t) = table_dir {
        cmd.env("TC_LIB_DIR", t);
    }
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "script failed: {}\n{}", String::from_utf8_lossy(&out.stderr), String::from_utf8_lossy(script));
    let args = std::fs::read_to_string(dir.join("tc.args")).unwrap();
    args.lines().map(str::to_owned).collect()
}

fn marks(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with("PWNED"))
        .collect()
}

#[test]
fn hostile_interface_names_reach_tc_as_one_word_and_run_nothing() {
    let d = scratch("dev");
    // Legal for the kernel (no `/`, `:`, white space; at most 15 bytes)
    // and each a command for an unquoting shell.
    for dev in ["e;>PWNED1", "$(>PWNED2)", "`>PWNED3`", "x'&&>PWNED5", "a\"b$c", "-;>PWNED4", "e;touch PWNED"] {
        if dev.contains(' ') {
            // White space is not an interface name: refused outright.
            let out = netfi().args(["export", "netem", "PLM-1", "--dev", dev]).output().unwrap();
            assert!(!out.status.success(), "{dev:?} accepted");
            assert!(String::from_utf8_lossy(&out.stderr).contains("interface name"), "{dev:?}");
            continue;
        }
        let out = netfi().args(["export", "netem", "PLM-1", &format!("--dev={dev}")]).output().unwrap();
        assert!(out.status.success(), "{dev:?}: {}", String::from_utf8_lossy(&out.stderr));
        let args = run_script(&d.0, &out.stdout, None);
        assert_eq!(args[..5], ["qdisc", "replace", "dev", dev, "root"], "{dev:?}");
        assert!(marks(&d.0).is_empty(), "{dev:?} ran a command: {:?}", marks(&d.0));
    }
}

#[test]
fn interface_names_follow_the_kernels_grammar() {
    for (dev, says) in [
        ("", "1 to 15 bytes"),
        ("sixteen-bytes-xx", "1 to 15 bytes"),
        ("a/b", "'/'"),
        ("a:1", "':'"),
        ("a\tb", "'\\t'"),
        ("a\nb", "'\\n'"),
        ("..", "not interface names"),
    ] {
        let out = netfi().args(["export", "netem", "PLM-1", "--dev", dev]).output().unwrap();
        assert!(!out.status.success(), "{dev:?} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{dev:?}: {err}");
    }
    netfi().args(["export", "netem", "PLM-1", "--dev", "fifteen-bytes-x"]).ok();
}

#[test]
fn a_hostile_scenario_name_stays_in_its_comment() {
    let d = scratch("name");
    let file = d.0.join("s.toml");
    std::fs::write(&file, "name = \"x\\ntouch PWNED5\\r\\ntouch PWNED6 #\"\n[[stage]]\nmodel = \"bernoulli\"\np = 0.1\n").unwrap();
    let out = netfi().args(["export", "netem", file.to_str().unwrap(), "--dev", "veth0"]).ok();
    let script = String::from_utf8(out.stdout.clone()).unwrap();
    assert!(!script.lines().any(|l| l.starts_with("touch")), "{script}");
    let args = run_script(&d.0, &out.stdout, None);
    assert_eq!(args[..4], ["qdisc", "replace", "dev", "veth0"]);
    assert!(marks(&d.0).is_empty(), "{:?}", marks(&d.0));
}

#[test]
fn a_hostile_table_dir_is_one_word_and_the_table_lands_in_it() {
    let d = scratch("table");
    let hostile = d.0.join("tables/t'; touch PWNED7; '$(touch PWNED8)");
    std::fs::create_dir_all(&hostile).unwrap();
    let out = netfi().args(["export", "netem", "DLM-2", "--dev", "veth0", "--table-dir", hostile.to_str().unwrap()]).ok();
    let args = run_script(&d.0, &out.stdout, None);
    let dist = args.iter().skip_while(|a| *a != "distribution").nth(1).unwrap().clone();
    assert!(hostile.join(format!("{dist}.dist")).is_file(), "table not written into {}", hostile.display());
    assert!(marks(&d.0).is_empty(), "{:?}", marks(&d.0));
    let script = String::from_utf8_lossy(&out.stdout);
    assert!(script.contains("# To remove it: tc qdisc del dev veth0 root"), "{script}");
}

#[test]
fn without_a_table_dir_the_script_finds_tcs_or_says_where_it_looked() {
    let d = scratch("find");
    let out = netfi().args(["export", "netem", "DLM-2", "--dev", "veth0"]).ok();
    let script = String::from_utf8_lossy(&out.stdout);
    assert!(script.contains("/usr/lib/x86_64-linux-gnu/tc") && script.contains("/usr/lib/tc"), "{script}");
    // TC_LIB_DIR, when set, wins over the search.
    let tables = d.0.join("tables");
    run_script(&d.0, &out.stdout, Some(&tables));
    assert_eq!(std::fs::read_dir(&tables).unwrap().count(), 1);
    // The search itself, whatever this machine has installed: the script
    // with each directory it searches moved into the test's own.
    let searched = ["/usr/lib/x86_64-linux-gnu/tc", "/usr/lib/aarch64-linux-gnu/tc", "/usr/lib64/tc", "/usr/lib/tc"];
    let moved: Vec<PathBuf> = (0..searched.len()).map(|k| d.0.join(format!("searched-{k}"))).collect();
    let local = searched.iter().zip(&moved).fold(script.to_string(), |s, (from, to)| s.replace(from, to.to_str().unwrap()));
    assert!(searched.iter().all(|p| !local.contains(p)), "{local}");
    // Where no directory of the list has tc's tables, the script stops
    // before tc runs, naming where it looked.
    let path = d.0.join("netem.sh");
    std::fs::write(&path, &local).unwrap();
    std::fs::remove_file(d.0.join("tc.args")).unwrap();
    let o = Command::new("sh")
        .arg(&path)
        .env_remove("TC_LIB_DIR")
        .env("PATH", format!("{}:{}", d.0.join("bin").display(), std::env::var("PATH").unwrap_or_default()))
        .env("NETFI_TC_ARGS", d.0.join("tc.args"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("looked in") && err.contains(moved[0].to_str().unwrap()), "{err}");
    assert!(!d.0.join("tc.args").exists(), "tc ran without its tables");
    // Where some have them, the first of the list that has them is used.
    for k in [2, 3] {
        std::fs::create_dir_all(&moved[k]).unwrap();
        std::fs::write(moved[k].join("normal.dist"), "").unwrap();
    }
    assert!(!run_script(&d.0, local.as_bytes(), None).is_empty());
    let tables = |k: usize| std::fs::read_dir(&moved[k]).unwrap().filter(|e| e.as_ref().unwrap().file_name() != "normal.dist").count();
    assert_eq!((tables(2), tables(3)), (1, 0), "the table goes to the first directory found");
}

/// What tc cannot take is refused, naming the flag or field and the range
/// it accepts: a frame rate beyond the physical range (`--rate-hz 1e12`
/// once wrote `limit 1593117369386`, `1e300` wrote `limit 1000`), a delay
/// or jitter beyond tc's 32-bit tick fields, and a slot budget beyond tc's
/// signed 32-bit fields. Values just inside are accepted.
#[test]
fn what_tc_cannot_take_is_refused_with_the_range() {
    let stderr = |o: &std::process::Output| String::from_utf8_lossy(&o.stderr).into_owned();
    for rate in ["1e12", "1e300", "0", "-5", "NaN", "inf", "0.01"] {
        let out = netfi().args(["export", "netem", "DLM-2", &format!("--rate-hz={rate}")]).output().unwrap();
        assert!(!out.status.success(), "--rate-hz {rate} accepted: {}", String::from_utf8_lossy(&out.stdout));
        assert!(stderr(&out).contains("expected a frame rate from 0.1 to 1000000 Hz"), "{rate}: {}", stderr(&out));
    }
    let d = scratch("limits");
    let write = |name: &str, text: &str| {
        let p = d.0.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_owned()
    };
    // tc (iproute2 before 6.10) keeps `delay` and `jitter` in 32-bit
    // fields of ticks, 15.625 a µs: at most 274,877,906 µs. An hour's delay
    // once exported as `delay 3600000000us`, which tc refuses, stopping the
    // script. Each field that gives netem's delay or jitter is named.
    let limit = "at most 274877906 µs (274.878 s)";
    for (name, stage, what) in [
        ("hour", "model = \"delay\"\nmin_ms = 3600000", "stage 1 (delay): netem's `delay` would be 3600000000 µs (from `min_ms`)"),
        ("over", "model = \"delay\"\nmin_ms = 274877.9066", "netem's `delay` would be 274877907 µs (from `min_ms`)"),
        ("uniform", "model = \"delay\"\nmin_ms = 1\ndist = \"uniform\"\njitter_ms = 600000", "netem's `delay` would be 300001000 µs (from `min_ms` + `jitter_ms` / 2)"),
        ("jitter", "model = \"jitter\"\nmean_ms = 10\nsd_ms = 300000\ndist = \"normal\"", "stage 1 (jitter): netem's `jitter` would be 300000000 µs (from `sd_ms` / 1.0000"),
        ("reorder", "model = \"reorder\"\np = 0.1\ndelay_ms = 300000", "stage 1 (reorder): netem's `delay` would be 300000000 µs (from `delay_ms`)"),
    ] {
        let path = write(&format!("{name}.toml"), &format!("[[stage]]\n{stage}\n"));
        let out = netfi().args(["export", "netem", &path]).output().unwrap();
        assert!(!out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stdout));
        assert!(stderr(&out).contains(what) && stderr(&out).contains(limit), "{name}: {}", stderr(&out));
    }
    // The longest delay tc takes is exported, and its script runs; its
    // queue at 10⁶ Hz (3.4·10⁸ packets) fits tc's 32-bit `limit`.
    let longest = write("longest.toml", "[[stage]]\nmodel = \"delay\"\nmin_ms = 274877.906\n");
    let out = netfi().args(["export", "netem", &longest, "--rate-hz", "1e6"]).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("netem limit 343597384 delay 274877906us\n"), "{}", String::from_utf8_lossy(&out.stdout));
    let args = run_script(&d.0, &out.stdout, None);
    assert_eq!(args[args.len() - 2..], ["delay", "274877906us"]);
    let slot = write("slot.toml", "[[stage]]\nmodel = \"slot\"\nmin_ms = 1\nmax_ms = 2\npackets = 2147483648\n");
    let out = netfi().args(["export", "netem", &slot]).output().unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("`packets` 2147483648: tc keeps it in a signed 32-bit field, so netem takes 0 to 2147483647"), "{}", stderr(&out));
    let bytes = write("bytes.toml", "[[stage]]\nmodel = \"slot\"\nmin_ms = 1\nmax_ms = 2\nbytes = 2000000000\n");
    let out = netfi().args(["export", "netem", &bytes]).output().unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("`bytes` 2000000000") && stderr(&out).contains("netem takes 0 to 2147483647"), "{}", stderr(&out));
    let ok = write("ok.toml", "[[stage]]\nmodel = \"slot\"\nmin_ms = 1\nmax_ms = 2\npackets = 2147483647\nbytes = 1604000000\n");
    let out = netfi().args(["export", "netem", &ok]).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("slot 1000us 2000us packets 2147483647 bytes 2147290323"), "{}", String::from_utf8_lossy(&out.stdout));
}
