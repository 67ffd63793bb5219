//! What the emulator adds between ROS 2 nodes, and what relaying a message
//! costs it.
//!
//! `cargo bench --bench ros2` (about a minute; `-- --quick` for half a
//! minute; `-- --netfi PATH` relays through another build's emulator, for
//! an A/B on the same machine) measures, in one run:
//!
//! - **Latency.** A talker publishes on `/bench` at `--rate-hz`; one
//!   subscriber takes `/bench` straight from it (the direct hop), another
//!   takes `/bench_out` through `netfi emulator --scenario Normal
//!   --ros2-topic /bench=/bench_out`: the same messages at the same moments
//!   on both routes. Two runs: an rclpy talker, with rclpy listeners and a
//!   Rust subscriber (RustDDS, in this process) on both topics (and on the
//!   RustDDS relay's, so that both relays write to the same subscribers); then a Rust
//!   talker (RustDDS, in this process) with the rclpy listeners. A
//!   message's latency is its reception less its source timestamp (the
//!   emulator keeps the source timestamp): for rclpy both are taken by the
//!   DDS layer (Fast DDS's), so neither Python's executor nor its timers
//!   are in it; the Rust subscriber polls every 20 µs and takes its time
//!   when it takes the message. Reported: p50, p99 and max of each route and of
//!   their difference, message for message (`added`: what netfi adds).
//!   Beside netfi, in the same run, two reference relays take `/bench`
//!   from the same talker: a plain rclpy relay node
//!   (`tests/ros2/relay_node.py`: subscribe, republish from the callback,
//!   what a ROS lab writes) to `/bench_relay`, and a minimal relay on
//!   RustDDS, the DDS library netfi uses (a child process of this bench:
//!   one thread that waits for the reader's wake-up, takes and writes, no
//!   netfi code between) to `/bench_rdds`, each with its rclpy listener.
//!   The rclpy node restamps what it publishes, so a relayed message's
//!   latency is its reception less the source time the direct listener saw
//!   for the same index. Reported for each relay: its latency, the hop it
//!   adds (relay − direct) and netfi's part against it (netfi − relay),
//!   message for message.
//! - **CPU per message.** The emulator's loop busy-polls its core, so its
//!   share is the busy time the emulator itself reports per message
//!   (`emulator.json` `busy`); its other threads (RustDDS's receive,
//!   discovery and send threads, the trace writer) are read from
//!   `/proc/<pid>/task` over the run (the scheduler's run time of each
//!   thread, `sched`'s `se.sum_exec_runtime`; `stat`'s sampled ticks only
//!   where there is none), also by thread name. The RustDDS relay's: its
//!   relaying thread's CPU time from the first message, and all its
//!   threads' from `/proc` from its subscribing to its last message (read
//!   by the relay itself), per message relayed.
//! - **Allocation.** RustDDS allocates per message: a counting allocator
//!   counts, on the calling thread only, what one `take` off a reader (into
//!   netfi's slot) and one `write` cost, between two participants of this
//!   process. netfi's own path (the link, the slots) allocates nothing
//!   (tests/alloc.rs for the link; the slots are fixed at start-up).
//! - **Steal**, over the latency run.
//!
//! The rclpy nodes run Fast DDS with its UDP transport only
//! (`FASTDDS_BUILTIN_TRANSPORTS=UDPv4`), as the emulator speaks it: the
//! direct hop is then UDP over loopback too, not shared memory, and no node
//! leaves shared-memory files behind.
//!
//! Results are printed and written to `target/netfi-bench/ros2/ros2.json`.
//! Without a Python that runs rclpy (`--python`, else `NETFI_ROS2_PYTHON`,
//! else `python3`) the latency part says so and is skipped.

use clap::Parser;
use netfi::service::args::EmulatorArgs;
use netfi::transport::ros2::{port::unix_ns, qos, Payload, Role, Ros2Node, Slots, TopicName, TypeName};
use serde_json::{json, Value};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::{Cell, RefCell};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Fast DDS with its UDP transport only, for the rclpy nodes.
const UDP_ONLY: (&str, &str) = ("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4");

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
    /// Leave the emulator's core as it is (by default it is cleared for the
    /// run, as `netfi run` does).
    #[arg(long)]
    no_isolate: bool,
    /// The netfi whose emulator relays (default: this build's), for an A/B
    /// against another build on the same machine.
    #[arg(long, value_name = "PATH")]
    netfi: Option<PathBuf>,
    /// Run as the minimal RustDDS relay in domain D (a child of the bench):
    /// `/bench` → `/bench_rdds` until --messages came, or none for 5 s
    /// after the first.
    #[arg(long, hide = true, value_name = "D")]
    rustdds_relay: Option<u16>,
    /// With --rustdds-relay: a file written once it subscribed.
    #[arg(long, hide = true)]
    ready: Option<PathBuf>,
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
    json!({ "count": v.len(), "p50_us": percentile(&v, 0.5) / 1e3, "p99_us": percentile(&v, 0.99) / 1e3, "max_us": percentile(&v, 1.0) / 1e3 })
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
    let mut writer = a.writer(&topic, &ty, &q)?;
    let mut reader = b.reader(&topic, &ty, &qos::reader(&q))?;
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
                // The message, padded as RTPS pads a serialized payload:
                // to a multiple of 4 bytes.
                assert_eq!(m.payload, Payload::Stored { len: message.len().next_multiple_of(4) as u32 });
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

/// Copies a message into a buffer, as it is.
#[derive(Clone)]
struct IntoBuf<'a>(&'a RefCell<Vec<u8>>);

impl<'de> rustdds::no_key::Decode<'de, Payload> for IntoBuf<'_> {
    type Error = std::convert::Infallible;
    fn decode_bytes(self, input: &'de [u8], _: rustdds::RepresentationIdentifier) -> Result<Payload, Self::Error> {
        let mut b = self.0.borrow_mut();
        b.clear();
        b.extend_from_slice(input);
        Ok(Payload::Stored { len: input.len() as u32 })
    }
}

/// Wakes a parked thread.
struct Unpark(std::thread::Thread);

impl std::task::Wake for Unpark {
    fn wake(self: Arc<Self>) {
        self.0.unpark();
    }
}

/// This thread's CPU time (ns).
fn thread_cpu_ns() -> u64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `t` is a valid timespec to write.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
}

/// The minimal relay on RustDDS, the DDS library the emulator uses: one
/// participant, a reader of `/bench` and a writer of `/bench_rdds` with the
/// emulator's QoS and its raw CDR adapters, and one thread that waits for
/// the reader's wake-up, takes what came and writes it on, with its source
/// time. Nothing of the emulator between (no link, no scheduler, no trace).
/// Prints what it relayed and its thread's CPU time from the first message.
fn rustdds_relay(domain: u16, n: usize, ready: Option<&Path>) -> anyhow::Result<()> {
    use netfi::transport::ros2::port::{RawCdr, RawOut};
    use rustdds::{DomainParticipant, QosPolicies, TopicKind};
    let dp = DomainParticipant::new(domain)?;
    let none = QosPolicies::qos_none();
    let (subscriber, publisher) = (dp.create_subscriber(&none)?, dp.create_publisher(&none)?);
    let ty = TypeName::parse("std_msgs/msg/String")?.dds();
    let q = qos::relay(None);
    let wq = qos::writer(&q);
    let out = dp.create_topic(TopicName::parse("/bench_rdds")?.dds(), ty.clone(), &wq, TopicKind::NoKey)?;
    let writer = publisher.create_datawriter_no_key::<rustdds::bytes::Bytes, RawOut>(&out, Some(wq))?;
    let t0 = Instant::now();
    let mut matched = 0;
    while matched < 1 {
        anyhow::ensure!(t0.elapsed() < Duration::from_secs(60), "the RustDDS relay found no subscriber of /bench_rdds within 60 s");
        while let Some(e) = rustdds::StatusEvented::try_recv_status(&writer) {
            if let rustdds::DataWriterStatus::PublicationMatched { current, .. } = e {
                matched = current.count();
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let rq = qos::reader(&q);
    let input = dp.create_topic(TopicName::parse("/bench")?.dds(), ty, &rq, TopicKind::NoKey)?;
    let reader = subscriber.create_simple_datareader_no_key::<Payload, RawCdr>(&input, Some(rq))?;
    if let Some(r) = ready {
        std::fs::write(r, "")?;
    }
    // Every thread's CPU from here to the last message, read by the relay
    // itself: it may be gone before the bench looks again.
    let pid = std::process::id();
    let cpu0 = threads_cpu_ns(pid);
    let buf = RefCell::new(Vec::with_capacity(64 * 1024));
    let waker = std::task::Waker::from(Arc::new(Unpark(std::thread::current())));
    let (mut relayed, mut failed, mut first, mut last) = (0usize, 0u64, None::<u64>, None::<Instant>);
    let t0 = Instant::now();
    while relayed < n && !last.is_some_and(|l| l.elapsed() > Duration::from_secs(5)) && t0.elapsed() < Duration::from_secs(600) {
        // The waker is taken when it fires: set again before each look, so
        // a message that comes between the look and the wait wakes it.
        reader.set_waker(Some(waker.clone()));
        let mut took = false;
        while let Some(c) = reader.try_take_one_with(IntoBuf(&buf))? {
            first.get_or_insert_with(thread_cpu_ns);
            if let Payload::Stored { .. } = c.sample {
                let bytes = rustdds::bytes::Bytes::copy_from_slice(&buf.borrow());
                match writer.write(bytes, c.write_options.source_timestamp()) {
                    Ok(()) => relayed += 1,
                    Err(_) => failed += 1,
                }
            }
            took = true;
        }
        if took {
            last = Some(Instant::now());
        } else {
            std::thread::park_timeout(Duration::from_millis(100));
        }
    }
    let cpu_ns = thread_cpu_ns() - first.unwrap_or(0);
    let (all, threads) = cpu_per_message(&cpu0, &threads_cpu_ns(pid), pid, false, relayed.max(1) as f64);
    println!("{}", json!({ "relayed": relayed, "write_failures": failed, "relay_thread_cpu_ns": cpu_ns, "all_threads_cpu_ns_per_message": all, "threads_cpu_ns_per_message": threads }));
    // Reliable resends to a late acknowledgement.
    std::thread::sleep(Duration::from_secs(1));
    Ok(())
}

/// The Python with rclpy, if it runs a node.
fn python(a: &Args) -> Option<PathBuf> {
    let py = a.python.clone().or_else(|| std::env::var_os("NETFI_ROS2_PYTHON").map(PathBuf::from)).unwrap_or_else(|| "python3".into());
    let ok = Command::new(&py).args(["-c", "import rclpy; rclpy.init(); rclpy.create_node('probe'); rclpy.shutdown()"]).env("ROS_DOMAIN_ID", "231").env(UDP_ONLY.0, UDP_ONLY.1).output();
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

/// A thread's CPU time (ns): the scheduler's own sum of its run time
/// (`se.sum_exec_runtime` in `/proc/<pid>/task/<tid>/sched`, in ms to the
/// ns), else user + system time from `stat` in clock ticks. The ticks are
/// sampled: a thread that runs in short bursts between them (a DDS
/// receive thread) is undercounted there several times over.
fn task_cpu_ns(task: &Path) -> Option<(String, f64)> {
    let stat = std::fs::read_to_string(task.join("stat")).ok()?;
    let (open, close) = (stat.find('(')?, stat.rfind(')')?);
    let name = stat[open + 1..close].to_string();
    let sched = std::fs::read_to_string(task.join("sched")).ok();
    let exact = sched.as_deref().and_then(|s| s.lines().find(|l| l.trim_start().starts_with("se.sum_exec_runtime"))?.split(':').nth(1)?.trim().parse::<f64>().ok());
    if let Some(ms) = exact {
        return Some((name, ms * 1e6));
    }
    let f: Vec<&str> = stat[close + 2..].split_whitespace().collect();
    let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    Some((name, ticks as f64 * 1e7))
}

/// CPU time (ns) of each thread of `pid`, by thread id: its name and time.
fn threads_cpu_ns(pid: u32) -> std::collections::BTreeMap<String, (String, f64)> {
    let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else { return Default::default() };
    dir.filter_map(|e| e.ok()).filter_map(|e| Some((e.file_name().to_string_lossy().into_owned(), task_cpu_ns(&e.path())?))).collect()
}

/// CPU (ns) a message between `before` and `after` of process `pid`'s
/// threads: of all of them (but its main thread with `but_main`), and by
/// thread name (the main thread's marked `(main)`).
fn cpu_per_message(before: &std::collections::BTreeMap<String, (String, f64)>, after: &std::collections::BTreeMap<String, (String, f64)>, pid: u32, but_main: bool, messages: f64) -> (f64, Value) {
    let mut by = std::collections::BTreeMap::<String, f64>::new();
    let mut all = 0.0;
    for (tid, (name, ns)) in after {
        let d = ns - before.get(tid).map_or(0.0, |b| b.1);
        let main = *tid == pid.to_string();
        *by.entry(if main { format!("{name} (main)") } else { name.clone() }).or_insert(0.0) += d / messages;
        if !(main && but_main) {
            all += d;
        }
    }
    (all / messages, json!(by))
}

/// Each row's index, source and reception times (ns).
fn rows(csv: &Path) -> Vec<(u64, i64, i64)> {
    std::fs::read_to_string(csv)
        .unwrap_or_default()
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some((f[0].parse().ok()?, f[1].parse().ok()?, f[2].parse().ok()?))
        })
        .collect()
}

/// A relay's route, as its listener saw it: a relay that restamps what it
/// republishes (an rclpy node does) hides the talker's time, so each
/// message's latency is its reception there less the source time the
/// direct listener saw for the same index.
fn relayed(csv: &Path, direct: &Path) -> Seen {
    let source: std::collections::BTreeMap<u64, i64> = rows(direct).into_iter().map(|(i, s, _)| (i, s)).collect();
    rows(csv).into_iter().filter_map(|(i, _, r)| Some((i, r - source.get(&i)?))).collect()
}

/// Each row's index and latency (reception less source, ns).
fn received(csv: &Path) -> Vec<(u64, i64)> {
    rows(csv).into_iter().map(|(i, s, r)| (i, r - s)).collect()
}

/// Who publishes `/bench` in a run.
#[derive(Clone, Copy, PartialEq)]
enum Talker {
    /// `tests/ros2/talker.py`.
    Rclpy,
    /// A RustDDS writer in a thread of this process.
    Rust,
}

/// Each message's index and latency (ns) as one subscriber saw it.
type Seen = Vec<(u64, i64)>;

/// The index a std_msgs/String of the talkers carries.
fn index_of(cdr: &[u8]) -> Option<u64> {
    let text = std::str::from_utf8(cdr.get(4..)?).ok()?;
    text.trim_end_matches('\0').split(' ').next()?.parse().ok()
}

/// A Rust subscriber of `/bench` (direct), `/bench_out` (through the
/// emulator) and `/bench_rdds` (through the minimal RustDDS relay, so that
/// both relays write to the same subscribers) in a thread of this process,
/// until `n` messages came on each or none for 5 s after the first: what
/// each saw. A message's latency is when the thread
/// took it (it polls every 20 µs) less its source timestamp.
fn rust_listener(domain: u16, n: usize, ready: Arc<AtomicBool>) -> std::thread::JoinHandle<anyhow::Result<[Seen; 3]>> {
    std::thread::spawn(move || {
        let mut node = Ros2Node::open(domain)?;
        let ty = TypeName::parse("std_msgs/msg/String")?;
        let q = qos::reader(&qos::relay(None));
        let mut readers = [node.reader(&TopicName::parse("/bench")?, &ty, &q)?, node.reader(&TopicName::parse("/bench_out")?, &ty, &q)?, node.reader(&TopicName::parse("/bench_rdds")?, &ty, &q)?];
        let slots = RefCell::new(Slots::new(1, 1024));
        let slot = slots.borrow_mut().alloc().expect("a slot");
        let mut seen: [Seen; 3] = [Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n)];
        ready.store(true, Ordering::Release);
        let (t0, mut last, mut polls) = (Instant::now(), None::<Instant>, 0u64);
        while seen.iter().any(|s| s.len() < n) && !last.is_some_and(|l| l.elapsed() > Duration::from_secs(5)) && t0.elapsed() < Duration::from_secs(600) {
            for (r, s) in readers.iter_mut().zip(seen.iter_mut()) {
                while let Some(m) = r.take(&slots, slot)? {
                    let now = unix_ns(rustdds::Timestamp::now()) as i64;
                    if let (Payload::Stored { len }, Some(src)) = (m.payload, m.source) {
                        if let Some(i) = index_of(&slots.borrow().get(slot)[..len as usize]) {
                            s.push((i, now - unix_ns(src) as i64));
                        }
                    }
                    last = Some(Instant::now());
                }
            }
            // The graph's news, taken as they come (discovery waits on
            // them otherwise).
            polls += 1;
            if polls % 500 == 0 {
                node.poll(netfi::clock::now_ns());
            }
            std::thread::sleep(Duration::from_micros(20));
        }
        Ok(seen)
    })
}

/// A Rust publisher of `/bench`: once `subscribers` have matched, `n`
/// std_msgs/String messages (each its index) at `rate_hz`, each stamped
/// with its source time; it stays 1 s for reliable resends.
fn rust_talker(domain: u16, n: usize, rate_hz: f64, subscribers: usize) -> std::thread::JoinHandle<anyhow::Result<()>> {
    std::thread::spawn(move || {
        let mut node = Ros2Node::open(domain)?;
        let topic = TopicName::parse("/bench")?;
        let mut writer = node.writer(&topic, &TypeName::parse("std_msgs/msg/String")?, &qos::relay(None))?;
        let t0 = Instant::now();
        loop {
            node.poll(netfi::clock::now_ns());
            if node.remotes(&topic, Role::Subscriber).count() >= subscribers {
                break;
            }
            anyhow::ensure!(t0.elapsed() < Duration::from_secs(60), "the Rust talker found no {subscribers} subscribers within 60 s");
            std::thread::sleep(Duration::from_millis(20));
        }
        // Matched on both sides: as the rclpy talker, a little after.
        std::thread::sleep(Duration::from_millis(500));
        let start = netfi::clock::now_ns();
        for i in 0..n {
            netfi::clock::sleep_until_ns(start + (i as f64 * 1e9 / rate_hz) as u64);
            writer.write(&string_cdr(&i.to_string()), Some(rustdds::Timestamp::now()))?;
        }
        std::thread::sleep(Duration::from_secs(1));
        Ok(())
    })
}

/// One run: a talker (rclpy or Rust) publishes `/bench`; the emulator
/// relays it to `/bench_out` through Normal; an rclpy listener takes each
/// topic, and, with an rclpy talker, a Rust listener takes both too.
fn route(a: &Args, py: &Path, talker_kind: Talker, messages: usize, domain: u16) -> anyhow::Result<Value> {
    let label = if talker_kind == Talker::Rclpy { "rclpy_talker" } else { "rust_talker" };
    let dir = a.out.join(label);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let domain_s = domain.to_string();
    let scripts = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/ros2");
    let node = |args: &[&str], log: &str| -> anyhow::Result<Kill> {
        let f = std::fs::File::create(dir.join(log))?;
        let c = Command::new(py).current_dir(&scripts).args(args).env("ROS_DOMAIN_ID", &domain_s).env(UDP_ONLY.0, UDP_ONLY.1).stdout(f.try_clone()?).stderr(f).stdin(Stdio::null()).spawn()?;
        Ok(Kill(c))
    };
    let wait_file = |p: &Path| {
        let t0 = Instant::now();
        while !p.exists() && t0.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    let (direct_csv, through_csv, relay_csv, rdds_csv) = (dir.join("direct.csv"), dir.join("through.csv"), dir.join("relay.csv"), dir.join("rdds.csv"));
    let n = messages.to_string();
    let mut listeners = Vec::new();
    for (topic, csv, name) in [("/bench", &direct_csv, "direct"), ("/bench_out", &through_csv, "through"), ("/bench_relay", &relay_csv, "relayed"), ("/bench_rdds", &rdds_csv, "rdds")] {
        let ready = dir.join(format!("{name}.ready"));
        listeners.push(node(&["listener.py", topic, csv.to_str().unwrap(), "--count", &n, "--idle-s", "5", "--depth", "1000", "--name", name, "--ready", ready.to_str().unwrap()], &format!("{name}.log"))?);
        wait_file(&ready);
    }
    // The plain rclpy relay node: /bench → /bench_relay, subscribed once
    // its listener is there.
    let relay_ready = dir.join("relay.ready");
    let mut relay = node(&["relay_node.py", "/bench", "/bench_relay", "--depth", "1000", "--name", "relay", "--ready", relay_ready.to_str().unwrap()], "relay.log")?;
    wait_file(&relay_ready);
    // The minimal RustDDS relay, a child process (its threads are its own
    // in /proc): /bench → /bench_rdds.
    let rdds_ready = dir.join("rdds_relay.ready");
    let rdds_out = dir.join("rdds_relay.json");
    let mut rdds = Kill(
        Command::new(std::env::current_exe()?)
            .args(["--rustdds-relay", &domain_s, "--messages", &n, "--ready", rdds_ready.to_str().unwrap()])
            .stdout(std::fs::File::create(&rdds_out)?)
            .stderr(std::fs::File::create(dir.join("rdds_relay.log"))?)
            .stdin(Stdio::null())
            .spawn()?,
    );
    wait_file(&rdds_ready);
    let rust = match talker_kind {
        Talker::Rclpy => {
            let ready = Arc::new(AtomicBool::new(false));
            let h = rust_listener(domain, messages, ready.clone());
            while !ready.load(Ordering::Acquire) && !h.is_finished() {
                std::thread::sleep(Duration::from_millis(20));
            }
            if h.is_finished() {
                h.join().map_err(|_| anyhow::anyhow!("the Rust listener panicked"))??;
                anyhow::bail!("the Rust listener ended before it subscribed");
            }
            Some(h)
        }
        Talker::Rust => None,
    };
    let cores = core_affinity::get_core_ids().map_or(1, |c| c.len());
    let mut emulator = EmulatorArgs::new(None, "Normal");
    emulator.scenario.seed = Some(1);
    emulator.ros2.ros2_topic = vec!["/bench=/bench_out".into()];
    emulator.ros2.ros2_domain = Some(domain);
    emulator.ros2.ros2_linger_ms = 300.0;
    emulator.expected_frames = messages as u64;
    emulator.out = dir.join("out");
    emulator.placement.core = (cores >= 2).then(|| cores - 1);
    emulator.placement.no_pin = cores < 2;
    // As `netfi run` places it: its core cleared of everything else.
    emulator.placement.isolate = cores >= 2 && !a.no_isolate;
    let f = std::fs::File::create(dir.join("emulator.log"))?;
    let mut emu = Kill(
        Command::new(a.netfi.clone().unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_netfi"))))
            .arg("emulator")
            .args(emulator.to_argv())
            .env(UDP_ONLY.0, UDP_ONLY.1)
            .stdout(f.try_clone()?)
            .stderr(f)
            .spawn()?,
    );
    let pid = emu.0.id();
    // The talker waits for every subscriber of /bench: the direct
    // listener(s), the two relays and the emulator.
    let subscribers = if rust.is_some() { 5 } else { 4 };
    let steal = netfi::host::StealTimer::start();
    let cpu0 = threads_cpu_ns(pid);
    match talker_kind {
        Talker::Rclpy => {
            let mut t = node(&["talker.py", "/bench", &n, "--rate-hz", &a.rate_hz.to_string(), "--wait-subs", &subscribers.to_string(), "--depth", "1000"], "talker.log")?;
            wait(&mut t, "the talker", Duration::from_secs(600))?;
        }
        Talker::Rust => rust_talker(domain, messages, a.rate_hz, subscribers).join().map_err(|_| anyhow::anyhow!("the Rust talker panicked"))??,
    }
    let cpu1 = threads_cpu_ns(pid);
    let steal = steal.stop();
    wait(&mut emu, "the emulator", Duration::from_secs(60))?;
    wait(&mut relay, "the rclpy relay node", Duration::from_secs(60))?;
    wait(&mut rdds, "the RustDDS relay", Duration::from_secs(60))?;
    let r: Value = serde_json::from_str(std::fs::read_to_string(&rdds_out)?.trim())?;
    let rdds_relayed = r["relayed"].as_u64().unwrap_or(0).max(1) as f64;
    let whats = ["the direct listener", "the listener through the emulator", "the listener through the rclpy relay node", "the listener through the RustDDS relay"];
    for ((l, what), csv) in listeners.iter_mut().zip(whats).zip([&direct_csv, &through_csv, &relay_csv, &rdds_csv]) {
        // A listener that wrote what it received but hangs in rclpy's
        // shutdown is stopped (by its drop), not a failed run.
        if let Err(e) = wait(l, what, Duration::from_secs(60)) {
            anyhow::ensure!(!rows(csv).is_empty(), e);
            eprintln!("{e}, after writing what it received: stopped");
        }
    }
    let e: Value = serde_json::from_slice(&std::fs::read(dir.join("out/emulator.json"))?)?;
    let delivered = e["frames"]["delivered"].as_u64().unwrap_or(0).max(1) as f64;
    // The emulator's loop (its main thread) busy-polls: its share is the
    // busy time it reports, not its CPU time.
    let (emulator_other, emulator_threads) = cpu_per_message(&cpu0, &cpu1, pid, true, delivered);
    let mut out = json!({
        "talker": if talker_kind == Talker::Rclpy { "rclpy" } else { "rust" },
        "messages": messages,
        "rate_hz": a.rate_hz,
        "rclpy_listener": routes(&received(&direct_csv), &received(&through_csv), &relayed(&relay_csv, &direct_csv), &relayed(&rdds_csv, &direct_csv)),
        "emulator_loop_busy_ns_per_message": e["busy"]["busy_ns_per_frame"],
        "emulator_busy": e["busy"],
        "emulator_other_threads_cpu_ns_per_message": emulator_other,
        "emulator_threads_cpu_ns_per_message": emulator_threads,
        "release_lateness_ns": e["release_lateness_ns"],
        "emulator_core": e["core"],
        "emulator_threads_placement": e["threads"],
        "rustdds_relay": r,
        "rustdds_relay_thread_cpu_ns_per_message": r["relay_thread_cpu_ns"].as_f64().unwrap_or(f64::NAN) / rdds_relayed,
        "rustdds_relay_all_threads_cpu_ns_per_message": r["all_threads_cpu_ns_per_message"],
        "rustdds_relay_threads_cpu_ns_per_message": r["threads_cpu_ns_per_message"],
        "steal_fraction": steal.fraction,
        "steal_ms": steal.ms,
    });
    if let Some(h) = rust {
        let [direct, through, rdds] = h.join().map_err(|_| anyhow::anyhow!("the Rust listener panicked"))??;
        out["rust_listener"] = both(&direct, &through);
        out["rust_listener"]["through_rustdds_relay"] = summary(rdds.iter().map(|d| d.1).collect());
    }
    Ok(out)
}

/// Message for message, `b`'s latency less `a`'s.
fn difference(a: &Seen, b: &Seen) -> Vec<i64> {
    let by_index: std::collections::BTreeMap<u64, i64> = a.iter().copied().collect();
    b.iter().filter_map(|(i, t)| by_index.get(i).map(|d| t - d)).collect()
}

/// [`both`], with the routes through the plain rclpy relay node and the
/// minimal RustDDS relay: each one's latency, the hop it adds (relay −
/// direct) and netfi's part against it (netfi − relay), message for
/// message.
fn routes(direct: &Seen, through: &Seen, relay: &Seen, rdds: &Seen) -> Value {
    let mut v = both(direct, through);
    v["through_rclpy_relay"] = summary(relay.iter().map(|d| d.1).collect());
    v["rclpy_relay_hop"] = summary(difference(direct, relay));
    v["netfi_less_rclpy_relay"] = summary(difference(relay, through));
    v["through_rustdds_relay"] = summary(rdds.iter().map(|d| d.1).collect());
    v["rustdds_relay_hop"] = summary(difference(direct, rdds));
    v["netfi_less_rustdds_relay"] = summary(difference(rdds, through));
    v
}

/// The direct route's latency, the route's through the emulator, and their
/// difference message for message.
fn both(direct: &Seen, through: &Seen) -> Value {
    let by_index: std::collections::BTreeMap<u64, i64> = direct.iter().copied().collect();
    let added: Vec<i64> = through.iter().filter_map(|(i, t)| by_index.get(i).map(|d| t - d)).collect();
    json!({
        "direct": summary(direct.iter().map(|d| d.1).collect()),
        "through_emulator": summary(through.iter().map(|d| d.1).collect()),
        "added": summary(added),
    })
}

fn latency_part(a: &Args, py: &Path, messages: usize) -> anyhow::Result<Value> {
    let domain = 170 + (std::process::id() % 30) as u16;
    Ok(json!({
        "rclpy_talker": route(a, py, Talker::Rclpy, messages, domain)?,
        "rust_talker": route(a, py, Talker::Rust, messages, domain + 1)?,
    }))
}

fn main() -> anyhow::Result<()> {
    let mut a = Args::parse();
    if let Some(domain) = a.rustdds_relay {
        return rustdds_relay(domain, a.messages, a.ready.as_deref());
    }
    // The nodes run in tests/ros2: their files are named absolutely.
    std::fs::create_dir_all(&a.out)?;
    a.out = std::path::absolute(&a.out)?;
    let messages = if a.quick { 1000 } else { a.messages };
    std::fs::create_dir_all(&a.out)?;
    let alloc = allocation_part(if a.quick { 200 } else { 2000 })?;
    println!("RustDDS on the calling thread: {alloc}");
    let latency = match python(&a) {
        Some(py) => latency_part(&a, &py, messages)?,
        None => Value::Null,
    };
    println!("talker → listener, direct and through the emulator (Normal): {latency:#}");
    let all = json!({ "allocation": alloc, "latency": latency });
    std::fs::write(a.out.join("ros2.json"), serde_json::to_vec_pretty(&all)?)?;
    Ok(())
}
