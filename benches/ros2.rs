//! What the emulator adds between ROS 2 nodes, and what relaying a message
//! costs it.
//!
//! `cargo bench --bench ros2` (about half a minute; `-- --quick` for a few
//! seconds) measures, in one run:
//!
//! - **Latency.** An rclpy talker publishes on `/bench` at `--rate-hz`; one
//!   rclpy listener takes `/bench` straight from it (the direct hop),
//!   another takes `/bench_out` through `netfi emulator --scenario Normal
//!   --ros2-topic /bench=/bench_out`: the same messages at the same moments
//!   on both routes. Each message's latency is its reception less its
//!   source timestamp, both taken by the DDS layer (Fast DDS's; the emulator
//!   keeps the source timestamp), so neither Python's executor nor its
//!   timers are in it. Reported: p50 and p99 of each route and of their
//!   difference, message for message.
//! - **CPU per message.** The emulator's loop busy-polls its core, so its
//!   share is the busy time the emulator itself reports per message
//!   (`emulator.json` `busy`); its other threads (RustDDS's receive,
//!   discovery and send threads, the trace writer) are read from
//!   `/proc/<pid>/task` over the run.
//! - **Allocation.** RustDDS allocates per message: a counting allocator
//!   counts, on the calling thread only, what one `take` off a reader (into
//!   netfi's slot) and one `write` cost, between two participants of this
//!   process. netfi's own path (the link, the slots) allocates nothing
//!   (tests/alloc.rs for the link; the slots are fixed at start-up).
//! - **Steal**, over the latency run.
//!
//! Results are printed and written to `target/netfi-bench/ros2/ros2.json`.
//! Without a Python that runs rclpy (`--python`, else `NETFI_ROS2_PYTHON`,
//! else `python3`) the latency part says so and is skipped.

use clap::Parser;
use netfi::transport::ros2::{qos, Payload, Ros2Node, Slots, TopicName, TypeName};
use serde_json::{json, Value};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::{Cell, RefCell};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Counts allocations made on threads that ask for it.
struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(p, l) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations `f` makes on this thread.
fn allocations<T>(f: impl FnOnce() -> T) -> (T, u64) {
    COUNT.with(|c| c.set(0));
    COUNTING.with(|c| c.set(true));
    let v = f();
    COUNTING.with(|c| c.set(false));
    (v, COUNT.with(Cell::get))
}

#[derive(Parser)]
struct Args {
    /// Messages of the latency run.
    #[arg(long, default_value_t = 10_000)]
    messages: usize,
    #[arg(long, default_value_t = 1000.0)]
    rate_hz: f64,
    /// A few seconds: 1000 messages.
    #[arg(long)]
    quick: bool,
    /// The Python with rclpy (default: $NETFI_ROS2_PYTHON, else python3).
    #[arg(long)]
    python: Option<PathBuf>,
    #[arg(long, default_value = "target/netfi-bench/ros2")]
    out: PathBuf,
    /// Passed by `cargo bench`.
    #[arg(long, hide = true)]
    bench: bool,
}

fn percentile(sorted: &[i64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize] as f64
}

fn summary(mut v: Vec<i64>) -> Value {
    v.sort_unstable();
    json!({ "count": v.len(), "p50_us": percentile(&v, 0.5) / 1e3, "p99_us": percentile(&v, 0.99) / 1e3 })
}

/// CDR of a std_msgs/String `text`: length with its NUL, bytes, NUL.
fn string_cdr(text: &str) -> Vec<u8> {
    let mut b = ((text.len() + 1) as u32).to_le_bytes().to_vec();
    b.extend_from_slice(text.as_bytes());
    b.push(0);
    b
}

/// Allocations per message of RustDDS's take (into a slot) and write, on
/// the calling thread, between two participants of this process.
fn allocation_part(messages: usize) -> anyhow::Result<Value> {
    let domain = 200 + (std::process::id() % 30) as u16;
    let (a, b) = (Ros2Node::open(domain)?, Ros2Node::open(domain)?);
    let topic = TopicName::parse("/alloc")?;
    let ty = TypeName::parse("std_msgs/msg/String")?;
    let q = qos::relay(None);
    let writer = a.writer(&topic, &ty, &q)?;
    let reader = b.reader(&topic, &ty, &qos::reader(&q))?;
    let slots = RefCell::new(Slots::new(2, 1024));
    let message = string_cdr("0123456789abcdef");
    std::thread::sleep(Duration::from_secs(2));
    let (mut writes, mut takes, mut taken) = (0u64, 0u64, 0usize);
    let t0 = Instant::now();
    for _ in 0..messages {
        let (r, n) = allocations(|| writer.write(&message, Some(rustdds::Timestamp::now())));
        r?;
        writes += n;
        let due = Instant::now() + Duration::from_millis(50);
        while Instant::now() < due {
            let (r, n) = allocations(|| reader.take(&slots, 0));
            if let Some(m) = r? {
                assert_eq!(m.payload, Payload::Stored { len: message.len() as u32 });
                takes += n;
                taken += 1;
                break;
            }
        }
    }
    anyhow::ensure!(taken > 0, "nothing came through in {:?}", t0.elapsed());
    Ok(json!({
        "messages": messages,
        "taken": taken,
        "allocations_per_write": writes as f64 / messages as f64,
        "allocations_per_take": takes as f64 / taken as f64,
    }))
}

/// The Python with rclpy, if it runs a node.
fn python(a: &Args) -> Option<PathBuf> {
    let py = a.python.clone().or_else(|| std::env::var_os("NETFI_ROS2_PYTHON").map(PathBuf::from)).unwrap_or_else(|| "python3".into());
    let ok = Command::new(&py).args(["-c", "import rclpy; rclpy.init(); rclpy.create_node('probe'); rclpy.shutdown()"]).env("ROS_DOMAIN_ID", "231").output();
    match ok {
        Ok(o) if o.status.success() => Some(py),
        _ => {
            eprintln!("ros2 bench: {} cannot run an rclpy node; the latency part is skipped", py.display());
            None
        }
    }
}

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn wait(c: &mut Kill, what: &str, timeout: Duration) -> anyhow::Result<()> {
    let t0 = Instant::now();
    while t0.elapsed() < timeout {
        if let Some(s) = c.0.try_wait()? {
            anyhow::ensure!(s.success(), "{what} failed: {s}");
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    anyhow::bail!("{what} did not end within {timeout:?}")
}

/// CPU ticks (user + system) of each thread of `pid` but `skip`.
fn thread_ticks(pid: u32, skip: u32) -> u64 {
    let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else { return 0 };
    dir.filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy() != skip.to_string())
        .filter_map(|e| std::fs::read_to_string(e.path().join("stat")).ok())
        .filter_map(|s| {
            let rest = &s[s.rfind(')')? + 2..];
            let f: Vec<&str> = rest.split_whitespace().collect();
            Some(f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?)
        })
        .sum()
}

fn received(csv: &Path) -> Vec<(u64, i64)> {
    std::fs::read_to_string(csv)
        .unwrap_or_default()
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some((f[0].parse().ok()?, f[2].parse::<i64>().ok()? - f[1].parse::<i64>().ok()?))
        })
        .collect()
}

fn latency_part(a: &Args, py: &Path, messages: usize) -> anyhow::Result<Value> {
    let dir = a.out.join("run");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let domain = (170 + std::process::id() % 30).to_string();
    let scripts = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/ros2");
    let node = |args: &[&str], log: &str| -> anyhow::Result<Kill> {
        let f = std::fs::File::create(dir.join(log))?;
        let c = Command::new(py).current_dir(&scripts).args(args).env("ROS_DOMAIN_ID", &domain).stdout(f.try_clone()?).stderr(f).stdin(Stdio::null()).spawn()?;
        Ok(Kill(c))
    };
    let wait_file = |p: &Path| {
        let t0 = Instant::now();
        while !p.exists() && t0.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    let (direct_csv, through_csv) = (dir.join("direct.csv"), dir.join("through.csv"));
    let n = messages.to_string();
    let mut listeners = Vec::new();
    for (topic, csv, name) in [("/bench", &direct_csv, "direct"), ("/bench_out", &through_csv, "through")] {
        let ready = dir.join(format!("{name}.ready"));
        listeners.push(node(&["listener.py", topic, csv.to_str().unwrap(), "--count", &n, "--idle-s", "5", "--depth", "1000", "--name", name, "--ready", ready.to_str().unwrap()], &format!("{name}.log"))?);
        wait_file(&ready);
    }
    // The talker waits for both: the direct listener and the emulator.
    let mut talker = node(&["talker.py", "/bench", &n, "--rate-hz", &a.rate_hz.to_string(), "--wait-subs", "2", "--depth", "1000"], "talker.log")?;
    let cores = core_affinity::get_core_ids().map_or(1, |c| c.len());
    let pin = if cores >= 2 { vec!["--core".to_string(), (cores - 1).to_string()] } else { vec!["--no-pin".to_string()] };
    let f = std::fs::File::create(dir.join("emulator.log"))?;
    let mut emu = Kill(
        Command::new(env!("CARGO_BIN_EXE_netfi"))
            .args(["emulator", "--scenario", "Normal", "--seed", "1", "--ros2-topic", "/bench=/bench_out", "--ros2-domain", &domain, "--ros2-linger-ms", "300", "--expected-frames", &n, "--out"])
            .arg(dir.join("out"))
            .args(&pin)
            .stdout(f.try_clone()?)
            .stderr(f)
            .spawn()?,
    );
    let pid = emu.0.id();
    let steal = netfi::host::StealTimer::start();
    let ticks0 = thread_ticks(pid, pid);
    wait(&mut talker, "the talker", Duration::from_secs(600))?;
    let ticks1 = thread_ticks(pid, pid);
    let steal = steal.stop();
    wait(&mut emu, "the emulator", Duration::from_secs(60))?;
    for (k, l) in listeners.iter_mut().enumerate() {
        wait(l, if k == 0 { "the direct listener" } else { "the listener through the emulator" }, Duration::from_secs(60))?;
    }
    let e: Value = serde_json::from_slice(&std::fs::read(dir.join("out/emulator.json"))?)?;
    let (direct, through) = (received(&direct_csv), received(&through_csv));
    let by_index: std::collections::BTreeMap<u64, i64> = direct.iter().copied().collect();
    let added: Vec<i64> = through.iter().filter_map(|(i, t)| by_index.get(i).map(|d| t - d)).collect();
    let tick_ns = 1e9 / 100.0;
    let delivered = e["frames"]["delivered"].as_u64().unwrap_or(0).max(1) as f64;
    Ok(json!({
        "messages": messages,
        "rate_hz": a.rate_hz,
        "direct": summary(direct.iter().map(|d| d.1).collect()),
        "through_emulator": summary(through.iter().map(|d| d.1).collect()),
        "added": summary(added),
        "emulator_loop_busy_ns_per_message": e["busy"]["busy_ns_per_frame"],
        "emulator_other_threads_cpu_ns_per_message": (ticks1.saturating_sub(ticks0)) as f64 * tick_ns / delivered,
        "release_lateness_ns": e["release_lateness_ns"],
        "steal_fraction": steal.fraction,
        "steal_ms": steal.ms,
    }))
}

fn main() -> anyhow::Result<()> {
    let a = Args::parse();
    let messages = if a.quick { 1000 } else { a.messages };
    std::fs::create_dir_all(&a.out)?;
    let alloc = allocation_part(if a.quick { 200 } else { 2000 })?;
    println!("RustDDS on the calling thread: {alloc}");
    let latency = match python(&a) {
        Some(py) => latency_part(&a, &py, messages)?,
        None => Value::Null,
    };
    println!("rclpy → rclpy, direct and through the emulator (Normal): {latency:#}");
    let all = json!({ "allocation": alloc, "latency": latency });
    std::fs::write(a.out.join("ros2.json"), serde_json::to_vec_pretty(&all)?)?;
    Ok(())
}
