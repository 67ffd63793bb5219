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

mod hosts;

use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU16, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

pub(crate) static ONE_RUN_AT_A_TIME: Mutex<()> = Mutex::new(());

fn here() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/ros2")
}

fn netfi() -> Command {
    Command::new(env!("CARGO_BIN_EXE_netfi"))
}

pub(crate) fn u(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not a count: {v}"))
}

/// The Python with rclpy, if there is one; says why not where there is not
/// (and fails where `NETFI_REQUIRE_ROS2` is set).
pub(crate) fn python() -> Option<PathBuf> {
    let py = std::env::var_os("NETFI_ROS2_PYTHON").map_or_else(|| PathBuf::from("python3"), PathBuf::from);
    // rclpy alone imports without a middleware; a node needs one.
    let probe = "import rclpy, std_msgs.msg, geometry_msgs.msg; rclpy.init(); rclpy.create_node('probe'); rclpy.shutdown()";
    let o = Command::new(&py).args(["-c", probe]).env("ROS_DOMAIN_ID", "231").output();
    let why = match o {
        Ok(o) if o.status.success() => return Some(py),
        Ok(o) => String::from_utf8_lossy(&o.stderr).trim().lines().last().unwrap_or_default().to_string(),
        Err(e) => format!("{}: {e}", py.display()),
    };
    let install = "pip install ros-rclpy==9.1.2 ros-std-msgs ros-geometry-msgs ros-rmw-fastrtps-cpp, and name that Python in NETFI_ROS2_PYTHON";
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
}

impl Case {
    pub(crate) fn new(name: &str, py: PathBuf) -> Case {
        let dir = std::env::temp_dir().join(format!("netfi-ros2-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Case { dir, domain: domain(), py, netns: None }
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

    fn spawn(&self, mut c: Command, name: &str) -> Proc {
        let log = self.dir.join(format!("{name}.log"));
        let f = std::fs::File::create(&log).unwrap();
        c.env("ROS_DOMAIN_ID", self.domain.to_string()).stdout(f.try_clone().unwrap()).stderr(f).stdin(Stdio::null());
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
        let cores = core_affinity::get_core_ids().map_or(1, |c| c.len());
        let pin: Vec<String> = if cores >= 2 { vec!["--core".into(), (cores - 1).to_string()] } else { vec!["--no-pin".into()] };
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
        let trace = self.dir.join(format!("check-{scenario}-{seed}.csv"));
        let o = netfi().args(["scenario", "check", scenario, "--frames", &n.to_string(), "--seed", &seed.to_string(), "--json", "--trace"]).arg(&trace).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        rows(&trace).iter().map(|r| r["fate"].clone()).collect()
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
/// closes, and, where the report says, the channel's own counts agree.
pub(crate) fn assert_balanced(r: &Value) {
    if let Some(b) = r.get("balanced") {
        assert_eq!(b, true, "{r:#}");
    }
    let dropped: u64 = r["dropped"].as_object().unwrap().values().map(u).sum();
    assert_eq!(u(&r["entered"]) + u(&r["duplicated"]), u(&r["delivered"]) + dropped + u(&r["held_at_end"]), "{r:#}");
}

/// The loss of `r` is its model's: the model's rate inside the report's
/// 95% interval.
fn assert_loss_is_the_models(e: &Value) {
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
fn assert_listener_got_what_was_delivered(t: &[BTreeMap<String, String>], got: &[Received]) {
    let mut delivered: Vec<&BTreeMap<String, String>> = t.iter().filter(|r| r["fate"] == "delivered").collect();
    delivered.sort_by_key(|r| r["release_ns"].parse::<u64>().unwrap());
    let want: Vec<u64> = delivered.iter().map(|r| index(r)).collect();
    let have: Vec<u64> = got.iter().map(|r| r.index).collect();
    assert_eq!(have, want, "the listener got the delivered messages, in release order");
}

#[test]
fn plm2_drops_exactly_what_scenario_check_drops_and_the_listener_gets_the_rest() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("plm2", py);
    const N: usize = 1500;
    let mut listener = c.listener("listener", "/chatter_out", &[]);
    let mut talker = c.node("talker.py", "talker", &["/chatter", &N.to_string(), "--rate-hz", "500"]);
    let mut emu = c.emulator(&["--scenario", "PLM-2", "--seed", "3", "--ros2-topic", "/chatter=/chatter_out"]);
    talker.done();
    emu.done();
    listener.done();
    let e = c.json("emulator.json");
    let f = &e["frames"];
    assert_balanced(f);
    assert_eq!((u(&f["entered"]), u(&f["sent_by_console"])), (N as u64, N as u64), "every message entered: {f:#}");
    assert_eq!(u(&f["held_at_end"]), 0);
    let r = c.json("ros2.json");
    assert_eq!(r["balanced"], true);
    assert_eq!(r["forward"]["type"], "std_msgs/msg/String");
    assert!(r["forward"]["motion"].is_null(), "a String is no kinematic type");
    assert_eq!(r["forward"]["type_from"], "publisher");
    assert_eq!(r["forward"]["lost_before_ingress"], 0);
    assert_eq!(r["forward"]["ended"]["reason"], "publishers_gone");
    // ge_lomax decides per message: with every message entered, the very
    // fates `scenario check` gives in simulated time, message for message.
    let t = trace(&c, "trace_emulator.csv");
    let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
    assert_eq!(fates, c.check_fates("PLM-2", N, 3));
    assert!(t.iter().enumerate().all(|(k, r)| index(r) == k as u64), "messages entered in the talker's order");
    assert_listener_got_what_was_delivered(&t, &c.received("listener"));
    assert_loss_is_the_models(&e);
}

#[test]
fn dlm1_delays_seen_by_the_listener_are_the_injected_ones() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("dlm1", py);
    const N: usize = 600;
    let mut listener = c.listener("listener", "/PSM1/servo_cp", &["--type", "pose"]);
    let mut talker = c.node("talker.py", "talker", &["/MTMR/measured_cp", &N.to_string(), "--rate-hz", "200", "--type", "pose"]);
    let mut emu = c.emulator(&["--scenario", "DLM-1", "--seed", "5", "--ros2-topic", "/MTMR/measured_cp=/PSM1/servo_cp"]);
    talker.done();
    emu.done();
    listener.done();
    let e = c.json("emulator.json");
    assert_balanced(&e["frames"]);
    assert_eq!(u(&e["frames"]["delivered"]), N as u64, "DLM-1 drops nothing");
    assert_eq!(c.json("ros2.json")["forward"]["type"], "geometry_msgs/msg/PoseStamped");
    let t = trace(&c, "trace_emulator.csv");
    let got = c.received("listener");
    assert_listener_got_what_was_delivered(&t, &got);
    // What the listener sees of each message (its reception less the
    // talker's source timestamp, which the emulator keeps) is the hop in,
    // the injected delay, the release's lateness and the hop out. Less the
    // hop in (from the trace), it is the injected delay plus what comes
    // after the release: never less than the delay and the lateness.
    let by_index: BTreeMap<u64, &BTreeMap<String, String>> = t.iter().map(|r| (index(r), r)).collect();
    let n = |r: &BTreeMap<String, String>, k: &str| r[k].parse::<i64>().unwrap();
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for m in &got {
        let r = by_index[&m.index];
        let seen = m.received_ns - m.source_ns;
        let hop_in = n(r, "ingress_ns") - n(r, "send_ns");
        let injected = n(r, "release_sched_ns") - n(r, "ingress_ns");
        let late = n(r, "release_ns") - n(r, "release_sched_ns");
        let y = seen - hop_in;
        // The wall clock the timestamps are read on may be slewed by up to
        // 500 ppm against the emulator's monotonic clock: twice that, and
        // a clock read's worth, is the tolerance.
        let tol = y / 1000 + 50_000;
        assert!(y >= injected + late - tol, "message {}: seen {seen} ns (hop in {hop_in}) but injected {injected} ns and {late} ns late", m.index);
        xs.push(injected as f64);
        ys.push(y as f64);
    }
    // And the listener sees the delays one for one: the slope of what it
    // sees against what was injected is 1, within six standard errors of
    // the fit (and the clocks' rates).
    let k = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / k, ys.iter().sum::<f64>() / k);
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let slope = sxy / sxx;
    let resid: f64 = xs.iter().zip(&ys).map(|(x, y)| (y - my - slope * (x - mx)).powi(2)).sum();
    let se = (resid / (k - 2.0) / sxx).sqrt();
    assert!((slope - 1.0).abs() <= 6.0 * se + 1e-3, "slope {slope} ± {se}: the listener does not see the injected delays");
    // DLM-1 reorders: the listener saw that too.
    assert!(got.windows(2).any(|w| w[1].index < w[0].index), "DLM-1 reorders some messages");
    // PoseStamped is read on both sides: the talker's x is its index, so
    // the console's path is N − 1 long; the robot's, in release order, is
    // the sum of the steps between what it got.
    let m = &c.json("ros2.json")["forward"]["motion"];
    assert_eq!(m["kind"], "pose_stamped");
    assert_eq!((u(&m["console"]["messages"]), m["console"]["length"].as_f64()), (N as u64, Some(N as f64 - 1.0)));
    assert_eq!(u(&m["robot"]["messages"]), got.len() as u64);
    let robot_length: u64 = got.windows(2).map(|w| w[1].index.abs_diff(w[0].index)).sum();
    assert_eq!(m["robot"]["length"].as_f64(), Some(robot_length as f64));
    assert!(m["divergence_max"].as_f64().unwrap() >= 1.0, "a delay of 70 ms or more at 200 Hz leaves the robot behind: {m}");
    assert_eq!(u(&m["malformed"]), 0);
}

#[test]
fn the_return_topic_goes_back_through_its_own_scenario() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("return", py);
    const N: usize = 800;
    let mut console_view = c.listener("console_view", "/MTMR/state", &[]);
    let mut robot = c.listener("robot", "/PSM1/servo_cp", &["--type", "pose"]);
    let mut state = c.node("talker.py", "robot_state", &["/PSM1/measured_cp", &N.to_string(), "--rate-hz", "400"]);
    let mut console = c.node("talker.py", "console", &["/MTMR/measured_cp", "200", "--rate-hz", "100", "--type", "pose"]);
    let mut emu = c.emulator(&[
        "--scenario",
        "Normal",
        "--seed",
        "8",
        "--ros2-topic",
        "/MTMR/measured_cp=/PSM1/servo_cp",
        "--ros2-return",
        "/PSM1/measured_cp=/MTMR/state",
        "--return-scenario",
        "PLM-2",
    ]);
    state.done();
    console.done();
    emu.done();
    robot.done();
    console_view.done();
    let e = c.json("emulator.json");
    assert_balanced(&e["frames"]);
    assert_eq!(u(&e["frames"]["delivered"]), 200);
    let r = &e["ros2_return"];
    assert_balanced(r);
    assert_eq!(r["scenario"], "PLM-2");
    assert_eq!((u(&r["entered"]), u(&r["sent_by_robot"]), u(&r["lost_before_ingress"])), (N as u64, N as u64, 0), "{r:#}");
    // The return path's own seed, derived from the lane's: its fates are
    // scenario check's for that seed.
    assert_ne!(u(&r["seed"]), 8);
    let t = trace(&c, "trace_ros2_return.csv");
    let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
    assert_eq!(fates, c.check_fates("PLM-2", N, u(&r["seed"])));
    assert_listener_got_what_was_delivered(&t, &c.received("console_view"));
    assert_eq!(c.received("robot").len(), 200, "the forward topic is untouched (Normal)");
    let ros2 = c.json("ros2.json");
    assert_eq!(ros2["return_path"]["from"], "/PSM1/measured_cp");
    assert_eq!(ros2["return_path"]["to"], "/MTMR/state");
}

#[test]
fn a_killed_publisher_ends_the_run_and_the_report_names_it() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("killed", py);
    let mut listener = c.listener("robot", "/cmd_out", &["--count", "300"]);
    // A talker that stays after its 300 messages until it is killed, with
    // a participant lease of 1 s (Fast DDS's default: 20 s), so that its
    // death is seen soon.
    let ready = c.dir.join("talker.ready");
    let lease = here().join("short_lease.xml");
    let mut talker = c.node_in(None, "talker.py", "console", &["/cmd", "300", "--rate-hz", "300", "--hang", "--linger-s", "0", "--ready", ready.to_str().unwrap()], &[("FASTDDS_DEFAULT_PROFILES_FILE", &lease)]);
    let mut emu = c.emulator(&["--scenario", "Normal", "--seed", "1", "--ros2-topic", "/cmd=/cmd_out"]);
    wait_file(&ready, &mut talker);
    // Its last message is out once it says so.
    let t0 = Instant::now();
    while !talker.log().contains("300 sent") {
        assert!(t0.elapsed() < Duration::from_secs(60), "{}", talker.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    // Its node's name reaches the emulator on Fast DDS's next heartbeat
    // (every 3 s) at the latest.
    std::thread::sleep(Duration::from_millis(3500));
    talker.child.kill().unwrap();
    emu.done();
    let r = c.json("ros2.json");
    let ended = &r["forward"]["ended"];
    assert_eq!(ended["reason"], "publishers_gone", "{r:#}");
    let detail = ended["detail"].as_str().unwrap();
    assert!(detail.contains("/console") && detail.contains("lease_expired"), "{detail}");
    let p = r["forward"]["endpoints"].as_array().unwrap().iter().find(|p| p["role"] == "publisher").expect("the publisher");
    assert_eq!((p["node"].as_str(), p["left"].as_str()), (Some("/console"), Some("lease_expired")));
    let e = c.json("emulator.json");
    assert_balanced(&e["frames"]);
    assert_eq!((u(&e["frames"]["entered"]), u(&e["frames"]["sent_by_console"])), (300, 300));
    assert!(emu.log().contains("the publisher /console of /cmd left (lease_expired)"), "{}", emu.log());
    listener.done();
}

/// Runs the emulator with `args` expecting it to refuse; its log.
fn refused(c: &Case, args: &[&str]) -> String {
    let mut emu = c.emulator(args);
    let s = emu.wait(Duration::from_secs(60));
    assert!(!s.success(), "the emulator did not refuse:\n{}", emu.log());
    emu.log()
}

#[test]
fn a_type_that_differs_from_the_one_given_or_expected_is_refused_with_both_types() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("type", py);
    let _talker = c.node("talker.py", "talker", &["/x", "1", "--wait-subs", "0", "--hang"]);
    let log = refused(&c, &["--scenario", "Normal", "--ros2-topic", "/x=/y", "--ros2-type", "/x=geometry_msgs/msg/PoseStamped"]);
    for says in ["type mismatch on /x", "--ros2-type gives geometry_msgs/msg/PoseStamped", "the publisher /talker publishes std_msgs/msg/String"] {
        assert!(log.contains(says), "{says}: {log}");
    }
    // A subscriber of the topic written that expects another type.
    let _sub = c.listener("listener", "/y", &["--type", "pose", "--timeout-s", "60"]);
    let log = refused(&c, &["--scenario", "Normal", "--ros2-topic", "/x=/y"]);
    for says in ["type mismatch on /y", "the subscriber /listener expects geometry_msgs/msg/PoseStamped", "the lane relays std_msgs/msg/String"] {
        assert!(log.contains(says), "{says}: {log}");
    }
}

#[test]
fn a_qos_that_cannot_match_is_refused_naming_the_policy_and_both_sides() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("qos", py);
    let _talker = c.node("talker.py", "talker", &["/x", "1", "--qos", "best_effort", "--wait-subs", "0", "--hang"]);
    // The reader asked for more than the publisher offers.
    let log = refused(&c, &["--scenario", "Normal", "--ros2-topic", "/x=/y", "--ros2-qos", "/x=reliable"]);
    for says in ["QoS mismatch on /x", "reliability", "the publisher /talker of /x offers best_effort", "requests reliable"] {
        assert!(log.contains(says), "{says}: {log}");
    }
    // A subscriber asks for more than the relay offers (the publisher's).
    let _sub = c.listener("listener", "/y", &["--qos", "reliable", "--timeout-s", "60"]);
    let log = refused(&c, &["--scenario", "Normal", "--ros2-topic", "/x=/y"]);
    for says in ["QoS mismatch on /y", "reliability", "offers best_effort", "the subscriber /listener of /y requests reliable"] {
        assert!(log.contains(says), "{says}: {log}");
    }
}

#[test]
fn two_lanes_each_with_its_own_scenario_seed_and_account() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("bimanual", py);
    const N: usize = 800;
    let mut psm1 = c.listener("psm1", "/PSM1/servo_cp", &["--type", "pose"]);
    let mut psm2 = c.listener("psm2", "/PSM2/servo_cp", &["--type", "pose"]);
    let mut mtmr = c.node("talker.py", "mtmr", &["/MTMR/measured_cp", &N.to_string(), "--rate-hz", "400", "--type", "pose"]);
    let mut mtml = c.node("talker.py", "mtml", &["/MTML/measured_cp", &N.to_string(), "--rate-hz", "400", "--type", "pose"]);
    let mut emu = c.emulator(&[
        "--scenario",
        "PLM-2",
        "--stream-scenario",
        "1=PLM-1",
        "--seed",
        "11",
        "--ros2-topic",
        "/MTMR/measured_cp=/PSM1/servo_cp",
        "--ros2-topic",
        "/MTML/measured_cp=/PSM2/servo_cp",
    ]);
    for p in [&mut mtmr, &mut mtml, &mut emu, &mut psm1, &mut psm2] {
        p.done();
    }
    let mut seeds = Vec::new();
    for (k, (scenario, listener)) in [("PLM-2", "psm1"), ("PLM-1", "psm2")].into_iter().enumerate() {
        let e = c.json(&format!("stream-{k}/emulator.json"));
        assert_eq!(e["scenario"], scenario);
        assert_balanced(&e["frames"]);
        assert_eq!(u(&e["frames"]["entered"]), N as u64, "lane {k}");
        let t = trace(&c, &format!("stream-{k}/trace_emulator.csv"));
        let fates: Vec<String> = t.iter().map(|r| r["fate"].clone()).collect();
        assert_eq!(fates, c.check_fates(scenario, N, u(&e["seed"])), "lane {k}");
        let got = c.received(listener);
        assert_listener_got_what_was_delivered(&t, &got);
        // Loss costs an absolute pose nothing once the next one arrives:
        // the robot's path runs from the first message it got to the last.
        let m = &c.json(&format!("stream-{k}/ros2.json"))["forward"]["motion"];
        assert_eq!(m["console"]["length"].as_f64(), Some(N as f64 - 1.0));
        let (first, last) = (got.first().unwrap().index, got.last().unwrap().index);
        assert_eq!(m["robot"]["length"].as_f64(), Some((last - first) as f64), "lane {k}");
        seeds.push(u(&e["seed"]));
    }
    assert_eq!(seeds[0], 11, "lane 0 keeps the run's seed");
    assert_ne!(seeds[0], seeds[1], "each lane its own seed");
    let joint = c.json("emulator.json");
    assert_eq!(u(&joint["total"]["entered"]), 2 * N as u64);
}

#[test]
fn bad_input_and_a_publisher_that_leaves_and_another_that_comes_keep_the_emulator_up() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("restart", py);
    let mut listener = c.listener("listener", "/b", &[]);
    // Every 50th message of the first talker is larger than the emulator
    // relays; the second comes after the first has left, within the
    // emulator's linger.
    let mut a = c.node("talker.py", "talker_a", &["/a", "200", "--rate-hz", "400", "--big-every", "50", "--big-bytes", "3000", "--linger-s", "0.5"]);
    let mut emu = c.emulator(&["--scenario", "Normal", "--ros2-topic", "/a=/b", "--ros2-max-bytes", "1024", "--ros2-linger-ms", "8000"]);
    a.done();
    let mut b = c.node("talker.py", "talker_b", &["/a", "100", "--rate-hz", "400", "--first", "200"]);
    b.done();
    emu.done();
    listener.done();
    let e = c.json("emulator.json");
    let f = &e["frames"];
    assert_balanced(f);
    assert_eq!((u(&f["entered"]), u(&f["sent_by_console"])), (300, 300), "{f:#}");
    assert_eq!((u(&f["dropped"]["too_large"]), u(&f["bad_input"]["len_oversize"])), (4, 4));
    assert_eq!(f["bad_input"]["from"], serde_json::json!(["/talker_a"]));
    assert_eq!(u(&f["delivered"]), 296);
    assert_eq!(c.received("listener").len(), 296);
    let r = c.json("ros2.json");
    let events: Vec<(String, String)> = r["forward"]["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["role"] == "publisher")
        .map(|e| (e["node"].as_str().unwrap().to_string(), e["what"].as_str().unwrap().to_string()))
        .collect();
    let want = [("/talker_a", "joined"), ("/talker_a", "left"), ("/talker_b", "joined"), ("/talker_b", "left")];
    assert_eq!(events, want.map(|(n, w)| (n.to_string(), w.to_string())));
}

#[test]
fn a_publisher_faster_than_the_queue_is_counted_as_queue_full() {
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("flood", py);
    let mut listener = c.listener("listener", "/b", &[]);
    // DLM-1 holds each message 70 ms or more: at 500 Hz that is 35 or more
    // at once, more than the 8 the queue holds.
    let mut a = c.node("talker.py", "talker", &["/a", "500", "--rate-hz", "500"]);
    let mut emu = c.emulator(&["--scenario", "DLM-1", "--seed", "2", "--ros2-topic", "/a=/b", "--queue-capacity", "8"]);
    a.done();
    emu.done();
    listener.done();
    let f = &c.json("emulator.json")["frames"];
    assert_balanced(f);
    assert_eq!(u(&f["entered"]), 500);
    assert!(u(&f["dropped"]["queue_full"]) > 0, "{f:#}");
    assert_eq!(c.received("listener").len() as u64, u(&f["delivered"]));
    assert!(c.json("ros2.json")["forward"]["slots_high_water"].as_u64().unwrap() <= 9, "one slot more than the queue");
}

#[test]
fn malformed_empty_and_oversized_messages_from_a_raw_dds_writer_are_counted_drops() {
    use netfi::transport::ros2::{qos, Role, Ros2Node, TopicName, TypeName};
    let Some(py) = python() else { return };
    let _one = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = Case::new("malformed", py);
    let mut listener = c.listener("listener", "/out", &["--type", "pose"]);
    // A DDS writer of this process, not a ROS node: it writes whatever
    // bytes it is given as PoseStamped.
    let mut node = Ros2Node::open(c.domain).unwrap();
    let topic = TopicName::parse("/in").unwrap();
    let writer = node.writer(&topic, &TypeName::parse("geometry_msgs/msg/PoseStamped").unwrap(), &qos::relay(None)).unwrap();
    let mut emu = c.emulator(&["--scenario", "Normal", "--ros2-topic", "/in=/out", "--ros2-max-bytes", "512"]);
    // The emulator's reader, seen from here.
    let t0 = Instant::now();
    loop {
        node.poll(netfi::clock::now_ns());
        if node.remotes(&topic, Role::Subscriber).next().is_some() {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "the emulator never subscribed:\n{}", emu.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    // A PoseStamped as rclpy writes it (frame id `0`), with its x set.
    let pose = |x: f64| {
        let mut b = vec![0u8; 8];
        b.extend_from_slice(&2u32.to_le_bytes());
        b.extend_from_slice(b"0\0");
        b.resize(16, 0);
        for v in [x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b
    };
    let mut sent = Vec::new();
    for i in 0..40u32 {
        let m = match i % 10 {
            3 => pose(f64::from(i))[..30].to_vec(), // truncated
            5 => vec![0u8; 600],                   // larger than 512 bytes
            7 => Vec::new(),                       // empty
            _ => pose(f64::from(i)),
        };
        writer.write(&m, Some(rustdds::Timestamp::now())).unwrap();
        sent.push(i % 10);
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(500));
    drop(writer);
    drop(node);
    emu.done();
    listener.done();
    let e = c.json("emulator.json");
    let f = &e["frames"];
    assert_balanced(f);
    assert_eq!(u(&f["entered"]), 40);
    assert_eq!((u(&f["dropped"]["wrong_size"]), u(&f["dropped"]["too_large"])), (8, 4), "{f:#}");
    let b = &f["bad_input"];
    assert_eq!((u(&b["len_short"]), u(&b["len_zero"]), u(&b["len_oversize"])), (4, 4, 4), "{b:#}");
    assert_eq!(b["from"].as_array().unwrap().len(), 1, "the writer is named (by its GUID: it is no ROS node)");
    assert_eq!(u(&f["delivered"]), 28);
    assert_eq!(c.received("listener").len(), 28, "the emulator stayed up and relayed the rest");
    let m = &c.json("ros2.json")["forward"]["motion"];
    assert_eq!((u(&m["malformed"]), u(&m["console"]["messages"])), (4, 28), "{m}");
}
