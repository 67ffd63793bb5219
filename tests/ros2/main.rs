//! ROS 2 topics through the emulator, with real ROS 2 nodes: rclpy
//! publishers and subscribers (`talker.py`, `listener.py`, with Fast DDS,
//! ROS 2's default middleware) on either side of `netfi emulator
//! --ros2-topic`. Each test runs in a ROS 2 domain of its own (and the
//! one across hosts in network namespaces of its own), so tests and runs
//! do not see each other.
//!
//! Needs a Python with rclpy and Fast DDS (`pip install ros-rclpy==9.1.2
//! ros-std-msgs ros-geometry-msgs ros-rmw-fastrtps-cpp`), named by
//! `NETFI_ROS2_PYTHON` (default `python3`). Without it each test says so and
//! passes, unless `NETFI_REQUIRE_ROS2` is set (as `.ci/run` does), where its
//! absence fails.
//!
//! The runs are serialized: each has a busy-waiting emulator.
//!
//! The rclpy nodes use Fast DDS's UDP transport only
//! ([`FASTDDS_UDP_ONLY`]): its default adds a shared-memory transport whose
//! segments (`/dev/shm/fastdds_*`, `/dev/shm/sem.fastdds_*`) a node that is
//! killed, as some of these tests kill them, leaves behind. Each test checks
//! at its end that its nodes left no such file.

mod bag;
mod edges;
mod hosts;
mod motion;
mod relay;
mod study;

use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU16, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

static ONE_RUN_AT_A_TIME: Mutex<()> = Mutex::new(());

/// For every process a test starts: Fast DDS (the rclpy nodes' middleware)
/// with its UDP transport only, without the shared-memory one it adds by
/// default, whose files outlive a killed node. The emulator (RustDDS)
/// speaks UDP only anyway.
pub(crate) const FASTDDS_UDP_ONLY: (&str, &str) = ("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4");

/// The names of Fast DDS's shared-memory files in /dev/shm now.
fn fastdds_shm() -> BTreeSet<String> {
    std::fs::read_dir("/dev/shm")
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with("fastdds_") || n.starts_with("sem.fastdds_"))
        .collect()
}

pub(crate) fn here() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/ros2")
}

#[path = "../common/netfi.rs"]
#[allow(dead_code)]
mod netfi_cmd;
pub(crate) use netfi_cmd::{emulator_pin, netfi};

pub(crate) fn u(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not a count: {v}"))
}

/// The Python with rclpy, if there is one; says why not where there is not
/// (and fails where `NETFI_REQUIRE_ROS2` is set).
pub(crate) fn python() -> Option<PathBuf> {
    let py = std::env::var_os("NETFI_ROS2_PYTHON").map_or_else(|| PathBuf::from("python3"), PathBuf::from);
    // rclpy alone imports without a middleware; a node needs one.
    let probe = "import rclpy, std_msgs.msg, geometry_msgs.msg, sensor_msgs.msg; rclpy.init(); rclpy.create_node('probe'); rclpy.shutdown()";
    let o = Command::new(&py).args(["-c", probe]).env("ROS_DOMAIN_ID", "231").env(FASTDDS_UDP_ONLY.0, FASTDDS_UDP_ONLY.1).output();
    let why = match o {
        Ok(o) if o.status.success() => return Some(py),
        Ok(o) => String::from_utf8_lossy(&o.stderr).trim().lines().last().unwrap_or_default().to_string(),
        Err(e) => format!("{}: {e}", py.display()),
    };
    let install = "pip install ros-rclpy==9.1.2 ros-std-msgs ros-geometry-msgs ros-sensor-msgs ros-rmw-fastrtps-cpp, and name that Python in NETFI_ROS2_PYTHON";
    assert!(std::env::var_os("NETFI_REQUIRE_ROS2").is_none(), "NETFI_REQUIRE_ROS2 is set but {} cannot run an rclpy node: {why}; {install}", py.display());
    eprintln!("skipping: {} cannot run an rclpy node ({why}); {install}", py.display());
    None
}

/// A ROS 2 domain no other test (or run of these tests) uses.
fn domain() -> u16 {
    static NEXT: AtomicU16 = AtomicU16::new(0);
    let k = NEXT.fetch_add(1, Ordering::Relaxed);
    1 + ((std::process::id() as u16).wrapping_mul(13).wrapping_add(k) % 230)
}

/// A process killed when dropped.
pub(crate) struct Proc {
    pub(crate) child: Child,
    name: String,
    log: PathBuf,
}

impl Proc {
    /// Waits up to `timeout` for it to end by itself.
    pub(crate) fn wait(&mut self, timeout: Duration) -> ExitStatus {
        let t0 = Instant::now();
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s;
            }
            if t0.elapsed() > timeout {
                let _ = self.child.kill();
                panic!("{} did not end within {timeout:?}; its log:\n{}", self.name, self.log());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    pub(crate) fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Waits for it to end by itself, successfully.
    pub(crate) fn done(&mut self) {
        let s = self.wait(Duration::from_secs(120));
        assert!(s.success(), "{} failed ({s}):\n{}", self.name, self.log());
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One test's run: its directory, its domain, its Python.
pub(crate) struct Case {
    pub(crate) dir: PathBuf,
    pub(crate) domain: u16,
    py: PathBuf,
    /// Runs the nodes and the emulator in this network namespace, if any.
    netns: Option<String>,
    /// Fast DDS's shared-memory files before the test's nodes started.
    shm_before: BTreeSet<String>,
    /// The runs are one at a time; held for the case's life.
    _one: MutexGuard<'static, ()>,
}

/// At the test's end (its processes, made before the case, are gone): the
/// test's nodes left no shared-memory file. The tests run one at a time,
/// so a file that came meanwhile is theirs.
impl Drop for Case {
    fn drop(&mut self) {
        if std::thread::panicking() {
            return;
        }
        let left: Vec<String> = fastdds_shm().difference(&self.shm_before).cloned().collect();
        assert!(left.is_empty(), "the nodes left Fast DDS shared-memory files in /dev/shm: {left:?}");
    }
}

impl Case {
    /// The case `name`, once no other runs; `None` (the test passes, saying
    /// why) where there is no rclpy to run its nodes with.
    pub(crate) fn start(name: &str) -> Option<Case> {
        let py = python()?;
        let one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        let dir = std::env::temp_dir().join(format!("netfi-ros2-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Some(Case { dir, domain: domain(), py, netns: None, shm_before: fastdds_shm(), _one: one })
    }

    /// Waits for each of `procs` to end successfully, in order; then
    /// `emulator.json`, whose account must close.
    pub(crate) fn finish(&self, procs: &mut [&mut Proc]) -> Value {
        for p in procs {
            p.done();
        }
        let e = self.json("emulator.json");
        assert_balanced(&e["frames"]);
        assert_off_the_loops_core(&e);
        e
    }

    fn command(&self, netns: Option<&str>, program: &Path) -> Command {
        match netns.or(self.netns.as_deref()) {
            Some(ns) => {
                let mut c = Command::new("ip");
                c.args(["netns", "exec", ns]).arg(program);
                c
            }
            None => Command::new(program),
        }
    }

    pub(crate) fn spawn(&self, mut c: Command, name: &str) -> Proc {
        let log = self.dir.join(format!("{name}.log"));
        let f = std::fs::File::create(&log).unwrap();
        c.env("ROS_DOMAIN_ID", self.domain.to_string()).env(FASTDDS_UDP_ONLY.0, FASTDDS_UDP_ONLY.1).stdout(f.try_clone().unwrap()).stderr(f).stdin(Stdio::null());
        Proc { child: c.spawn().unwrap_or_else(|e| panic!("starting {name}: {e}")), name: name.to_string(), log }
    }

    /// `script` (talker.py, listener.py) as node `name`, with `args`, in
    /// network namespace `netns` if given.
    pub(crate) fn node_in(&self, netns: Option<&str>, script: &str, name: &str, args: &[&str], env: &[(&str, &Path)]) -> Proc {
        let mut c = self.command(netns, &self.py);
        c.current_dir(here()).arg(here().join(script)).args(args).args(["--name", name]);
        for (k, v) in env {
            c.env(k, v);
        }
        self.spawn(c, name)
    }

    pub(crate) fn node(&self, script: &str, name: &str, args: &[&str]) -> Proc {
        self.node_in(None, script, name, args, &[])
    }

    /// A listener of `topic` writing `<name>.csv`, subscribed when this
    /// returns.
    pub(crate) fn listener_in(&self, netns: Option<&str>, name: &str, topic: &str, extra: &[&str]) -> Proc {
        let ready = self.dir.join(format!("{name}.ready"));
        let csv = self.dir.join(format!("{name}.csv"));
        let mut args = vec![topic, csv.to_str().unwrap(), "--ready", ready.to_str().unwrap()];
        args.extend_from_slice(extra);
        let mut p = self.node_in(netns, "listener.py", name, &args, &[]);
        wait_file(&ready, &mut p);
        p
    }

    pub(crate) fn listener(&self, name: &str, topic: &str, extra: &[&str]) -> Proc {
        self.listener_in(None, name, topic, extra)
    }

    /// `netfi emulator` in this case's domain and directory with `args`.
    pub(crate) fn emulator_in(&self, netns: Option<&str>, args: &[&str]) -> Proc {
        let pin = emulator_pin();
        let mut c = self.command(netns, Path::new(env!("CARGO_BIN_EXE_netfi")));
        c.arg("emulator").args(["--ros2-domain", &self.domain.to_string(), "--out"]).arg(self.dir.join("out")).args(&pin).args(args);
        if !args.contains(&"--ros2-linger-ms") {
            c.args(["--ros2-linger-ms", "500"]);
        }
        self.spawn(c, "emulator")
    }

    pub(crate) fn emulator(&self, args: &[&str]) -> Proc {
        self.emulator_in(None, args)
    }

    pub(crate) fn json(&self, file: &str) -> Value {
        let p = self.dir.join("out").join(file);
        serde_json::from_slice(&std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).unwrap()
    }

    /// The rows of a listener's CSV.
    pub(crate) fn received(&self, name: &str) -> Vec<Received> {
        rows(&self.dir.join(format!("{name}.csv")))
            .into_iter()
            .map(|r| Received { index: r["index"].parse().unwrap(), source_ns: r["source_ns"].parse().unwrap(), received_ns: r["received_ns"].parse().unwrap() })
            .collect()
    }

    /// `netfi scenario check`'s fate of each of `n` messages of `scenario`
    /// with `seed`, in simulated time, by ingress index.
    pub(crate) fn check_fates(&self, scenario: &str, n: usize, seed: u64) -> Vec<String> {
        self.check_rows(scenario, n, seed).iter().map(|r| r["fate"].clone()).collect()
    }

    /// `netfi scenario check`'s trace of `n` messages of `scenario` with
    /// `seed`, in simulated time, by ingress index.
    pub(crate) fn check_rows(&self, scenario: &str, n: usize, seed: u64) -> Vec<BTreeMap<String, String>> {
        let trace = self.dir.join(format!("check-{scenario}-{seed}.csv"));
        let o = netfi().args(["scenario", "check", scenario, "--frames", &n.to_string(), "--seed", &seed.to_string(), "--json", "--trace"]).arg(&trace).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        rows(&trace)
    }
}

/// A message a listener received.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Received {
    pub(crate) index: u64,
    pub(crate) source_ns: i64,
    pub(crate) received_ns: i64,
}

/// A CSV file's rows, by column name.
pub(crate) fn rows(path: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let head: Vec<String> = lines.next().unwrap_or_default().split(',').map(str::to_string).collect();
    lines.map(|l| head.iter().cloned().zip(l.split(',').map(str::to_string)).collect()).collect()
}

pub(crate) fn wait_file(path: &Path, p: &mut Proc) {
    let t0 = Instant::now();
    while !path.exists() {
        if let Some(s) = p.child.try_wait().unwrap() {
            panic!("{} ended ({s}) before {}:\n{}", p.name, path.display(), p.log());
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "no {} within 60 s:\n{}", path.display(), p.log());
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The emulator's trace, by ingress index.
pub(crate) fn trace(case: &Case, file: &str) -> Vec<BTreeMap<String, String>> {
    let mut t = rows(&case.dir.join("out").join(file));
    t.sort_by_key(|r| r["ingress_index"].parse::<u64>().unwrap());
    t
}

/// The index a message carried (the talker's count, from 0): its DDS
/// sequence number less one, for a talker that starts at 0.
pub(crate) fn index(row: &BTreeMap<String, String>) -> u64 {
    row["console_index"].parse::<u64>().unwrap() - 1
}

/// The account of `r` (a path's report, or `emulator.json`'s `frames`)
/// closes, and the report says so (its `balanced`: the channel's own
/// counts agree).
pub(crate) fn assert_balanced(r: &Value) {
    assert_eq!(r["balanced"], true, "{r:#}");
    let dropped: u64 = r["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&r["entered"]) + u(&r["duplicated"]), u(&r["delivered"]) + dropped + u(&r["held_at_end"]), "{r:#}");
}

/// The loss of `r` is its model's: the model's rate inside the report's
/// 95% interval.
pub(crate) fn assert_loss_is_the_models(e: &Value) {
    let exact = e["stages"][0]["loss_rate_model"].as_f64().unwrap();
    let [lo, hi] = [e["loss_rate_ci95"][0].as_f64().unwrap(), e["loss_rate_ci95"][1].as_f64().unwrap()];
    // The interval is the batch means' 95%: the model falls outside it with
    // probability 0.05; twice its half width (about 3.9 standard errors,
    // α ≈ 1e-4) keeps the test from failing one run in twenty.
    let (mid, half) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
    assert!((exact - mid).abs() <= 2.0 * half, "model {exact} outside twice the 95% interval [{lo}, {hi}]");
}

/// Every message the emulator delivered reached `listener`, in the order
/// it released them, and nothing else did.
pub(crate) fn assert_listener_got_what_was_delivered(t: &[BTreeMap<String, String>], got: &[Received]) {
    let mut delivered: Vec<&BTreeMap<String, String>> = t.iter().filter(|r| r["fate"] == "delivered").collect();
    delivered.sort_by_key(|r| r["release_ns"].parse::<u64>().unwrap());
    let want: Vec<u64> = delivered.iter().map(|r| index(r)).collect();
    let have: Vec<u64> = got.iter().map(|r| r.index).collect();
    assert_eq!(have, want, "the listener got the delivered messages, in release order");
}

/// A pinned emulator's other threads, RustDDS's among them, are listed in
/// `emulator.json` and none may run on the loop's core.
fn assert_off_the_loops_core(e: &Value) {
    let Some(core) = e["core"].as_u64() else { return };
    let threads = e["threads"].as_array().unwrap_or_else(|| panic!("no threads listed: {e}"));
    assert!(threads.iter().any(|t| t["name"].as_str().is_some_and(|n| n.starts_with("RustDDS"))), "RustDDS's threads not listed: {threads:?}");
    for t in threads {
        let cpus = netfi::host::isolate::parse_list(t["cpus"].as_str().unwrap()).unwrap();
        assert!(!cpus.contains(&(core as usize)), "{t} may run on the loop's core {core}");
    }
}
