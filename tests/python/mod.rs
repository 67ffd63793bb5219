//! The Python clients (clients/python) against the real netfi processes,
//! over iceoryx2's official Python bindings: the interface of
//! docs/interface.md as both sides implement it, Python console → emulator →
//! Python robot, the Rust console with the Python robot, the Python console
//! with the Rust simulator, and a client of another payload version refused.
//!
//! Needs `python3` with the `iceoryx2` (0.10) and `lz4` packages; without
//! them each test says so and passes, unless `NETFI_REQUIRE_PYTHON` is set
//! (as `.ci/run` does), where their absence fails.
//!
//! The runs are serialized: each has a busy-waiting emulator pinned to a core.

use crate::common::wait_file;
use crate::common::netfi::emulator_pin;
use crate::common::netfi::netfi;
use netfi::sample::FrameSample;
use netfi::transport::{IpcConfig, Role, RunId};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::common::machine;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Whether python3 can import the bindings; prints why not when it cannot.
pub(crate) fn python_ready() -> bool {
    let o = Command::new("python3").args(["-c", "import iceoryx2, lz4"]).output();
    let why = match o {
        Ok(o) if o.status.success() => return true,
        Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_string(),
        Err(e) => format!("python3: {e}"),
    };
    assert!(
        std::env::var_os("NETFI_REQUIRE_PYTHON").is_none(),
        "NETFI_REQUIRE_PYTHON is set but the Python bindings are missing: {why}; pip install iceoryx2==0.10.0 lz4"
    );
    eprintln!("skipping: the Python bindings are not installed ({why}); pip install iceoryx2==0.10.0 lz4");
    false
}

/// The layout the Rust side of this build uses, for `NETFI_IOX_LAYOUT`.
fn rust_layout(config: &IpcConfig) -> &'static str {
    if config.prefix().starts_with("netfi_u") {
        "per-user"
    } else {
        "shared"
    }
}

/// A Python program of the client tree, with the run's layout in its
/// environment (so that a layout mismatch fails one test, the one that
/// checks it, rather than all of them by timeout).
fn python(script: &str, run: &Run) -> Command {
    let mut c = Command::new("python3");
    c.arg(root().join("clients/python").join(script))
        .env("PYTHONPATH", root().join("clients/python"))
        .env("NETFI_IOX_LAYOUT", rust_layout(&run.config));
    c
}

/// One run: its id, output directory and iceoryx2 configuration. Removes
/// what the run left in /dev/shm and under the iceoryx2 root when dropped.
struct Run {
    id: String,
    out: PathBuf,
    config: IpcConfig,
}

impl Run {
    /// [`Run::new`] where the Python bindings are there (see [`python_ready`]).
    fn ready(name: &str) -> Option<Run> {
        python_ready().then(|| Run::new(name))
    }

    fn new(name: &str) -> Run {
        let id = format!("py-{name}-{}", std::process::id());
        let out = std::env::temp_dir().join(format!("netfi-py-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        std::fs::create_dir_all(&out).unwrap();
        let config = IpcConfig::new(RunId::new(&id).unwrap());
        Run { id, out, config }
    }

    fn json(&self, file: &str) -> Value {
        let p = self.out.join(file);
        let bytes = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }

    fn emulator(&self, scenario: &str, extra: &[&str]) -> Witness {
        let pin = emulator_pin();
        let pin: Vec<&str> = pin.iter().map(String::as_str).collect();
        self.service("emulator", &[&["--scenario", scenario][..], &pin, extra].concat())
    }

    /// `netfi simulator` of this run with `extra`, once ready.
    fn simulator(&self, extra: &[&str]) -> Witness {
        self.service("simulator", extra)
    }

    /// `netfi ROLE` of this run with `args`, once it says it is ready.
    fn service(&self, role: &str, args: &[&str]) -> Witness {
        let child = netfi()
            .args([role, "--run-id", &self.id, "--out"])
            .arg(&self.out)
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        wait_file(&self.out.join(format!("{role}.ready")));
        Witness(Some(child))
    }

    /// The Python viewer of the run's `video_out`, subscribed: its JSON
    /// summary goes to `viewer.json`, its rows to `viewer.csv`.
    fn python_viewer(&self, hz: &str) -> Witness {
        let csv = self.out.join("viewer.csv");
        self.python_end("viewer", &["--hz", hz], Some(&csv))
    }

    fn python_robot(&self) -> Witness {
        self.python_end("robot", &[], None)
    }

    /// `examples/<name>.py` of the run, its JSON summary to `<name>.json`,
    /// `extra` and then `--csv <csv>` when given; returns once it says it
    /// is ready (`<name>.ready`).
    fn python_end(&self, name: &str, extra: &[&str], csv: Option<&Path>) -> Witness {
        let ready = self.out.join(format!("{name}.ready"));
        let mut c = python(&format!("examples/{name}.py"), self);
        c.args(["--run-id", &self.id]).args(extra).args(["--timeout-s", "120", "--out"]).arg(self.out.join(format!("{name}.json")));
        if let Some(path) = csv {
            c.arg("--csv").arg(path);
        }
        let child = c.arg("--ready").arg(&ready).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
        wait_file(&ready);
        Witness(Some(child))
    }
}

impl Drop for Run {
    fn drop(&mut self) {
        let prefix = self.config.prefix().to_string();
        let root = root_path(&self.config);
        for dir in [PathBuf::from("/dev/shm"), root.join("nodes"), root.join("services")] {
            let Ok(rd) = std::fs::read_dir(&dir) else { continue };
            for e in rd.filter_map(|e| e.ok()) {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    let p = e.path();
                    let _ = std::fs::remove_dir_all(&p).or_else(|_| std::fs::remove_file(&p));
                }
            }
        }
    }
}

fn root_path(config: &IpcConfig) -> PathBuf {
    use iceoryx2::prelude::SemanticString;
    PathBuf::from(String::from_utf8_lossy(config.iceoryx2().global.root_path().as_bytes()).into_owned())
}

/// A child process, killed and reaped however the test ends.
struct Witness(Option<Child>);

impl Witness {
    /// Waits at most `limit` for the process to end on its own.
    fn finish(mut self, what: &str, limit: Duration) -> Output {
        let mut child = self.0.take().unwrap();
        let t0 = Instant::now();
        while child.try_wait().unwrap().is_none() {
            if t0.elapsed() > limit {
                let _ = child.kill();
                let o = child.wait_with_output().unwrap();
                panic!("{what} did not end within {limit:?}; stderr:\n{}", String::from_utf8_lossy(&o.stderr));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{what} failed ({}); stderr:\n{}", o.status, String::from_utf8_lossy(&o.stderr));
        o
    }
}

impl Drop for Witness {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn run_ok(mut c: Command, what: &str) -> Output {
    let o = c.output().unwrap();
    assert!(o.status.success(), "{what} failed ({}); stderr:\n{}", o.status, String::from_utf8_lossy(&o.stderr));
    o
}

/// `python3 -c code` with the client tree on its path (and no
/// `NETFI_IOX_LAYOUT`: the module's own default).
fn python_c(code: &str) -> Command {
    let mut c = Command::new("python3");
    c.env("PYTHONPATH", root().join("clients/python")).env_remove("NETFI_IOX_LAYOUT").args(["-c", code]);
    c
}

/// What `python3 -c code` printed, as JSON.
fn python_json(code: &str, what: &str) -> Value {
    serde_json::from_slice(&run_ok(python_c(code), what).stdout).unwrap()
}

/// A payload's layout as netfi_iox gives it (`type_name`, `size`,
/// `alignment`, `offsets`, and the `iceoryx2_type_name` its bindings see)
/// is the Rust type `T`'s, field for field.
fn assert_layout<T: iceoryx2::prelude::ZeroCopySend>(l: &Value, type_name: &str, offsets: &[(&str, usize)]) {
    // SAFETY: type_name only returns the #[type_name] attribute's string.
    let rust_name = unsafe { <T as iceoryx2::prelude::ZeroCopySend>::type_name() };
    assert_eq!(l["iceoryx2_type_name"], rust_name);
    assert_eq!(l["type_name"], type_name);
    assert_eq!(u(&l["size"]), core::mem::size_of::<T>() as u64);
    assert_eq!(u(&l["alignment"]), core::mem::align_of::<T>() as u64);
    let off = &l["offsets"];
    for (field, at) in offsets {
        assert_eq!(u(&off[*field]), *at as u64, "{field}");
    }
    assert_eq!(off.as_object().unwrap().len(), offsets.len(), "a field the Rust type lacks: {off}");
}

/// `(name, offset)` of each named field of a type.
macro_rules! offsets {
    ($t:ty: $($f:ident),*) => { &[$((stringify!($f), core::mem::offset_of!($t, $f))),*] };
}

#[track_caller]
fn u(v: &Value) -> u64 {
    match v.as_u64() {
        Some(n) => n,
        None => panic!("not a count: {v}"),
    }
}

/// entered = delivered + dropped + held_at_end, every frame the console
/// sent entered, and the emulator ended on the console's end marker.
fn assert_emulator_balanced(emu: &Value, sent: u64) {
    assert_emulator_account(emu, sent);
    assert_eq!(emu["ended_by"], "end_marker");
}

/// entered = delivered + dropped + held_at_end, and every frame the console
/// sent entered.
fn assert_emulator_account(emu: &Value, sent: u64) {
    let f = &emu["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&f["sent_by_console"]), sent, "{f}");
    assert_eq!(u(&f["entered"]), sent, "{f}");
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert_eq!(u(&f["held_at_end"]), 0, "{f}");
    assert_eq!(u(&emu["send_errors"]), 0);
}

/// The Python module's interface (payload layout, type name, names,
/// configuration, limits) is the Rust one.
#[test]
fn the_python_interface_is_the_rust_one() {
    let Some(run) = Run::ready("layout") else { return };
    // No NETFI_IOX_LAYOUT (python_c leaves it out): the module's own default must be this build's.
    let py = python_json(
        &format!(
            r#"
import json, netfi_iox as n, netfi_iox.run as r
root, prefix = n.location("{id}")
print(json.dumps({{
    "layout": r.file_layout(), "root": root, "prefix": prefix,
    "services": [n.service_name("{id}", c) for c in n.CHANNELS],
    "nodes": [n.node_name("{id}", x) for x in ("console", "emulator", "simulator", "tool")],
    "limits": [r.SUBSCRIBER_BUFFER_FRAMES, r.MAX_PUBLISHERS_PER_CHANNEL, r.MAX_SUBSCRIBERS_PER_CHANNEL, r.MAX_NODES_PER_CHANNEL, r.HISTORY_FRAMES],
    "end": n.FLAG_END, "raw": n.FLAG_RAW, "itp_len": n.ITP_FRAME_LEN,
}}))
"#,
            id = run.id
        ),
        "python3 netfi_iox",
    );
    let rust_root = root_path(&run.config);
    assert_eq!(
        (py["prefix"].as_str().unwrap(), Path::new(py["root"].as_str().unwrap())),
        (run.config.prefix(), rust_root.as_path()),
        "netfi_iox.run.DEFAULT_LAYOUT ({}) is not the layout of this netfi build ({}): set it to {:?}",
        py["layout"],
        rust_layout(&run.config),
        rust_layout(&run.config)
    );
    // Every port of a shipped channel (the test builds' own haptic channel
    // is not part of the Python interface).
    use netfi::service::channel::haptic::{HAPTIC, HAPTIC_OUT};
    let test_only = [run.config.service_name(HAPTIC), run.config.service_name(HAPTIC_OUT)];
    let services: Vec<String> = netfi::service::ports().iter().map(|c| run.config.service_name(*c)).filter(|n| !test_only.contains(n)).collect();
    assert_eq!(py["services"], serde_json::json!(services));
    let nodes: Vec<String> = [Role::Console, Role::Emulator, Role::Simulator, Role::Tool].iter().map(|r| run.config.node_name(*r)).collect();
    assert_eq!(py["nodes"], serde_json::json!(nodes));
    use netfi::transport::{MAX_NODES_PER_CHANNEL, MAX_PUBLISHERS_PER_CHANNEL, MAX_SUBSCRIBERS_PER_CHANNEL, SUBSCRIBER_BUFFER_FRAMES};
    assert_eq!(
        py["limits"],
        serde_json::json!([SUBSCRIBER_BUFFER_FRAMES, MAX_PUBLISHERS_PER_CHANNEL, MAX_SUBSCRIBERS_PER_CHANNEL, MAX_NODES_PER_CHANNEL, 0])
    );
    let ps = &run.config.iceoryx2().defaults.publish_subscribe;
    assert_eq!(ps.publisher_history_size, 0);
    assert!(!ps.enable_safe_overflow);
    assert_eq!((u(&py["end"]), u(&py["raw"])), (FrameSample::FLAG_END as u64, FrameSample::FLAG_RAW as u64));
    assert_eq!(u(&py["itp_len"]), netfi::sample::ITP_FRAME_LEN as u64);

    // The payloads: the type name iceoryx2 sees, size, alignment, offsets.
    let l = python_json(
        "import json, iceoryx2, netfi_iox as n; l = n.layout(); l['iceoryx2_type_name'] = iceoryx2.get_type_name(n.FrameSample); print(json.dumps(l))",
        "python3 netfi_iox.layout",
    );
    assert_layout::<FrameSample>(
        &l,
        FrameSample::TYPE_NAME,
        offsets!(FrameSample: send_ns, console_index, ingress_index, ingress_ns, injected_delay_ns, release_sched_ns, release_ns, len, flags, wire, _pad),
    );
    use netfi::sample::FeedbackSample;
    let l = python_json(
        "import json, iceoryx2, netfi_iox as n; l = n.feedback_layout(); l['iceoryx2_type_name'] = iceoryx2.get_type_name(n.FeedbackSample); print(json.dumps(l))",
        "python3 netfi_iox.feedback_layout",
    );
    assert_layout::<FeedbackSample>(
        &l,
        FeedbackSample::TYPE_NAME,
        offsets!(FeedbackSample:
            send_ns, robot_index, console_index, command_send_ns, command_ingress_ns, command_release_ns,
            command_injected_delay_ns, ingress_index, ingress_ns, injected_delay_ns, release_sched_ns, release_ns,
            sequence, flags, position, rotation, grasp, commands
        ),
    );
}

/// The Python module finds the user's iceoryx2 root in netfi's order
/// (docs/interface.md): a private `NETFI_IPC_ROOT`, then a private
/// `$XDG_RUNTIME_DIR`'s `netfi-iceoryx2`, passing over either when it is
/// open to others; pure file-system rules, so no run is needed.
#[test]
fn the_python_root_follows_netfis_order() {
    use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
    if !python_ready() {
        return;
    }
    let base = std::env::temp_dir().join(format!("netfi-py-root-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let dir = |name: &str, mode: u32| {
        let d = base.join(name);
        std::fs::DirBuilder::new().recursive(true).mode(mode).create(&d).unwrap();
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(mode)).unwrap();
        d
    };
    std::fs::DirBuilder::new().mode(0o700).create(&base).unwrap();
    let (named, open, xdg) = (dir("named", 0o700), dir("open", 0o755), dir("xdg", 0o700));
    let root_with = |env: &[(&str, &Path)]| {
        let mut c = python_c("import netfi_iox.run as r; print(r.user_root_dir())");
        c.env_remove("NETFI_IPC_ROOT").env_remove("XDG_RUNTIME_DIR");
        for (k, v) in env {
            c.env(k, v);
        }
        String::from_utf8(run_ok(c, "python3 user_root_dir").stdout).unwrap().trim().to_string()
    };
    let slash = |p: &Path| format!("{}/", p.display());
    assert_eq!(root_with(&[("NETFI_IPC_ROOT", &named), ("XDG_RUNTIME_DIR", &xdg)]), slash(&named));
    assert_eq!(root_with(&[("NETFI_IPC_ROOT", &open), ("XDG_RUNTIME_DIR", &xdg)]), slash(&xdg.join("netfi-iceoryx2")));
    let made = std::fs::symlink_metadata(xdg.join("netfi-iceoryx2")).unwrap();
    assert!(made.is_dir() && made.permissions().mode() & 0o077 == 0, "made private");
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    let tmp = root_with(&[("XDG_RUNTIME_DIR", &open)]);
    assert!(tmp.starts_with(&format!("/tmp/netfi-iceoryx2-{uid}")), "an open XDG_RUNTIME_DIR is passed over: {tmp}");
    let _ = std::fs::remove_dir_all(&base);
}

/// The Python ITP encoder and decoder agree with the Rust codec, checksum
/// included, on every frame of a synthetic stream and the real capture.
#[test]
fn python_itp_frames_are_rust_itp_frames() {
    let Some(run) = Run::ready("codec") else { return };
    let o = run_ok(
        python_c("import sys, netfi_iox as n; f = n.ItpFrame(sequence=2**32-1, delx=(2**31-1, -5), dely=(7, 8), delz=(-9, 10), qx=(0.5, -0.25), buttonstate=(1, 2), grasp=(300, -4), surgeon_mode=1).seal(); sys.stdout.buffer.write(f.encode())"),
        "python3 ItpFrame.encode",
    );
    let wire = o.stdout;
    assert_eq!(wire.len(), netfi::frame::FRAME_LEN);
    let view = netfi::frame::ItpView::new_checked(&wire[..]).unwrap();
    let f = netfi::frame::ItpFrame::parse(&view).expect("the Python frame's checksum is the Rust one");
    assert_eq!(f.sequence, u32::MAX);
    assert_eq!(f.delx, [i32::MAX, -5]);
    assert_eq!(f.grasp, [300, -4]);
    drop(run);
}

/// Python console → netfi emulator (PLM-2) → Python robot: every frame is
/// accounted for, the robot receives exactly what the emulator released,
/// and the loss realizes the model (the fates are those the scenario gives
/// the same seed in simulated time).
#[test]
fn python_console_through_the_emulator_to_the_python_robot() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("py-py") else { return };
    let robot = run.python_robot();
    let emu = run.emulator("PLM-2", &["--seed", "3", "--expected-frames", "20000"]);
    let console = python("examples/console.py", &run)
        .args(["--run-id", &run.id, "--frames", "20000", "--rate-hz", "2500", "--out"])
        .arg(run.out.join("console.json"))
        .output()
        .unwrap();
    assert!(console.status.success(), "console: {}", String::from_utf8_lossy(&console.stderr));
    emu.finish("emulator", Duration::from_secs(60));
    robot.finish("robot", Duration::from_secs(60));
    let (c, e, r) = (run.json("console.json"), run.json("emulator.json"), run.json("robot.json"));
    assert_eq!(u(&c["frames_sent"]), 20000, "{c}");
    assert_eq!((u(&c["send_errors"]), u(&c["sent_unsubscribed"])), (0, 0), "{c}");
    assert_emulator_balanced(&e, 20000);
    let delivered = u(&e["frames"]["delivered"]);
    assert_eq!(u(&r["released_by_emulator"]), delivered, "{r}");
    assert_eq!(u(&r["received"]), delivered, "{r}");
    assert_eq!(r["balanced"], true);
    assert_eq!((u(&r["bad_checksum"]), u(&r["wrong_size"])), (0, 0));
    assert_eq!(r["ended_by"], "end_marker");
    // The robot also followed the console's direct copies.
    assert_eq!(u(&r["received_direct"]), 20000);
    // Realized loss: the model's rate within the run's 95 % interval, and the
    // very drops the scenario gives this seed in simulated time.
    crate::common::assert_plm2_seed3_is_the_checks(&e);
    assert!(u(&e["frames"]["dropped"]["ge_lomax"]) > 0);
    // The feedback loop, balanced the other way: one feedback per command
    // the robot received, every one through the return scenario (Normal)
    // and to the Python console.
    assert_feedback_balanced(&e, &r, &c, delivered);
}

/// A stand-alone emulator between the Python console and robot, which
/// write no report of netfi's: `netfi report DIR` heads it as the
/// emulator's, balances its frames at the emulator with what only the
/// clients know said as not known, lists no `report.json`, and exits 0;
/// the same directory with a file cut short (a real fault) exits 1.
#[test]
fn a_stand_alone_emulators_report_says_what_it_knows_and_fails_only_on_a_fault() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("alone") else { return };
    let robot = run.python_robot();
    let emu = run.emulator("PLM-2", &["--seed", "3", "--expected-frames", "2000"]);
    let mut console = python("examples/console.py", &run);
    console.args(["--run-id", &run.id, "--frames", "2000", "--rate-hz", "2000", "--out"]).arg(run.out.join("py_console.json"));
    run_ok(console, "python console");
    emu.finish("emulator", Duration::from_secs(60));
    robot.finish("robot", Duration::from_secs(60));
    assert_emulator_balanced(&run.json("emulator.json"), 2000);
    let o = netfi().arg("report").arg(&run.out).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.starts_with(&format!("netfi emulator {}: scenario PLM-2 (seed 3)", run.out.file_name().unwrap().to_string_lossy())), "{text}");
    assert!(text.contains("started without `netfi run`"), "{text}");
    assert!(text.contains("frames     sent 2000  entered 2000  delivered "), "{text}");
    assert!(text.contains("accounting balanced at the emulator: ") && text.contains("not known: what the robot received"), "{text}");
    assert!(text.contains("  accounting balanced; loss"), "the feedback loop balances on the counts there are: {text}");
    for never in ["NOT balanced", "FAULT", "report.json", "netfi run "] {
        assert!(!text.contains(never), "{never}: {text}");
    }
    // A file cut short is a real fault: said, and the exit status is 1.
    std::fs::write(run.out.join("trace_feedback.csv.partial"), b"ingress_index\n").unwrap();
    let o = netfi().arg("report").arg(&run.out).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success(), "a run with a cut file reported as whole:\n{text}");
    assert!(text.contains("FAULT      cut file: "), "{text}");
    assert!(String::from_utf8_lossy(&o.stderr).contains("had faults: cut file: "), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Robot → emulator → console: the robot sent one feedback per command it
/// received, each entered the emulator's feedback path and, through a
/// Normal return scenario, reached the console, which measured its round
/// trip.
fn assert_feedback_balanced(e: &Value, r: &Value, c: &Value, commands: u64) {
    let fb = &e["feedback"];
    assert_eq!(u(&r["feedback_sent"]), commands, "{r}");
    assert_eq!(u(&fb["sent_by_robot"]), commands, "{fb}");
    assert_eq!(u(&fb["entered"]), commands, "{fb}");
    let dropped: u64 = fb["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&fb["entered"]), u(&fb["delivered"]) + dropped + u(&fb["held_at_end"]), "{fb}");
    assert_eq!((dropped, u(&fb["held_at_end"])), (0, 0), "Normal drops nothing: {fb}");
    assert_eq!(fb["balanced"], true, "{fb}");
    assert_eq!(fb["scenario"], "Normal");
    let cf = &c["feedback"];
    assert_eq!(u(&cf["received"]), commands, "{cf}");
    assert_eq!(u(&cf["sent_by_emulator"]), commands, "{cf}");
    assert_eq!(u(&cf["unknown_command"]), 0, "{cf}");
    assert_eq!(cf["ended_by"], "end_marker", "{cf}");
    assert_eq!(u(&cf["round_trip_us"]["count"]), commands, "{cf}");
}

/// netfi's own console → emulator → the Python robot: the robot decodes
/// every frame the Rust console encoded, and with nothing lost its pose is
/// the console's.
#[test]
fn rust_console_through_the_emulator_to_the_python_robot() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("rs-py") else { return };
    let robot = run.python_robot();
    let emu = run.emulator("Normal", &["--seed", "1", "--expected-frames", "3000"]);
    let mut console = netfi();
    console.args(["console", "--run-id", &run.id, "--frames", "3000", "--rate-hz", "1000", "--seed", "2", "--out"]).arg(&run.out);
    run_ok(console, "netfi console");
    emu.finish("emulator", Duration::from_secs(60));
    robot.finish("robot", Duration::from_secs(60));
    let (e, r) = (run.json("emulator.json"), run.json("robot.json"));
    assert_emulator_balanced(&e, 3000);
    assert_eq!(u(&e["frames"]["delivered"]), 3000);
    assert_eq!(u(&r["received"]), 3000, "{r}");
    assert_eq!(u(&r["released_by_emulator"]), 3000);
    assert_eq!(u(&r["received_direct"]), 3000);
    assert_eq!(u(&r["sent_by_console"]), 3000);
    assert_eq!((u(&r["bad_checksum"]), u(&r["wrong_size"])), (0, 0));
    assert!(u(&r["applied"]) > 0);
    // The Python robot's feedback reached netfi's console, every piece.
    let c = run.json("console.json");
    assert_eq!(u(&e["feedback"]["entered"]), 3000, "{}", e["feedback"]);
    assert_eq!(u(&c["feedback"]["received"]), 3000, "{}", c["feedback"]);
    assert_eq!(u(&c["feedback"]["round_trip_ns"]["count"]), 3000, "{}", c["feedback"]);
    assert_eq!(c["feedback"]["ended_by"], "end_marker");
    for arm in 0..2 {
        assert_eq!(c["feedback"]["divergence_max_mm"][arm].as_f64(), Some(0.0), "nothing lost, yet the robot diverged: {}", c["feedback"]);
    }
    for arm in r["divergence"].as_array().unwrap() {
        for (k, v) in arm.as_object().unwrap() {
            assert!(v.as_f64().unwrap().abs() < 1e-9, "{k} diverged by {v} with nothing lost: {r}");
        }
    }
}

/// The Python console → emulator → netfi's own simulator: the simulator
/// receives every frame the emulator released, finds every checksum the
/// Python console computed right, and follows the direct copies.
#[test]
fn python_console_through_the_emulator_to_the_rust_simulator() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("py-rs") else { return };
    let sim = run.simulator(&[]);
    let emu = run.emulator("PLM-1", &["--seed", "5", "--expected-frames", "3000"]);
    let mut console = python("examples/console.py", &run);
    console.args(["--run-id", &run.id, "--frames", "3000", "--rate-hz", "1000", "--out"]).arg(run.out.join("console.json"));
    run_ok(console, "python console");
    emu.finish("emulator", Duration::from_secs(60));
    sim.finish("simulator", Duration::from_secs(60));
    let (e, s) = (run.json("emulator.json"), run.json("simulator.json"));
    assert_emulator_balanced(&e, 3000);
    assert_eq!(e["frames"]["bad_checksum_passed"], 0);
    let delivered = u(&e["frames"]["delivered"]);
    assert_eq!(u(&s["received"]), delivered, "{s}");
    assert_eq!(u(&s["released_by_emulator"]), delivered);
    assert_eq!(u(&s["received_direct"]), 3000);
    assert_eq!((u(&s["bad_checksum"]), u(&s["wrong_size"])), (0, 0));
    assert_eq!(s["ended_by"], "end_marker");
    // netfi's simulator's feedback reached the Python console, every piece.
    let c = run.json("console.json");
    assert_eq!(u(&s["feedback_sent"]), delivered, "{s}");
    assert_eq!(u(&e["feedback"]["entered"]), delivered, "{}", e["feedback"]);
    assert_eq!(u(&c["feedback"]["received"]), delivered, "{}", c["feedback"]);
    assert_eq!(c["feedback"]["ended_by"], "end_marker");
}

/// The Python console replays the real capture: every record, in order,
/// reaches the robot with its checksum intact.
#[test]
fn the_python_console_replays_the_real_capture() {
    if !python_ready() {
        return;
    }
    let Some(cap) = crate::common::data::shipped_capture() else { return };
    let _guard = machine::alone();
    let run = Run::new("replay");
    let robot = run.python_robot();
    let emu = run.emulator("Normal", &["--seed", "1", "--expected-frames", "1500"]);
    let mut console = python("examples/console.py", &run);
    console.args(["--run-id", &run.id, "--frames", "1500", "--out"]).arg(run.out.join("console.json")).arg("--capture").arg(&cap);
    run_ok(console, "python console --capture");
    emu.finish("emulator", Duration::from_secs(60));
    robot.finish("robot", Duration::from_secs(60));
    let (c, e, r) = (run.json("console.json"), run.json("emulator.json"), run.json("robot.json"));
    assert_eq!(u(&c["frames_sent"]), 1500);
    // At its original timing: 1500 frames of a ~517 Hz recording take ~2.9 s.
    let d = c["duration_s"].as_f64().unwrap();
    assert!(d > 2.0, "replayed in {d} s, faster than recorded");
    assert_emulator_balanced(&e, 1500);
    assert_eq!(u(&r["received"]), 1500);
    assert_eq!((u(&r["bad_checksum"]), u(&r["wrong_size"])), (0, 0));
    // The capture's own frames: the robot's pose is the console's.
    for arm in r["divergence"].as_array().unwrap() {
        assert_eq!(arm["x"], 0, "{r}");
    }
}

/// A client of another payload version (another type name, or the same
/// name with another size) is refused when it opens the run's channel, with
/// a message that names both.
#[test]
fn a_client_of_another_payload_version_is_refused() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("version") else { return };
    let emu = run.emulator("Normal", &["--seed", "1"]);
    let o = python("../../tests/python/other_version.py", &run).arg(&run.id).output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 2, "{stdout}");
    // Another name.
    assert!(lines[0].contains("netfi::FrameSample.v0") && lines[0].contains("netfi::FrameSample.v1"), "{}", lines[0]);
    // The same name, another size.
    assert!(lines[1].contains("200 bytes") && lines[1].contains("192 bytes"), "{}", lines[1]);
    // The emulator was not disturbed: a v1 console still streams through it.
    let robot = run.python_robot();
    let mut console = python("examples/console.py", &run);
    console.args(["--run-id", &run.id, "--frames", "200", "--rate-hz", "1000", "--no-direct"]);
    run_ok(console, "python console");
    emu.finish("emulator", Duration::from_secs(60));
    robot.finish("robot", Duration::from_secs(60));
    assert_eq!(u(&run.json("robot.json")["received"]), 200);
}

/// Killing the Python robot mid-run: the emulator finds it dead, ends the
/// feedback early, the console ends its stream on that, and the emulator
/// drains it and ends, saying which peer died; every frame the console sent
/// entered the emulator, and the emulator's account closes.
#[test]
fn killing_the_python_robot_ends_the_run_with_nothing_unaccounted() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("kill-robot") else { return };
    let mut robot = run.python_robot();
    let emu = run.emulator("PLM-1", &["--seed", "4", "--expected-frames", "60000"]);
    let console = python("examples/console.py", &run)
        .args(["--run-id", &run.id, "--frames", "60000", "--rate-hz", "1000", "--no-direct", "--out"])
        .arg(run.out.join("console.json"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let console = Witness(Some(console));
    std::thread::sleep(Duration::from_secs(3));
    // SIGKILL: the robot leaves its node behind, as a crash does.
    let mut child = robot.0.take().unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    console.finish("python console", Duration::from_secs(60));
    emu.finish("emulator", Duration::from_secs(60));
    let (c, e) = (run.json("console.json"), run.json("emulator.json"));
    assert_eq!(e["ended_by"], "peer_died", "{e}");
    let dead = e["dead_peers"].as_array().unwrap();
    assert!(dead.iter().any(|d| d.as_str().unwrap().starts_with("simulator")), "{e}");
    assert_eq!(c["ended_by"], "emulator_ended", "{c}");
    let sent = u(&c["frames_sent"]);
    assert!(sent > 1000 && sent < 60000, "the console stopped early: {sent}");
    assert_eq!(u(&c["sent_unsubscribed"]), 0, "{c}");
    assert_emulator_account(&e, sent);
}

/// A stand-alone emulator releases frames whether or not a robot is
/// subscribed, and counts those that went nowhere apart; with
/// `--wait-for-peer-s` it opens its input only once a robot is there.
#[test]
fn frames_released_to_no_robot_are_counted_and_the_emulator_can_wait_for_one() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("no-robot") else { return };
    let emu = run.emulator("Normal", &["--seed", "1", "--expected-frames", "300"]);
    let mut console = python("examples/console.py", &run);
    console.args(["--run-id", &run.id, "--frames", "300", "--rate-hz", "1000", "--no-direct"]);
    run_ok(console, "python console");
    emu.finish("emulator", Duration::from_secs(60));
    let e = run.json("emulator.json");
    assert_emulator_balanced(&e, 300);
    assert_eq!(u(&e["frames"]["delivered"]), 300);
    assert_eq!(u(&e["frames"]["delivered_unsubscribed"]), 300, "{e}");

    let run = Run::new("wait-robot");
    let pin = emulator_pin();
    let emu = netfi()
        .args(["emulator", "--run-id", &run.id, "--scenario", "Normal", "--seed", "1", "--wait-for-peer-s", "60", "--out"])
        .arg(&run.out)
        .args(&pin)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let emu = Witness(Some(emu));
    std::thread::sleep(Duration::from_millis(1500));
    assert!(!run.out.join("emulator.ready").exists(), "the emulator was ready without a robot");
    let robot = run.python_robot();
    wait_file(&run.out.join("emulator.ready"));
    let mut console = python("examples/console.py", &run);
    console.args(["--run-id", &run.id, "--frames", "300", "--rate-hz", "1000", "--no-direct"]);
    run_ok(console, "python console");
    emu.finish("emulator", Duration::from_secs(60));
    robot.finish("robot", Duration::from_secs(60));
    let (e, r) = (run.json("emulator.json"), run.json("robot.json"));
    assert_emulator_balanced(&e, 300);
    assert_eq!(u(&e["frames"]["delivered_unsubscribed"]), 0, "{e}");
    assert_eq!(u(&r["received"]), 300, "{r}");
}

/// netfi's own processes, refused by a run whose channel carries another
/// payload version, name both versions.
#[test]
fn the_rust_refusal_names_both_payload_versions() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("rust-refusal") else { return };
    let holder = r#"
import sys, netfi_iox as n
class V0(n.FrameSample):
    @staticmethod
    def type_name():
        return "netfi::FrameSample.v0"
with n.RunNode(sys.argv[1], "tool") as node:
    p = node.publisher("console", V0)
    print("ready", flush=True)
    sys.stdin.read()
"#;
    let mut c = python_c(holder);
    c.env("NETFI_IOX_LAYOUT", rust_layout(&run.config))
        .arg(&run.id)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = c.spawn().unwrap();
    let mut line = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(child.stdout.as_mut().unwrap()), &mut line).unwrap();
    assert_eq!(line.trim(), "ready");
    let o = netfi()
        .args(["emulator", "--run-id", &run.id, "--scenario", "Normal", "--no-pin", "--out"])
        .arg(&run.out)
        .output()
        .unwrap();
    drop(child.stdin.take());
    let _ = child.wait();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "the emulator opened a v0 channel: {err}");
    assert!(err.contains("netfi::FrameSample.v0") && err.contains("netfi::FrameSample.v1"), "{err}");
}

/// A foreign publisher's bad input — a `len` of zero, shorter or longer
/// than a frame, garbage control bits, a raw flag, garbage bytes, then a
/// flood faster than the emulator takes it — is dropped by kind and
/// counted, with the sender named; the emulator stays up and the account
/// closes.
#[test]
fn bad_input_is_counted_by_kind_and_its_sender_named() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("bad-input") else { return };
    let emu = run.emulator("Normal", &["--seed", "1", "--expected-frames", "40000"]);
    let o = python("../../tests/python/bad_input.py", &run).args([&run.id, "30000"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let sent: Value = serde_json::from_slice(&o.stdout).unwrap();
    emu.finish("emulator", Duration::from_secs(60));
    let e = run.json("emulator.json");
    let f = &e["frames"];
    // What the publisher was told its emulator's queue refused never entered.
    let offered = u(&sent["sent"]);
    let refused = u(&sent["refused"]);
    assert_eq!(u(&f["entered"]), offered - refused, "{f}");
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&f["entered"]), u(&f["delivered"]) + dropped + u(&f["held_at_end"]), "{f}");
    assert_eq!(u(&f["dropped"]["wrong_size"]), 3, "{f}");
    assert_eq!(u(&f["dropped"]["bad_flags"]), 2, "{f}");
    let b = &f["bad_input"];
    assert_eq!((u(&b["len_zero"]), u(&b["len_short"]), u(&b["len_oversize"]), u(&b["bad_flags"])), (1, 1, 1, 2), "{b}");
    assert_eq!(u(&f["bad_checksum_passed"]), 1, "{f}");
    let from: Vec<&str> = b["from"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert!(from.iter().any(|w| w.starts_with("console") && w.contains("pid")), "{b}");
    assert_eq!(e["ended_by"], "end_marker");
}

/// `netfi::VideoHeader.v1` in Python is the Rust header: type name, size,
/// alignment, every offset, the flags, the channels' limits; and the
/// Python camera's group of pictures is the Rust camera's.
#[test]
fn the_python_video_header_is_the_rust_one() {
    if !python_ready() {
        return;
    }
    use netfi::transport::ipc::video::VideoHeader;
    use netfi::transport::ipc::video::{DEFAULT_VIDEO_MAX_BYTES, VIDEO_BUFFER_FRAMES, VIDEO_HELD_FRAMES, VIDEO_INITIAL_SLICE_BYTES};
    let gops = [(8e6, 60.0, 30u32, 8.0), (2e6, 5.0, 5, 8.0), (1e6, 60.0, 1, 1.0), (3.3e6, 59.94, 12, 5.5), (8e6, 10.0, 10, 8.0)];
    let script = format!(
        r#"
import json, typing, iceoryx2, netfi_iox as n, netfi_iox.video as v
l = n.video_header_layout()
l["iceoryx2_type_name"] = iceoryx2.get_type_name(n.VideoHeader)
l["flags"] = [n.FLAG_VIDEO_END, n.FLAG_KEY]
l["limits"] = [v.VIDEO_BUFFER_FRAMES, v.VIDEO_HELD_FRAMES, v.VIDEO_INITIAL_SLICE_BYTES, v.DEFAULT_VIDEO_MAX_BYTES, list(v.channel_limits("video")), list(v.channel_limits("video_out"))]
l["payload"] = iceoryx2.get_type_name(typing.get_args(v.VIDEO_PAYLOAD)[0])
l["gops"] = [[g.key_bytes, g.delta_bytes] for g in (n.Gop(*p) for p in {gops})]
print(json.dumps(l))
"#,
        gops = serde_json::to_string(&gops.iter().map(|g| serde_json::json!([g.0, g.1, g.2, g.3])).collect::<Vec<_>>()).unwrap()
    );
    let l = python_json(&script, "python3 netfi_iox.video_header_layout");
    assert_layout::<VideoHeader>(
        &l,
        VideoHeader::TYPE_NAME,
        offsets!(VideoHeader: send_ns, frame_index, ingress_index, ingress_ns, release_sched_ns, release_ns, len, flags, gop_index, _reserved),
    );
    // SAFETY: type_name only returns the #[type_name] attribute's string.
    assert_eq!(l["payload"], unsafe { <u8 as iceoryx2::prelude::ZeroCopySend>::type_name() });
    assert_eq!(l["flags"], serde_json::json!([VideoHeader::FLAG_END, VideoHeader::FLAG_KEY]));
    assert_eq!(
        l["limits"],
        serde_json::json!([
            VIDEO_BUFFER_FRAMES,
            VIDEO_HELD_FRAMES,
            VIDEO_INITIAL_SLICE_BYTES,
            DEFAULT_VIDEO_MAX_BYTES,
            [1, VIDEO_HELD_FRAMES],
            [netfi::transport::MAX_SUBSCRIBERS_PER_CHANNEL, 1]
        ])
    );
    for (g, py) in gops.iter().zip(l["gops"].as_array().unwrap()) {
        let rust = netfi::video::Gop::new(g.0, g.1, g.2, g.3).unwrap();
        assert_eq!(py, &serde_json::json!([rust.key_bytes, rust.delta_bytes]), "{g:?}");
    }
}

/// A child's stderr, read on a thread of its own: waits for a line that
/// starts with `prefix`, and keeps draining after it.
fn wait_for_line(child: &mut Child, prefix: &str) {
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufRead::lines(std::io::BufReader::new(stderr)).map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut seen = Vec::new();
    loop {
        match rx.recv_timeout(Duration::from_secs(60)) {
            Ok(l) if l.starts_with(prefix) => return,
            Ok(l) => seen.push(l),
            Err(e) => panic!("no line `{prefix}…` ({e}); stderr so far:\n{}", seen.join("\n")),
        }
    }
}

/// The rows of a `video_received.csv`-shaped file, by column name.
fn video_rows(path: &Path) -> Vec<std::collections::BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    assert_eq!(header.join(","), netfi::video::RECEIVED_CSV_HEADER, "{}", path.display());
    lines.map(|l| header.iter().cloned().zip(l.split(',').map(String::from)).collect()).collect()
}

/// The Python camera → netfi emulator (video path, Normal) → the Python
/// viewer and netfi's console, side by side on `video_out`: every frame
/// the camera sent entered, was released, and reached both whole; both
/// recorded the same header of each frame; Rust checked the Python
/// camera's bytes, Python the Rust emulator's copy.
#[test]
fn the_python_camera_through_the_emulator_to_the_python_viewer_and_netfis_console() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("video-py") else { return };
    let viewer = run.python_viewer("60");
    let video = ["--video-mbps", "2", "--video-hz", "60", "--video-gop", "30"];
    let emu = run.emulator("Normal", &[&["--seed", "1", "--no-feedback"][..], &video].concat());
    // netfi's console drives the forward stream (until told to stop) and
    // receives the video too; it has subscribed once it streams.
    let mut console = netfi()
        .args(["console", "--run-id", &run.id, "--duration-s", "600", "--rate-hz", "1000", "--no-direct", "--seed", "2"])
        .args(video)
        .arg("--out")
        .arg(&run.out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_line(&mut console, "console: ");
    let console = Witness(Some(console));
    let mut camera = python("examples/camera.py", &run);
    camera.args(["--run-id", &run.id, "--mbps", "2", "--hz", "60", "--gop", "30", "--frames", "90", "--out"]).arg(run.out.join("camera.json"));
    run_ok(camera, "python camera");
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(console.0.as_ref().unwrap().id() as i32, libc::SIGINT) }, 0);
    console.finish("netfi console", Duration::from_secs(60));
    emu.finish("emulator", Duration::from_secs(60));
    viewer.finish("viewer", Duration::from_secs(60));
    let (cam, e, w, c) = (run.json("camera.json"), run.json("emulator.json"), run.json("viewer.json"), run.json("console.json"));
    assert_eq!((u(&cam["frames_sent"]), u(&cam["send_errors"]), u(&cam["sent_unsubscribed"])), (90, 0, 0), "{cam}");
    let ev = &e["video"];
    assert_eq!((u(&ev["sent_by_camera"]), u(&ev["entered"]), u(&ev["delivered"])), (90, 90, 90), "{ev:#}");
    assert_eq!((u(&ev["delivered_unsubscribed"]), u(&ev["held_at_end"])), (0, 0), "{ev:#}");
    assert_eq!(ev["balanced"], true);
    assert_eq!(u(&ev["bytes_entered"]), u(&cam["bytes_sent"]));
    // The Python viewer: every frame the emulator released, whole, in order.
    assert_eq!((u(&w["received"]), u(&w["whole"]), u(&w["damaged"]), u(&w["late"])), (90, 90, 0, 0), "{w}");
    assert_eq!(u(&w["released_by_emulator"]), 90, "{w}");
    assert_eq!((&w["balanced"], &w["indices_increasing"], &w["ended_by"]), (&Value::Bool(true), &Value::Bool(true), &Value::from("end_marker")), "{w}");
    assert_eq!((u(&w["key_frames"]), u(&w["last_frame_index"]), u(&w["bytes"])), (3, 89, u(&cam["bytes_sent"])), "{w}");
    assert_eq!(u(&w["delay_ms"]["count"]), 90);
    // netfi's console: the Python camera's bytes are whole to Rust too.
    let cv = &c["video"];
    assert_eq!((u(&cv["received"]), u(&cv["whole"]), u(&cv["damaged"])), (90, 90, 0), "{cv:#}");
    assert_eq!(cv["released_by_emulator"], 90);
    assert_eq!(c["ended_by"], "signal");
    // Both records: one row per frame, 0 … 89, the same header of each.
    let (rs, py) = (video_rows(&run.out.join("video_received.csv")), video_rows(&run.out.join("viewer.csv")));
    assert_eq!((rs.len(), py.len()), (90, 90));
    for (k, (a, b)) in rs.iter().zip(&py).enumerate() {
        assert_eq!(a["frame_index"], k.to_string());
        for col in ["frame_index", "gop_index", "key", "len", "bytes", "send_ns", "ingress_index", "ingress_ns", "release_sched_ns", "release_ns", "fate"] {
            assert_eq!(a[col], b[col], "frame {k}, {col}");
        }
        assert_eq!(a["key"] == "1", k % 30 == 0, "frame {k}");
    }
}

/// netfi's camera (in netfi's simulator) → netfi emulator → the Python
/// viewer: every frame the Rust camera sent reaches the Python viewer
/// whole, its sizes the Rust camera's group of pictures.
#[test]
fn netfis_camera_through_the_emulator_to_the_python_viewer() {
    let _guard = machine::alone();
    let Some(run) = Run::ready("video-rs") else { return };
    let viewer = run.python_viewer("60");
    let video = ["--video-mbps", "4", "--video-hz", "60", "--video-gop", "30"];
    let sim = run.simulator(&video);
    let emu = run.emulator("Normal", &[&["--seed", "1"][..], &video].concat());
    let mut console = netfi();
    console.args(["console", "--run-id", &run.id, "--frames", "2000", "--rate-hz", "1000", "--seed", "2", "--out"]).arg(&run.out);
    run_ok(console, "netfi console");
    emu.finish("emulator", Duration::from_secs(60));
    sim.finish("simulator", Duration::from_secs(60));
    viewer.finish("viewer", Duration::from_secs(60));
    let (s, e, w) = (run.json("simulator.json"), run.json("emulator.json"), run.json("viewer.json"));
    let cam = &s["camera"];
    let sent = u(&cam["frames_sent"]);
    assert!(sent >= 60, "the camera ran while 2000 commands went through: {cam}");
    assert_eq!((u(&cam["send_errors"]), u(&cam["sent_unsubscribed"])), (0, 0), "{cam}");
    let ev = &e["video"];
    assert_eq!((u(&ev["sent_by_camera"]), u(&ev["entered"]), u(&ev["delivered"])), (sent, sent, sent), "{ev:#}");
    assert_eq!(ev["balanced"], true);
    assert_eq!((u(&w["received"]), u(&w["whole"]), u(&w["damaged"]), u(&w["late"])), (sent, sent, 0, 0), "{w}");
    assert_eq!(u(&w["released_by_emulator"]), sent, "{w}");
    assert_eq!((&w["indices_increasing"], &w["ended_by"]), (&Value::Bool(true), &Value::from("end_marker")), "{w}");
    assert_eq!(u(&w["key_frames"]), sent.div_ceil(30), "{w}");
    assert_eq!(u(&w["bytes"]), u(&cam["bytes_sent"]), "{w}");
    let rows = video_rows(&run.out.join("viewer.csv"));
    assert_eq!(rows.len() as u64, sent);
    for (k, r) in rows.iter().enumerate() {
        let len = if k % 30 == 0 { &cam["key_bytes"] } else { &cam["delta_bytes"] };
        assert_eq!((r["frame_index"].as_str(), r["len"].as_str(), r["fate"].as_str()), (k.to_string().as_str(), len.to_string().as_str(), "whole"), "{r:?}");
    }
}

/// `netfi_iox.capture` reads a capture written in batches (one LZ4 frame
/// per 1 000 records, as the study's recorder writes them) as every record
/// of it, and refuses garbage after or between its frames; the shipped
/// recording re-packed so (when present) reads as its 41 508 records.
#[test]
fn the_python_capture_reader_reads_every_frame_and_refuses_garbage() {
    if !python_ready() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("netfi-py-capture-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, records: &[netfi::capture::CaptureRecord]| {
        let path = dir.join(name);
        let mut w = netfi::capture::CaptureWriter::create(&path).unwrap();
        for (i, r) in records.iter().enumerate() {
            if i > 0 && i % 1_000 == 0 {
                w.end_frame().unwrap();
            }
            w.write_record(r).unwrap();
        }
        w.finish().unwrap();
        path
    };
    let records: Vec<_> = (0..2_500u32)
        .map(|i| {
            let f = netfi::frame::ItpFrame { sequence: i, delx: [1, -1], qw: [1.0, 1.0], surgeon_mode: 1, ..Default::default() };
            netfi::capture::CaptureRecord::new(u64::from(i) * 2_000_000, &f.with_checksum())
        })
        .collect();
    let load = |path: &Path| {
        python_c("import sys; from netfi_iox import capture; r = capture.load(sys.argv[1]); print(len(r), r[-1][0])").arg(path).output().unwrap()
    };
    let batched = write("batched.bin", &records);
    let o = load(&batched);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), format!("2500 {}", 2_499u64 * 2_000_000));
    let bytes = std::fs::read(&batched).unwrap();
    let first = std::fs::read(write("first.bin", &records[..1_000])).unwrap().len();
    for (name, bad) in [("after", [&bytes[..], &b"junk"[..]].concat()), ("between", [&bytes[..first], &b"junk"[..], &bytes[first..]].concat())] {
        let path = dir.join(name);
        std::fs::write(&path, bad).unwrap();
        let o = load(&path);
        assert!(!o.status.success(), "garbage {name} accepted: {}", String::from_utf8_lossy(&o.stdout));
        assert!(String::from_utf8_lossy(&o.stderr).contains("that are not an LZ4 frame"), "{name}: {}", String::from_utf8_lossy(&o.stderr));
    }
    if let Some(real) = crate::common::data::shipped_capture() {
        let cap = netfi::capture::load(&real).unwrap();
        let o = load(&write("real.bin", &cap.records));
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(String::from_utf8_lossy(&o.stdout).starts_with("41508 "), "{}", String::from_utf8_lossy(&o.stdout));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A console and a robot written from docs/interface.md alone
/// (`tests/python/doc_client.py`: iceoryx2's bindings and ctypes, nothing
/// of netfi's Python module) take part in a run of the stand-alone
/// emulator: every frame is accounted for, the robot receives exactly what
/// the emulator released and the fates the scenario gives the seed, the
/// run's management segment is private to the user, and the last process
/// to close (the robot, held open until the others have gone) removes it.
#[test]
fn a_client_written_from_the_document_alone_takes_part_in_a_run() {
    if !python_ready() {
        return;
    }
    let script = root().join("tests/python/doc_client.py");
    let text = std::fs::read_to_string(&script).unwrap();
    assert!(!text.contains("import netfi_iox") && !text.contains("from netfi_iox"), "the client imports netfi's module");
    let _guard = machine::alone();
    let run = Run::new("doc");
    assert_eq!(rust_layout(&run.config), "per-user", "the document's layout is per-user");
    let doc = |args: &[&str]| {
        let mut c = Command::new("python3");
        c.arg(&script).args(args).env_remove("PYTHONPATH");
        c
    };
    let path = |name: &str| run.out.join(name).to_str().unwrap().to_owned();
    let robot = doc(&["robot", &run.id, &path("robot.json"), &path("robot.ready"), &path("robot.close")])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let robot = Witness(Some(robot));
    wait_file(&run.out.join("robot.ready"));
    let emu = run.emulator("PLM-2", &["--seed", "3", "--expected-frames", "3000"]);
    run_ok(doc(&["console", &run.id, "3000", &path("console.json")]), "the document's console");
    emu.finish("emulator", Duration::from_secs(60));
    std::fs::write(run.out.join("robot.close"), "").unwrap();
    robot.finish("the document's robot", Duration::from_secs(60));
    let (c, e, r) = (run.json("console.json"), run.json("emulator.json"), run.json("robot.json"));
    assert_eq!((u(&c["sent"]), u(&c["unsubscribed"])), (3000, 0), "{c}");
    assert_emulator_balanced(&e, 3000);
    let delivered = u(&e["frames"]["delivered"]);
    assert_eq!((u(&r["received"]), u(&r["marker"]), u(&r["bad"])), (delivered, delivered, 0), "{r}");
    let check = netfi().args(["scenario", "check", "PLM-2", "--frames", "3000", "--seed", "3", "--json"]).output().unwrap();
    let check: Value = serde_json::from_slice(&check.stdout).unwrap();
    assert_eq!(check["delivered"].as_u64(), Some(delivered));
    assert_eq!(r["mgmt_modes"], serde_json::json!(["0o600"]), "{r}");
    assert_eq!(r["removed_segment"], true, "{r}");
    let prefix = run.config.prefix().to_string();
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with(&prefix))
        .collect();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
}

/// The configuration table of docs/interface.md, key by key, is this
/// build's: what a client written from the document sets is what netfi's
/// processes set.
#[test]
fn the_documents_configuration_table_is_the_rust_one() {
    let doc = std::fs::read_to_string(root().join("docs/interface.md")).unwrap();
    let rows: std::collections::BTreeMap<String, String> = doc
        .lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let key = cells.get(1)?.strip_prefix("`defaults.publish_subscribe.")?.strip_suffix('`')?;
            let value = cells.get(2)?.split_whitespace().next()?.trim_matches('`');
            Some((key.to_string(), value.to_string()))
        })
        .collect();
    let config = IpcConfig::new(RunId::new("doc-table").unwrap());
    let ps = &config.iceoryx2().defaults.publish_subscribe;
    let rust: std::collections::BTreeMap<String, String> = [
        ("max_publishers", ps.max_publishers.to_string()),
        ("max_subscribers", ps.max_subscribers.to_string()),
        ("max_nodes", ps.max_nodes.to_string()),
        ("subscriber_max_buffer_size", ps.subscriber_max_buffer_size.to_string()),
        ("subscriber_max_borrowed_samples", ps.subscriber_max_borrowed_samples.to_string()),
        ("publisher_max_loaned_samples", ps.publisher_max_loaned_samples.to_string()),
        ("publisher_history_size", ps.publisher_history_size.to_string()),
        ("enable_safe_overflow", ps.enable_safe_overflow.to_string()),
        ("backpressure_strategy", format!("{:?}", ps.backpressure_strategy)),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    assert_eq!(rows, rust);
    let g = &config.iceoryx2().global;
    assert!(!g.node.cleanup_dead_nodes_on_creation && !g.node.cleanup_dead_nodes_on_destruction && !g.service.cleanup_dead_nodes_on_open);
}
