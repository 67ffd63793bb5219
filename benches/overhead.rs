//! The macro benchmark: what the emulator adds to a frame's one-way latency,
//! measured against the physical floor (a bare iceoryx2 hop) and against
//! kernel UDP, its release lateness, and the highest frame rate it sustains
//! with no unintended loss.
//!
//! `cargo bench --bench overhead` runs everything with 10 s intervals, three
//! times (10 to 15 minutes on 2 cores); `NETFI_BENCH_FULL=1` runs the long
//! version (60 s intervals, 5 repetitions). Results go to
//! `target/netfi-bench/`: `overhead.json`, `overhead.md`, HdrHistogram logs
//! under `hlog/`, and each run's own files under `runs/`. The method is in
//! `docs/performance.md`; in short:
//!
//! - **Chain intervals.** A real `netfi emulator` process, pinned to the
//!   last core, runs a scenario between two ports. This benchmark plays both
//!   ends in *one* thread on another core: it sends frame after frame,
//!   alternately through the emulator (the chain) and straight to itself (the
//!   direct hop), and busy-polls both receive ports in between. Because the
//!   same thread sends and receives, no arrival ever waits for a sender to
//!   give up a core, and both routes see the same placement, the same load
//!   and the same moments. Added latency = chain − direct, percentile by
//!   percentile. Over iceoryx2 the frames carry the emulator's stamps, so the
//!   chain is also split into its first hop, the time inside the emulator
//!   and its second hop. Over UDP the ends are non-blocking, busy-polled
//!   loopback sockets and the send times are kept in a table by sequence.
//! - **Floor intervals.** No emulator: a sender thread on the first core and
//!   a receiver thread spinning on the emulator's core exchange frames over
//!   the same transport: the physical cost of one cross-core hop.
//! - **Probe.** A thread spinning on each core records the gaps between its
//!   clock reads: what interrupts, the hypervisor and other tasks take from
//!   any busy loop there, the emulator's included.
//! - **Delay interval.** The iceoryx2 chain through PLM-2 then DLM-2: release
//!   lateness while hundreds of frames wait for their times, and the
//!   end-to-end latency beyond the injected delay.
//! - **Product run.** `netfi run Normal` as shipped (console and simulator
//!   processes), for its own report of the same quantities.
//! - **Throughput.** `netfi run --no-direct` at rising rates (doubling, then
//!   bisection) for 10 s each; a rate is sustained when every frame is
//!   delivered or dropped by the scenario, nothing else.
//!
//! Each interval records the host's steal time, its load average and the
//! CPU that other processes used during it. Nothing
//! here asserts a time: the figures are printed and written beside the bars
//! of `docs/performance.md`, reported as met or not met.
//!
//! Settings (environment variables):
//!
//! | variable | default | meaning |
//! |---|---|---|
//! | `NETFI_BENCH_FULL` | unset | `1`: 60 s intervals, 5 repetitions |
//! | `NETFI_BENCH_SECONDS` | 10 (60 full) | length of each chain interval (floor intervals: half) |
//! | `NETFI_BENCH_REPS` | 3 (5 full) | repetitions of the latency, delay and product intervals |
//! | `NETFI_BENCH_RATES` | `1000,100000` | frame rates of the latency intervals, Hz |
//! | `NETFI_BENCH_PARTS` | all | comma list of `latency`, `delay`, `product`, `throughput` |
//! | `NETFI_BENCH_THROUGHPUT_S` | 10 | length of each throughput trial |
//! | `NETFI_BENCH_RT_PRIORITY` | unset | run the emulator and this benchmark's threads at this SCHED_FIFO priority |
//! | `NETFI_BENCH_QUIET_CORES` | unset | before each interval, wait until other processes keep at most this many cores busy |
//! | `NETFI_BENCH_QUIET_WAIT_S` | 600 | ... but for at most this long |
//! | `NETFI_BENCH_OUT` | `target/netfi-bench` | where results go |
//!
//! Arguments after `--` that are part names select parts too:
//! `cargo bench --bench overhead -- latency`.

use anyhow::{bail, Context, Result};
use netfi::clock::{now_ns, sleep_until_ns};
use netfi::frame::ItpFrame;
use netfi::host::CpuTimes;
use netfi::metrics::{fmt_ns, LatencyHistogram, Summary};
use netfi::sample::{FrameSample, ITP_FRAME_LEN};
use netfi::service::emulator::EmulatorReport;
use netfi::service::report::RunReport;
use netfi::service::signals::stop_requested;
use netfi::transport::udp::{PeerAddr, UdpOptions, UdpPort};
use netfi::transport::{Channel, FramePublisher, FrameSubscriber, IpcConfig, IpcNode, Role, RunId};
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const NETFI: &str = env!("CARGO_BIN_EXE_netfi");

/// The delay scenario of the delay interval and of the second throughput
/// search (the study's 30% loss followed by its 300 ms delay).
const PLM2_DLM2: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenarios/plm2_dlm2.toml");

/// Frames sent before recording starts, in seconds of the interval's rate:
/// page faults of fresh shared memory, cold caches and the first
/// connections stay out of the figures.
const WARMUP_S: f64 = 0.5;

/// Before a frame is due, the driving thread sleeps until this long before
/// it (when nothing is in flight), then polls: other work on its core runs
/// in the gaps instead of preempting it at random moments.
const SLEEP_SLACK_NS: u64 = 100_000;

/// Requested kernel buffers of the benchmark's own UDP sockets (the
/// emulator's are 4 MiB too).
const UDP_BUFFER_BYTES: usize = 4 << 20;

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` does not, and
    // this benchmark takes minutes, so it only says how to run it.
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !args.iter().any(|a| a == "--bench") {
        println!("overhead: a macro benchmark of several minutes; run it with `cargo bench --bench overhead`");
        return;
    }
    if let Err(e) = run(&args) {
        eprintln!("overhead benchmark failed: {e:#}");
        std::process::exit(1);
    }
}

/// What to run, from the environment and the arguments.
#[derive(Debug, Clone, Serialize)]
struct Settings {
    full: bool,
    interval_s: f64,
    floor_s: f64,
    repetitions: usize,
    rates_hz: Vec<f64>,
    parts: Vec<String>,
    throughput_trial_s: f64,
    rt_priority: Option<i32>,
    /// Wait before each interval until other processes keep at most this
    /// many cores busy, for at most this many seconds.
    quiet: Option<(f64, f64)>,
    out_dir: PathBuf,
    emulator_core: Option<usize>,
    driver_core: Option<usize>,
    /// Clear the emulator's core of every other thread and interrupt that
    /// may run elsewhere, for the whole benchmark (`netfi::host::isolate`).
    isolate: bool,
}

const PARTS: [&str; 5] = ["latency", "delay", "product", "throughput", "sockperf"];

impl Settings {
    fn from_env(args: &[String]) -> Result<Settings> {
        let var = |name: &str| std::env::var(name).ok().filter(|v| !v.trim().is_empty());
        let full = var("NETFI_BENCH_FULL").is_some_and(|v| v != "0");
        let num = |name: &str, default: f64| -> Result<f64> {
            match var(name) {
                Some(v) => v.trim().parse::<f64>().with_context(|| format!("{name}={v}: expected a number")),
                None => Ok(default),
            }
        };
        let interval_s = num("NETFI_BENCH_SECONDS", if full { 60.0 } else { 10.0 })?;
        let repetitions = num("NETFI_BENCH_REPS", if full { 5.0 } else { 3.0 })? as usize;
        let throughput_trial_s = num("NETFI_BENCH_THROUGHPUT_S", 10.0)?;
        anyhow::ensure!(interval_s > 0.0 && repetitions >= 1 && throughput_trial_s > 0.0, "intervals and repetitions must be positive");
        let rates_hz = match var("NETFI_BENCH_RATES") {
            Some(v) => v
                .split(',')
                .map(|r| r.trim().parse::<f64>().with_context(|| format!("NETFI_BENCH_RATES: `{r}` is not a rate in Hz")))
                .collect::<Result<Vec<f64>>>()?,
            None => vec![1000.0, 100_000.0],
        };
        anyhow::ensure!(rates_hz.iter().all(|r| r.is_finite() && *r > 0.0), "NETFI_BENCH_RATES: rates must be positive");
        let from_args: Vec<String> = args.iter().filter(|a| PARTS.contains(&a.as_str())).cloned().collect();
        let parts = match var("NETFI_BENCH_PARTS") {
            Some(v) => v.split(',').map(|p| p.trim().to_string()).collect(),
            None if !from_args.is_empty() => from_args,
            None => PARTS.iter().map(|p| p.to_string()).collect(),
        };
        if let Some(p) = parts.iter().find(|p| !PARTS.contains(&p.as_str())) {
            bail!("unknown part `{p}`; the parts are {}", PARTS.join(", "));
        }
        let rt_priority = match var("NETFI_BENCH_RT_PRIORITY") {
            Some(v) => Some(v.trim().parse::<i32>().with_context(|| format!("NETFI_BENCH_RT_PRIORITY={v}"))?),
            None => None,
        };
        let quiet = match var("NETFI_BENCH_QUIET_CORES") {
            Some(v) => Some((
                v.trim().parse::<f64>().with_context(|| format!("NETFI_BENCH_QUIET_CORES={v}: expected a number of cores"))?,
                num("NETFI_BENCH_QUIET_WAIT_S", 600.0)?,
            )),
            None => None,
        };
        let out_dir = match var("NETFI_BENCH_OUT") {
            Some(v) => PathBuf::from(v),
            None => Path::new(env!("CARGO_TARGET_TMPDIR")).parent().context("locating the target directory")?.join("netfi-bench"),
        };
        // The emulator gets the last core, the benchmark's driving thread
        // the first: the same placement as `netfi run` on a small machine.
        let cores: Vec<usize> = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect();
        let (emulator_core, driver_core) = match cores.as_slice() {
            [first, .., last] => (Some(*last), Some(*first)),
            _ => (None, None),
        };
        let isolate = var("NETFI_BENCH_ISOLATE").is_none_or(|v| v != "0");
        Ok(Settings {
            isolate,
            full,
            interval_s,
            floor_s: interval_s / 2.0,
            repetitions,
            rates_hz,
            parts,
            throughput_trial_s,
            rt_priority,
            quiet,
            out_dir,
            emulator_core,
            driver_core,
        })
    }

    fn wants(&self, part: &str) -> bool {
        self.parts.iter().any(|p| p == part)
    }
}

// ---------------------------------------------------------------------------
// The host: steal time and load average around every interval.

/// The host's state over one interval.
#[derive(Debug, Clone, Copy, Default, Serialize)]
struct HostWindow {
    steal_ms: u64,
    steal_fraction: f64,
    /// 1-minute load average at the start and at the end. It counts this
    /// benchmark's own busy threads too (up to 2 during an interval) and
    /// lags by about a minute.
    load_start: f64,
    load_end: f64,
    /// Cores kept busy by other processes over the half second before the
    /// interval, while this benchmark was idle: the background load.
    background_busy_cores: f64,
    /// Cores kept busy by other processes during the interval: all busy
    /// CPU time less this benchmark's and its children's, over the
    /// interval's length (10 ms resolution).
    others_busy_cores: f64,
    /// Seconds spent waiting for a quiet host before the interval.
    waited_for_quiet_s: f64,
}

struct HostTimer {
    cpu: Option<CpuTimes>,
    load: f64,
    background: f64,
    waited_s: f64,
    busy: Option<(u64, u64)>,
    own_s: f64,
    t0: Instant,
}

impl HostTimer {
    /// Starts an interval: first waits (up to the configured time) for the
    /// background load to fall to the configured level, if one is set.
    fn start(quiet: Option<(f64, f64)>) -> HostTimer {
        let t_wait = Instant::now();
        let mut background = busy_cores(Duration::from_millis(500));
        if let Some((cores, max_wait_s)) = quiet {
            let mut said = false;
            while background > cores && t_wait.elapsed().as_secs_f64() < max_wait_s && !stop_requested() {
                if !said {
                    println!("  (waiting for a quiet host: other processes keep {background:.2} cores busy, more than {cores})");
                    said = true;
                }
                std::thread::sleep(Duration::from_secs(5));
                background = busy_cores(Duration::from_millis(500));
            }
        }
        let waited_s = t_wait.elapsed().as_secs_f64() - 0.5;
        HostTimer { cpu: CpuTimes::read(), load: load_average(), background, waited_s, busy: cpu_ticks(), own_s: own_cpu_s(), t0: Instant::now() }
    }

    fn stop(&self) -> HostWindow {
        let steal = match (self.cpu, CpuTimes::read()) {
            (Some(a), Some(b)) => b.steal_since(&a),
            _ => Default::default(),
        };
        let elapsed = self.t0.elapsed().as_secs_f64();
        let others = match (self.busy, cpu_ticks()) {
            (Some((b0, _)), Some((b1, _))) if elapsed > 0.0 => {
                let busy_s = (b1 - b0) as f64 / ticks_per_s();
                ((busy_s - (own_cpu_s() - self.own_s)) / elapsed).max(0.0)
            }
            _ => f64::NAN,
        };
        HostWindow {
            steal_ms: steal.ms,
            steal_fraction: steal.fraction,
            load_start: self.load,
            load_end: load_average(),
            background_busy_cores: self.background,
            others_busy_cores: others,
            waited_for_quiet_s: self.waited_s.max(0.0),
        }
    }
}

fn ticks_per_s() -> f64 {
    // SAFETY: sysconf only reads a configuration value.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 {
        t as f64
    } else {
        100.0
    }
}

/// CPU seconds used by this process and by its children that have been
/// waited for (the emulator, `netfi run` and its services).
fn own_cpu_s() -> f64 {
    let secs = |who: libc::c_int| {
        // SAFETY: a zeroed rusage is a valid output buffer for getrusage.
        let mut u: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: `u` is a valid, writable rusage.
        if unsafe { libc::getrusage(who, &mut u) } != 0 {
            return 0.0;
        }
        let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
        tv(u.ru_utime) + tv(u.ru_stime)
    };
    secs(libc::RUSAGE_SELF) + secs(libc::RUSAGE_CHILDREN)
}

/// Busy and total ticks of all CPUs from `/proc/stat`. Busy is time spent
/// running tasks (user, nice, system): interrupt and softirq time is left
/// out, as the kernel bills it to no process (UDP loopback delivery runs
/// there), and steal is reported on its own.
fn cpu_ticks() -> Option<(u64, u64)> {
    CpuTimes::read().map(|c| (c.busy, c.total))
}

/// Cores busy on average over `window` (NaN where `/proc/stat` is unreadable).
fn busy_cores(window: Duration) -> f64 {
    let cores = core_affinity::get_core_ids().map_or(1, |c| c.len()) as f64;
    let a = cpu_ticks();
    std::thread::sleep(window);
    match (a, cpu_ticks()) {
        (Some((b0, t0)), Some((b1, t1))) if t1 > t0 => (b1 - b0) as f64 / (t1 - t0) as f64 * cores,
        _ => f64::NAN,
    }
}

fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg").ok().and_then(|s| s.split_whitespace().next().and_then(|x| x.parse().ok())).unwrap_or(f64::NAN)
}

fn host_facts(s: &Settings) -> Value {
    let read = |p: &str| std::fs::read_to_string(p).map(|t| t.trim().to_string()).unwrap_or_default();
    let cpuinfo = read("/proc/cpuinfo");
    let model = cpuinfo.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).unwrap_or("").trim().to_string();
    json!({
        "cores": core_affinity::get_core_ids().map_or(0, |c| c.len()),
        "cpu_model": model,
        "kernel": read("/proc/sys/kernel/osrelease"),
        "clocksource": read("/sys/devices/system/clocksource/clocksource0/current_clocksource"),
        "emulator_core": s.emulator_core,
        "driver_core": s.driver_core,
    })
}

// ---------------------------------------------------------------------------
// The benchmark's ends of a chain: send on a route, poll a route.

/// Which way a frame goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// Through the emulator.
    Chain,
    /// Straight to the receiving end, no emulator.
    Direct,
}

/// One frame that arrived.
#[derive(Debug, Clone, Copy)]
struct Arrival {
    slot: u64,
    recv_ns: u64,
    send_ns: u64,
    /// The emulator's stamps (iceoryx2 only): taken off its port, released.
    ingress_ns: u64,
    release_ns: u64,
    injected_delay_ns: u64,
}

trait Ends {
    /// Sends slot `slot`'s frame on `route`, stamping its send time as late
    /// as the transport allows. `false` if the transport refused it.
    fn send(&mut self, route: Route, slot: u64, wire: &[u8; ITP_FRAME_LEN]) -> bool;
    /// One waiting frame of `route`, stamped on arrival.
    fn poll(&mut self, route: Route) -> Option<Arrival>;
    /// Whether the emulator stamps its ingress and release times on frames.
    fn stamped(&self) -> bool;
}

/// The ITP frame of slot `slot`: a valid checksum, so the emulator's
/// validation passes it; the sequence identifies the slot (UDP carries
/// nothing else).
fn wire(slot: u64) -> [u8; ITP_FRAME_LEN] {
    ItpFrame { sequence: slot as u32, delx: [1, -1], surgeon_mode: 1, qw: [1.0, 1.0], ..ItpFrame::default() }.with_checksum().to_bytes()
}

struct IpcEnds {
    _console: IpcNode,
    _simulator: IpcNode,
    to_emulator: FramePublisher,
    direct_tx: FramePublisher,
    from_emulator: FrameSubscriber,
    direct_rx: FrameSubscriber,
}

impl IpcEnds {
    /// Opens the console's and the simulator's ports of run `run_id` and
    /// waits until the emulator is attached on both sides.
    fn open(run_id: &str) -> Result<IpcEnds> {
        let cfg = IpcConfig::new(RunId::new(run_id)?);
        let console = IpcNode::open(&cfg, Role::Console)?;
        let simulator = IpcNode::open(&cfg, Role::Simulator)?;
        let to_emulator = console.publisher(Channel::Console)?;
        let direct_tx = console.publisher(Channel::Direct)?;
        let from_emulator = simulator.subscriber(Channel::Emulator)?;
        let direct_rx = simulator.subscriber(Channel::Direct)?;
        let mut ends = IpcEnds { _console: console, _simulator: simulator, to_emulator, direct_tx, from_emulator, direct_rx };
        let t0 = Instant::now();
        while ends.to_emulator.peers_connected() == 0 || ends.from_emulator.peers_connected() == 0 || ends.direct_tx.peers_connected() == 0 {
            // Polling attaches the subscribers to the publishers.
            let _ = ends.from_emulator.try_recv();
            let _ = ends.direct_rx.try_recv();
            anyhow::ensure!(t0.elapsed() < Duration::from_secs(10), "the emulator of run {run_id} did not attach within 10 s");
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(ends)
    }

    fn end(&mut self, chain_sent: u64) {
        let _ = self.to_emulator.send(&FrameSample::end_marker(chain_sent));
    }
}

impl Ends for IpcEnds {
    #[inline]
    fn send(&mut self, route: Route, slot: u64, wire: &[u8; ITP_FRAME_LEN]) -> bool {
        let port = match route {
            Route::Chain => &mut self.to_emulator,
            Route::Direct => &mut self.direct_tx,
        };
        port.send_with(|s| {
            s.len = ITP_FRAME_LEN as u32;
            s.wire = *wire;
            s.console_index = slot;
            s.send_ns = now_ns();
        })
        .is_ok_and(|n| n > 0)
    }

    #[inline]
    fn poll(&mut self, route: Route) -> Option<Arrival> {
        let port = match route {
            Route::Chain => &mut self.from_emulator,
            Route::Direct => &mut self.direct_rx,
        };
        let got = port.recv_with(|s| {
            let recv_ns = now_ns();
            (!s.is_end()).then_some(Arrival {
                slot: s.console_index,
                recv_ns,
                send_ns: s.send_ns,
                ingress_ns: s.ingress_ns,
                release_ns: s.release_ns,
                injected_delay_ns: s.injected_delay_ns,
            })
        });
        got.ok().flatten().flatten()
    }

    fn stamped(&self) -> bool {
        true
    }
}

struct UdpEnds {
    tx: UdpPort,
    emulator_in: PeerAddr,
    direct_to: PeerAddr,
    rx_chain: UdpPort,
    rx_direct: UdpPort,
    /// Send time of each slot: UDP carries no metadata.
    sent_ns: Vec<u64>,
    buf: [u8; 256],
}

impl UdpEnds {
    fn new(rx_chain: UdpPort, emulator_in: SocketAddr, slots: u64) -> Result<UdpEnds> {
        let opts = UdpOptions { reuse_address: false, buffer_bytes: Some(UDP_BUFFER_BYTES) };
        let loopback: SocketAddr = "127.0.0.1:0".parse().expect("a literal address");
        let tx = UdpPort::bind(loopback, &opts)?;
        let rx_direct = UdpPort::bind(loopback, &opts)?;
        let direct_to = PeerAddr::new(rx_direct.local_addr());
        // Written once here (not zero-allocated), so the table's pages are
        // resident and no page fault lands between a stamp and its send.
        let sent_ns = vec![u64::MAX; slots as usize];
        Ok(UdpEnds { tx, emulator_in: PeerAddr::new(emulator_in), direct_to, rx_chain, rx_direct, sent_ns, buf: [0; 256] })
    }
}

impl Ends for UdpEnds {
    #[inline]
    fn send(&mut self, route: Route, slot: u64, wire: &[u8; ITP_FRAME_LEN]) -> bool {
        let to = match route {
            Route::Chain => &self.emulator_in,
            Route::Direct => &self.direct_to,
        };
        self.sent_ns[slot as usize] = now_ns();
        self.tx.send_to(wire, to).is_ok()
    }

    #[inline]
    fn poll(&mut self, route: Route) -> Option<Arrival> {
        let port = match route {
            Route::Chain => &self.rx_chain,
            Route::Direct => &self.rx_direct,
        };
        let d = port.recv_from(&mut self.buf).ok().flatten()?;
        let recv_ns = now_ns();
        if d.len != ITP_FRAME_LEN {
            return None;
        }
        let slot = u64::from(u32::from_le_bytes([self.buf[0], self.buf[1], self.buf[2], self.buf[3]]));
        let send_ns = *self.sent_ns.get(slot as usize).filter(|t| **t != u64::MAX)?;
        Some(Arrival { slot, recv_ns, send_ns, ingress_ns: 0, release_ns: 0, injected_delay_ns: 0 })
    }

    fn stamped(&self) -> bool {
        false
    }
}

// ---------------------------------------------------------------------------
// Driving a chain interval.

/// What one chain interval measured on the benchmark's side.
#[derive(Debug, Clone, Default)]
struct Drive {
    /// Receive − send − injected delay, through the emulator.
    chain: LatencyHistogram,
    /// Receive − send, straight.
    direct: LatencyHistogram,
    /// Chain split by the emulator's stamps (iceoryx2): send → taken off
    /// its port; taken → released; released → received.
    hop1: LatencyHistogram,
    inside: LatencyHistogram,
    hop2: LatencyHistogram,
    /// Actual − planned send time.
    send_lateness: LatencyHistogram,
    chain_sent: u64,
    chain_received: u64,
    direct_sent: u64,
    direct_received: u64,
    refused: u64,
    seconds: f64,
}

/// Slots of an interval: `warmup + frames` per route, alternating chain
/// (even slots) and direct (odd slots), half a period apart.
fn slots_for(rate_hz: f64, seconds: f64) -> (u64, u64) {
    let warmup = (rate_hz * WARMUP_S).ceil() as u64;
    let frames = (rate_hz * seconds).round() as u64;
    (2 * warmup, 2 * (warmup + frames))
}

/// Sends every slot at its time and busy-polls both routes in between, in
/// one thread; then waits up to `drain_ns` for the chain's last frames.
fn drive(ends: &mut impl Ends, rate_hz: f64, seconds: f64, drain_ns: u64, may_sleep: bool) -> Drive {
    let (warm, slots) = slots_for(rate_hz, seconds);
    let half_period_ns = 1e9 / rate_hz / 2.0;
    let mut d = Drive::default();
    let stamped = ends.stamped();
    let t0 = now_ns() + 1_000_000;
    let mut slot = 0u64;
    let mut t_record = 0u64;
    let mut drain_until = u64::MAX;
    loop {
        let now = now_ns();
        if stop_requested() {
            break;
        }
        if slot < slots {
            let target = t0 + (slot as f64 * half_period_ns) as u64;
            if now >= target {
                let route = if slot % 2 == 0 { Route::Chain } else { Route::Direct };
                let ok = ends.send(route, slot, &wire(slot));
                match (route, ok) {
                    (Route::Chain, true) => d.chain_sent += 1,
                    (Route::Direct, true) => d.direct_sent += 1,
                    (_, false) => d.refused += 1,
                }
                if slot >= warm {
                    if slot == warm {
                        t_record = now;
                    }
                    d.send_lateness.record(now - target);
                }
                slot += 1;
                if slot == slots {
                    drain_until = now_ns() + drain_ns;
                }
            }
        }
        while let Some(a) = ends.poll(Route::Chain) {
            d.chain_received += 1;
            if a.slot >= warm {
                d.chain.record_signed(a.recv_ns as i64 - a.send_ns as i64 - a.injected_delay_ns as i64);
                if stamped {
                    d.hop1.record_signed(a.ingress_ns as i64 - a.send_ns as i64);
                    d.inside.record_signed(a.release_ns as i64 - a.ingress_ns as i64 - a.injected_delay_ns as i64);
                    d.hop2.record_signed(a.recv_ns as i64 - a.release_ns as i64);
                }
            }
        }
        while let Some(a) = ends.poll(Route::Direct) {
            d.direct_received += 1;
            if a.slot >= warm {
                d.direct.record_signed(a.recv_ns as i64 - a.send_ns as i64);
            }
        }
        let in_flight = d.chain_sent > d.chain_received || d.direct_sent > d.direct_received;
        if slot == slots {
            if !in_flight || now_ns() > drain_until {
                break;
            }
        } else if may_sleep && !in_flight {
            let target = t0 + (slot as f64 * half_period_ns) as u64;
            if target > now_ns() + 2 * SLEEP_SLACK_NS {
                sleep_until_ns(target - SLEEP_SLACK_NS);
            }
        }
    }
    d.seconds = (now_ns().saturating_sub(t_record)) as f64 / 1e9;
    d
}

/// Pins the calling thread to `core` and, when asked, moves it to
/// SCHED_FIFO at `rt_priority`.
fn pin(core: Option<usize>, rt_priority: Option<i32>) {
    if let Some(c) = core {
        if !core_affinity::set_for_current(core_affinity::CoreId { id: c }) {
            eprintln!("overhead: could not pin a thread to core {c}");
        }
    }
    if let Some(p) = rt_priority {
        if let Err(e) = netfi::service::set_realtime(p) {
            eprintln!("overhead: SCHED_FIFO {p} refused ({e}); staying at normal priority");
        }
    }
}

// ---------------------------------------------------------------------------
// The emulator process.

struct Emulator {
    child: Child,
    dir: PathBuf,
}

fn emulator_common(s: &Settings, scenario: &str, dir: &Path, expected_frames: u64) -> Vec<String> {
    let mut a: Vec<String> = vec![
        "emulator".into(),
        "--scenario".into(),
        scenario.into(),
        "--seed".into(),
        "1".into(),
        "--out".into(),
        dir.display().to_string(),
        "--expected-frames".into(),
        expected_frames.to_string(),
    ];
    match s.emulator_core {
        Some(c) => a.extend(["--core".into(), c.to_string()]),
        None => a.push("--no-pin".into()),
    }
    if let Some(p) = s.rt_priority {
        a.extend(["--rt-priority".into(), p.to_string()]);
    }
    a
}

impl Emulator {
    fn spawn(dir: &Path, args: &[String]) -> Result<Emulator> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for stale in ["emulator.ready", "emulator.json", "udp_endpoints.json", "udp.json"] {
            let _ = std::fs::remove_file(dir.join(stale));
        }
        let log = std::fs::File::create(dir.join("emulator.log"))?;
        let child =
            Command::new(NETFI).args(args).stdin(Stdio::null()).stdout(log.try_clone()?).stderr(log).spawn().with_context(|| format!("starting {NETFI}"))?;
        let mut e = Emulator { child, dir: dir.to_path_buf() };
        let t0 = Instant::now();
        while !dir.join("emulator.ready").exists() {
            if let Ok(Some(status)) = e.child.try_wait() {
                bail!("the emulator ended before it was ready ({status}); see {}", dir.join("emulator.log").display());
            }
            if t0.elapsed() > Duration::from_secs(30) {
                e.stop();
                bail!("the emulator was not ready after 30 s; see {}", dir.join("emulator.log").display());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Ok(e)
    }

    /// Waits up to `wait` for the emulator to end by itself, then stops it;
    /// returns its report.
    fn finish(mut self, wait: Duration) -> Result<EmulatorReport> {
        let t0 = Instant::now();
        while t0.elapsed() < wait {
            if let Ok(Some(_)) = self.child.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        self.stop();
        let path = self.dir.join("emulator.json");
        let report: EmulatorReport = serde_json::from_slice(&std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?)
            .with_context(|| format!("parsing {}", path.display()))?;
        // The per-frame trace is not needed here, and at 100 kHz it is large.
        let _ = std::fs::remove_file(self.dir.join("trace_emulator.csv"));
        Ok(report)
    }

    fn stop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            // SAFETY: signalling our own child by its pid.
            unsafe {
                libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
            }
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(10) {
                if let Ok(Some(_)) = self.child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop();
    }
}

static RUN_COUNTER: AtomicU64 = AtomicU64::new(0);

fn fresh_run_id() -> String {
    format!("bench{}n{}", std::process::id(), RUN_COUNTER.fetch_add(1, Ordering::Relaxed))
}

// ---------------------------------------------------------------------------
// Intervals.

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
enum Transport {
    Iceoryx2,
    Udp,
}

impl Transport {
    fn name(self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Udp => "udp",
        }
    }
}

/// One chain interval's results.
#[derive(Debug, Clone, Serialize)]
struct ChainResult {
    name: String,
    repetition: usize,
    transport: Transport,
    scenario: String,
    rate_hz: f64,
    seconds: f64,
    host: HostWindow,
    chain_ns: Summary,
    direct_ns: Summary,
    /// `chain − direct`, percentile by percentile.
    added_ns: BTreeMap<String, i64>,
    hop1_ns: Option<Summary>,
    inside_ns: Option<Summary>,
    hop2_ns: Option<Summary>,
    send_lateness_ns: Summary,
    chain_sent: u64,
    chain_received: u64,
    direct_sent: u64,
    direct_received: u64,
    refused: u64,
    emulator: EmulatorFigures,
    hlogs: Vec<PathBuf>,
}

/// The emulator's own figures of an interval (from `emulator.json`).
#[derive(Debug, Clone, Serialize)]
struct EmulatorFigures {
    entered: u64,
    delivered: u64,
    dropped: BTreeMap<String, u64>,
    held_at_end: u64,
    decision_ns: Summary,
    release_lateness_ns: Summary,
    ingress_wait_ns: Summary,
    steal_fraction: f64,
    realtime_priority: Option<i32>,
    out_dir: PathBuf,
}

impl EmulatorFigures {
    fn from(r: &EmulatorReport, dir: &Path) -> EmulatorFigures {
        EmulatorFigures {
            entered: r.process.frames.entered,
            delivered: r.process.frames.delivered,
            dropped: r.process.frames.dropped.clone(),
            held_at_end: r.process.frames.held_at_end,
            decision_ns: r.shaping.link.decision_ns,
            release_lateness_ns: r.shaping.link.release_lateness_ns,
            ingress_wait_ns: r.shaping.link.ingress_wait_ns,
            steal_fraction: r.process.steal_fraction,
            realtime_priority: r.process.realtime_priority,
            out_dir: dir.to_path_buf(),
        }
    }
}

/// One floor interval's results.
#[derive(Debug, Clone, Serialize)]
struct FloorResult {
    name: String,
    repetition: usize,
    transport: Transport,
    rate_hz: f64,
    seconds: f64,
    host: HostWindow,
    hop_ns: Summary,
    sent: u64,
    received: u64,
    hlog: PathBuf,
}

/// `a − b` for every percentile and the maximum.
fn difference(a: &Summary, b: &Summary) -> BTreeMap<String, i64> {
    netfi::metrics::difference(a, b, &KEYS)
}

fn rate_label(rate_hz: f64) -> String {
    if rate_hz >= 1000.0 && (rate_hz / 1000.0).fract() == 0.0 {
        format!("{}k", rate_hz / 1000.0)
    } else {
        format!("{rate_hz}")
    }
}

fn write_hlog(h: &LatencyHistogram, dir: &Path, name: &str, tag: &str, seconds: f64) -> Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join(format!("{name}.hlog"));
    h.write_log(&path, tag, 0.0, seconds).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// A chain interval: the emulator between the benchmark's two ends over
/// `transport`, at `rate_hz` per route, for `seconds`.
fn chain_interval(s: &Settings, transport: Transport, scenario: &str, scenario_label: &str, rate_hz: f64, seconds: f64, rep: usize) -> Result<ChainResult> {
    check_interrupted()?;
    let name = format!("chain-{}-{}-{}-r{rep}", transport.name(), scenario_label, rate_label(rate_hz));
    let dir = s.out_dir.join("runs").join(&name);
    let _ = std::fs::remove_dir_all(&dir);
    let (_, slots) = slots_for(rate_hz, seconds);
    let expected = slots / 2 + 16;
    let delayed = scenario_label != "normal";
    // Frames still held by a delay scenario when the last one is sent.
    let drain_ns: u64 = if delayed { 5_000_000_000 } else { 200_000_000 };
    let host = HostTimer::start(s.quiet);
    let (drive, report) = match transport {
        Transport::Iceoryx2 => {
            let run_id = fresh_run_id();
            let mut args = emulator_common(s, scenario, &dir, expected);
            args.extend(["--run-id".into(), run_id.clone()]);
            let emu = Emulator::spawn(&dir, &args)?;
            let (core, rt) = (s.driver_core, s.rt_priority);
            let handle = std::thread::spawn(move || -> Result<Drive> {
                pin(core, rt);
                let mut ends = IpcEnds::open(&run_id)?;
                let d = drive(&mut ends, rate_hz, seconds, drain_ns, !delayed);
                ends.end(d.chain_sent);
                // Keep the ports open until the emulator has seen the end.
                std::thread::sleep(Duration::from_millis(50));
                Ok(d)
            });
            let d = handle.join().map_err(|_| anyhow::anyhow!("the driving thread panicked"))?;
            check_interrupted()?;
            let d = match d {
                Ok(d) => d,
                Err(e) => {
                    let _ = emu.finish(Duration::ZERO);
                    return Err(e);
                }
            };
            (d, emu.finish(Duration::from_secs(10))?)
        }
        Transport::Udp => {
            let opts = UdpOptions { reuse_address: false, buffer_bytes: Some(UDP_BUFFER_BYTES) };
            let rx_chain = UdpPort::bind("127.0.0.1:0".parse().expect("a literal address"), &opts)?;
            let mut args = emulator_common(s, scenario, &dir, expected);
            args.extend([
                "--ingress".into(),
                "udp://127.0.0.1:0".into(),
                "--egress".into(),
                format!("udp://{}", rx_chain.local_addr()),
                "--payload".into(),
                "itp".into(),
                "--no-return".into(),
                "--idle-end-ms".into(),
                "300".into(),
            ]);
            let emu = Emulator::spawn(&dir, &args)?;
            let endpoints: Value = serde_json::from_slice(&std::fs::read(dir.join("udp_endpoints.json"))?)?;
            let ingress: SocketAddr = endpoints["ingress"].as_str().context("udp_endpoints.json: no ingress")?.parse()?;
            let (core, rt) = (s.driver_core, s.rt_priority);
            let handle = std::thread::spawn(move || -> Result<Drive> {
                pin(core, rt);
                let mut ends = UdpEnds::new(rx_chain, ingress, slots)?;
                Ok(drive(&mut ends, rate_hz, seconds, drain_ns, !delayed))
            });
            let d = handle.join().map_err(|_| anyhow::anyhow!("the driving thread panicked"))??;
            check_interrupted()?;
            (d, emu.finish(Duration::from_secs(10))?)
        }
    };
    let host = host.stop();
    let hdir = s.out_dir.join("hlog");
    let mut hlogs = vec![
        write_hlog(&drive.chain, &hdir, &format!("{name}-chain"), "chain", drive.seconds)?,
        write_hlog(&drive.direct, &hdir, &format!("{name}-direct"), "direct", drive.seconds)?,
    ];
    let stamped = transport == Transport::Iceoryx2;
    if stamped {
        hlogs.push(write_hlog(&drive.hop1, &hdir, &format!("{name}-hop1"), "hop1", drive.seconds)?);
        hlogs.push(write_hlog(&drive.inside, &hdir, &format!("{name}-inside"), "inside", drive.seconds)?);
        hlogs.push(write_hlog(&drive.hop2, &hdir, &format!("{name}-hop2"), "hop2", drive.seconds)?);
    }
    hlogs.push(dir.join("lateness.hlog"));
    hlogs.push(dir.join("decision.hlog"));
    let (chain_ns, direct_ns) = (drive.chain.summary(), drive.direct.summary());
    Ok(ChainResult {
        name,
        repetition: rep,
        transport,
        scenario: report.process.scenario.clone(),
        rate_hz,
        seconds: drive.seconds,
        host,
        added_ns: difference(&chain_ns, &direct_ns),
        chain_ns,
        direct_ns,
        hop1_ns: stamped.then(|| drive.hop1.summary()),
        inside_ns: stamped.then(|| drive.inside.summary()),
        hop2_ns: stamped.then(|| drive.hop2.summary()),
        send_lateness_ns: drive.send_lateness.summary(),
        chain_sent: drive.chain_sent,
        chain_received: drive.chain_received,
        direct_sent: drive.direct_sent,
        direct_received: drive.direct_received,
        refused: drive.refused,
        emulator: EmulatorFigures::from(&report, &dir),
        hlogs,
    })
}

/// A floor interval: a sender on the driving core, a receiver spinning on
/// the emulator's core, one hop of `transport`, no emulator.
fn floor_interval(s: &Settings, transport: Transport, rate_hz: f64, seconds: f64, rep: usize) -> Result<FloorResult> {
    check_interrupted()?;
    let name = format!("floor-{}-{}-r{rep}", transport.name(), rate_label(rate_hz));
    let warm = (rate_hz * WARMUP_S).ceil() as u64;
    let frames = warm + (rate_hz * seconds).round() as u64;
    let period_ns = 1e9 / rate_hz;
    let done = Arc::new(AtomicBool::new(false));
    let host = HostTimer::start(s.quiet);
    let (tx_core, rx_core, rt) = (s.driver_core, s.emulator_core, s.rt_priority);
    let (sent, hist, received, secs) = match transport {
        Transport::Iceoryx2 => {
            let run_id = fresh_run_id();
            let (ready_tx, ready_rx) = std::sync::mpsc::channel::<()>();
            let rid = run_id.clone();
            let done_rx = done.clone();
            let receiver = std::thread::spawn(move || -> Result<(LatencyHistogram, u64)> {
                pin(rx_core, rt);
                let node = IpcNode::open(&IpcConfig::new(RunId::new(&rid)?), Role::Simulator)?;
                let mut sub = node.subscriber(Channel::Direct)?;
                let _ = ready_tx.send(());
                let (mut h, mut n) = (LatencyHistogram::new(), 0u64);
                loop {
                    match sub.recv_with(|f| (now_ns(), *f)) {
                        Ok(Some((t, f))) if f.is_end() => {
                            let _ = t;
                            break;
                        }
                        Ok(Some((t, f))) => {
                            n += 1;
                            if f.console_index >= warm {
                                h.record_signed(t as i64 - f.send_ns as i64);
                            }
                        }
                        _ => {
                            if done_rx.load(Ordering::Acquire) {
                                break;
                            }
                            std::hint::spin_loop();
                        }
                    }
                }
                Ok((h, n))
            });
            ready_rx.recv_timeout(Duration::from_secs(10)).context("the floor receiver did not start")?;
            let core = tx_core;
            let sender = std::thread::spawn(move || -> Result<(u64, f64)> {
                pin(core, rt);
                let node = IpcNode::open(&IpcConfig::new(RunId::new(&run_id)?), Role::Console)?;
                let mut publ = node.publisher(Channel::Direct)?;
                let t = Instant::now();
                while publ.peers_connected() == 0 {
                    anyhow::ensure!(t.elapsed() < Duration::from_secs(10), "the floor receiver did not attach");
                    std::thread::sleep(Duration::from_millis(1));
                }
                std::thread::sleep(Duration::from_millis(20));
                let (sent, secs) = pace(frames, period_ns, warm, |i| {
                    publ.send_with(|f| {
                        f.len = ITP_FRAME_LEN as u32;
                        f.console_index = i;
                        f.send_ns = now_ns();
                    })
                    .is_ok_and(|n| n > 0)
                });
                std::thread::sleep(Duration::from_millis(20));
                let _ = publ.send(&FrameSample::end_marker(sent));
                std::thread::sleep(Duration::from_millis(20));
                Ok((sent, secs))
            });
            let (sent, secs) = sender.join().map_err(|_| anyhow::anyhow!("the floor sender panicked"))??;
            done.store(true, Ordering::Release);
            let (h, n) = receiver.join().map_err(|_| anyhow::anyhow!("the floor receiver panicked"))??;
            check_interrupted()?;
            (sent, h, n, secs)
        }
        Transport::Udp => {
            let opts = UdpOptions { reuse_address: false, buffer_bytes: Some(UDP_BUFFER_BYTES) };
            let rx = UdpPort::bind("127.0.0.1:0".parse().expect("a literal address"), &opts)?;
            let to = PeerAddr::new(rx.local_addr());
            let sent_ns: Arc<Vec<AtomicU64>> = Arc::new((0..frames).map(|_| AtomicU64::new(0)).collect());
            let (sent_r, done_r) = (sent_ns.clone(), done.clone());
            let receiver = std::thread::spawn(move || -> (LatencyHistogram, u64) {
                pin(rx_core, rt);
                let (mut h, mut n, mut buf) = (LatencyHistogram::new(), 0u64, [0u8; 256]);
                loop {
                    match rx.recv_from(&mut buf) {
                        Ok(Some(_)) => {
                            let t = now_ns();
                            n += 1;
                            let i = u64::from(u32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]));
                            if i >= warm {
                                if let Some(s) = sent_r.get(i as usize) {
                                    h.record_signed(t as i64 - s.load(Ordering::Acquire) as i64);
                                }
                            }
                        }
                        _ => {
                            if done_r.load(Ordering::Acquire) {
                                break;
                            }
                            std::hint::spin_loop();
                        }
                    }
                }
                (h, n)
            });
            let core = tx_core;
            let sender = std::thread::spawn(move || -> Result<(u64, f64)> {
                pin(core, rt);
                let tx = UdpPort::bind("127.0.0.1:0".parse().expect("a literal address"), &opts)?;
                Ok(pace(frames, period_ns, warm, |i| {
                    let w = wire(i);
                    sent_ns[i as usize].store(now_ns(), Ordering::Release);
                    tx.send_to(&w, &to).is_ok()
                }))
            });
            let (sent, secs) = sender.join().map_err(|_| anyhow::anyhow!("the floor sender panicked"))??;
            std::thread::sleep(Duration::from_millis(50));
            done.store(true, Ordering::Release);
            let (h, n) = receiver.join().map_err(|_| anyhow::anyhow!("the floor receiver panicked"))?;
            check_interrupted()?;
            (sent, h, n, secs)
        }
    };
    let host = host.stop();
    let hlog = write_hlog(&hist, &s.out_dir.join("hlog"), &name, "floor", secs)?;
    Ok(FloorResult { name, repetition: rep, transport, rate_hz, seconds: secs, host, hop_ns: hist.summary(), sent, received, hlog })
}

/// What a thread spinning on one core (with nothing else to do) loses to
/// the machine: the gaps between consecutive clock reads.
#[derive(Debug, Clone, Serialize)]
struct ProbeResult {
    repetition: usize,
    core: Option<usize>,
    seconds: f64,
    host: HostWindow,
    /// Lengths of the gaps longer than 2 µs.
    gaps_ns: Summary,
    /// Gaps longer than 10 µs, 100 µs and 1 ms, per second.
    gaps_over_10us_per_s: f64,
    gaps_over_100us_per_s: f64,
    gaps_over_1ms_per_s: f64,
    /// Share of the time spent in gaps longer than 10 µs.
    lost_fraction: f64,
    hlog: PathBuf,
}

/// Spins one thread on the emulator's core and one on the driving core
/// for `seconds`, each reading the clock, and records every gap between
/// two reads longer than 2 µs: the interruptions (interrupts, the
/// hypervisor, other tasks) that any busy loop there suffers, the
/// emulator's and the benchmark's included.
fn probe_interval(s: &Settings, seconds: f64, rep: usize) -> Result<Vec<ProbeResult>> {
    check_interrupted()?;
    let host = HostTimer::start(s.quiet);
    let rt = s.rt_priority;
    let mut cores = vec![s.emulator_core];
    if s.driver_core != s.emulator_core {
        cores.push(s.driver_core);
    }
    let threads: Vec<_> = cores
        .iter()
        .map(|&core| {
            std::thread::spawn(move || {
                pin(core, rt);
                let mut h = LatencyHistogram::new();
                let (mut lost_ns, mut over) = (0u64, [0u64; 3]);
                let t0 = now_ns();
                let end = t0 + (seconds * 1e9) as u64;
                let mut prev = t0;
                loop {
                    let t = now_ns();
                    let gap = t - prev;
                    prev = t;
                    if gap > 2_000 {
                        h.record(gap);
                        if gap > 10_000 {
                            lost_ns += gap;
                            over[0] += 1;
                        }
                        over[1] += u64::from(gap > 100_000);
                        over[2] += u64::from(gap > 1_000_000);
                    }
                    if t >= end || (gap > 2_000 && stop_requested()) {
                        break;
                    }
                }
                (core, h, lost_ns, over)
            })
        })
        .collect();
    let mut done = Vec::new();
    for t in threads {
        done.push(t.join().map_err(|_| anyhow::anyhow!("a probe thread panicked"))?);
    }
    check_interrupted()?;
    let host = host.stop();
    let mut out = Vec::new();
    for (core, h, lost_ns, over) in done {
        let name = format!("probe-core{}-r{rep}", core.map_or("-".into(), |c| c.to_string()));
        let hlog = write_hlog(&h, &s.out_dir.join("hlog"), &name, "gap", seconds)?;
        out.push(ProbeResult {
            repetition: rep,
            core,
            seconds,
            host,
            gaps_ns: h.summary(),
            gaps_over_10us_per_s: over[0] as f64 / seconds,
            gaps_over_100us_per_s: over[1] as f64 / seconds,
            gaps_over_1ms_per_s: over[2] as f64 / seconds,
            lost_fraction: lost_ns as f64 / (seconds * 1e9),
            hlog,
        });
    }
    Ok(out)
}

/// Calls `send(i)` for `i` in `0..frames` at `period_ns` apart, sleeping
/// until shortly before each when there is time; returns the frames the
/// transport took and the seconds after the warm-up.
fn pace(frames: u64, period_ns: f64, warm: u64, mut send: impl FnMut(u64) -> bool) -> (u64, f64) {
    let t0 = now_ns() + 1_000_000;
    let mut sent = 0;
    let mut t_record = t0;
    for i in 0..frames {
        if stop_requested() {
            break;
        }
        let target = t0 + (i as f64 * period_ns) as u64;
        if target > now_ns() + 2 * SLEEP_SLACK_NS {
            sleep_until_ns(target - SLEEP_SLACK_NS);
        }
        while now_ns() < target {
            std::hint::spin_loop();
        }
        if i == warm {
            t_record = now_ns();
        }
        if send(i) {
            sent += 1;
        }
    }
    (sent, (now_ns() - t_record) as f64 / 1e9)
}

// ---------------------------------------------------------------------------
// The product run and the throughput search (`netfi run`).

fn netfi_run(dir: &Path, scenario: &str, rate_hz: f64, seconds: f64, extra: &[&str]) -> Result<RunReport> {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir)?;
    let log = std::fs::File::create(dir.join("run.log"))?;
    let mut child = Command::new(NETFI)
        .args(["run", scenario, "--rate-hz", &rate_hz.to_string(), "--duration-s", &seconds.to_string(), "--seed", "1", "--out"])
        .arg(dir)
        .args(extra)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("running {NETFI} run"))?;
    // Polled rather than waited for, so that a stop of the benchmark alone
    // (SIGTERM, or Ctrl-C outside a terminal) reaches the run too.
    let mut signalled = false;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if stop_requested() && !signalled {
            signalled = true;
            // SAFETY: signalling our own child by its pid.
            unsafe {
                libc::kill(child.id() as libc::pid_t, libc::SIGINT);
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    check_interrupted()?;
    let path = dir.join("report.json");
    let report: RunReport = serde_json::from_slice(&std::fs::read(&path).with_context(|| format!("reading {} (netfi run: {status})", path.display()))?)
        .with_context(|| format!("parsing {}", path.display()))?;
    for big in ["trace.csv", "received.csv"] {
        let _ = std::fs::remove_file(dir.join(big));
    }
    Ok(report)
}

/// One throughput trial.
#[derive(Debug, Clone, Serialize)]
struct Trial {
    rate_hz: f64,
    sustained: bool,
    /// Why not, or what limited it.
    verdict: String,
    console_rate_hz: Option<f64>,
    sent: Option<u64>,
    entered: Option<u64>,
    delivered: Option<u64>,
    received: Option<u64>,
    dropped: BTreeMap<String, u64>,
    console_send_errors: Option<u64>,
    emulator_send_errors: Option<u64>,
    ingress_wait_p99_ns: Option<u64>,
    release_lateness_p99_ns: Option<u64>,
    steal_fraction: f64,
    host: HostWindow,
    out_dir: PathBuf,
}

/// Runs one trial and judges it: sustained when the console offered the
/// rate, the run balanced (every frame delivered or dropped by the scenario)
/// and nothing was refused or dropped for want of room.
fn trial(s: &Settings, label: &str, scenario: &str, rate_hz: f64) -> Result<Trial> {
    check_interrupted()?;
    let dir = s.out_dir.join("runs").join(format!("throughput-{label}-{}", rate_hz as u64));
    // The release queue holds one second of frames, so a delay scenario
    // tests the emulator's speed rather than the queue's size.
    let queue = (rate_hz as u64).max(1 << 16).to_string();
    let host = HostTimer::start(s.quiet);
    let r = netfi_run(&dir, scenario, rate_hz, s.throughput_trial_s, &["--no-direct", "--queue-capacity", &queue])?;
    let host = host.stop();
    let f = &r.frames;
    let console_rate = r.console.as_ref().map(|c| c.rate_hz);
    let console_errors = r.console.as_ref().map(|c| c.send_errors);
    let emu_errors = r.emulator.as_ref().map(|e| e.send_errors);
    let unintended: Vec<String> =
        f.dropped.iter().filter(|(k, _)| matches!(k.as_str(), "queue_full" | "wrong_size" | "bad_checksum")).map(|(k, v)| format!("{v} {k}")).collect();
    let verdict = if !r.faults.is_empty() && !f.balanced {
        format!("lost frames: {}", r.faults.join("; "))
    } else if !r.faults.is_empty() {
        format!("fault: {}", r.faults.join("; "))
    } else if !unintended.is_empty() {
        format!("dropped outside the scenario: {}", unintended.join(", "))
    } else if !f.balanced {
        "not balanced".to_string()
    } else if console_rate.is_some_and(|c| c < 0.98 * rate_hz) {
        format!("the console paced only {:.0} frames/s", console_rate.unwrap_or(0.0))
    } else {
        "sustained".to_string()
    };
    Ok(Trial {
        rate_hz,
        sustained: verdict == "sustained",
        verdict,
        console_rate_hz: console_rate,
        sent: f.sent,
        entered: f.entered,
        delivered: f.delivered,
        received: f.received,
        dropped: f.dropped.clone(),
        console_send_errors: console_errors,
        emulator_send_errors: emu_errors,
        ingress_wait_p99_ns: r.overhead_ns.ingress_wait.map(|p| p.p99),
        release_lateness_p99_ns: r.overhead_ns.release_lateness.map(|p| p.p99),
        steal_fraction: r.steal.fraction,
        host,
        out_dir: dir,
    })
}

/// Doubling from `start_hz` until a rate fails, then bisection to 5%.
fn search(s: &Settings, label: &str, scenario: &str, start_hz: f64, max_hz: f64) -> Result<(f64, Vec<Trial>)> {
    let mut trials = Vec::new();
    let run = |rate: f64, trials: &mut Vec<Trial>| -> Result<bool> {
        let t = trial(s, label, scenario, rate)?;
        println!(
            "  throughput {label} {:>9.0} frames/s: {} (console {:.0}/s, steal {:.2}%, others {:.2} cores)",
            rate,
            t.verdict,
            t.console_rate_hz.unwrap_or(0.0),
            t.steal_fraction * 100.0,
            t.host.others_busy_cores
        );
        let ok = t.sustained;
        trials.push(t);
        Ok(ok)
    };
    let (mut lo, mut hi): (Option<f64>, Option<f64>) = (None, None);
    let mut rate = start_hz;
    loop {
        if run(rate, &mut trials)? {
            lo = Some(rate);
            if rate >= max_hz {
                break;
            }
            rate = (rate * 2.0).min(max_hz);
        } else {
            hi = Some(rate);
            break;
        }
    }
    if lo.is_none() {
        let mut r = start_hz / 2.0;
        while r >= 1000.0 {
            if run(r, &mut trials)? {
                lo = Some(r);
                break;
            }
            hi = Some(r);
            r /= 2.0;
        }
    }
    while let (Some(l), Some(h)) = (lo, hi) {
        if (h - l) / l <= 0.05 {
            break;
        }
        let mid = ((l + h) / 2.0 / 1000.0).round() * 1000.0;
        if mid <= l || mid >= h {
            break;
        }
        if run(mid, &mut trials)? {
            lo = Some(mid);
        } else {
            hi = Some(mid);
        }
    }
    Ok((lo.unwrap_or(0.0), trials))
}

// ---------------------------------------------------------------------------
// sockperf ping-pong through the UDP bridge, against a direct run.

const HALT_POLL_NS: &str = "/sys/module/haltpoll/parameters/guest_halt_poll_ns";
/// Guest halt polling for the second sockperf variant: 200 µs, the
/// kernel's documented default where the cpuidle-haltpoll driver polls.
const SOCKPERF_HALT_POLL_NS: u64 = 200_000;

/// sockperf's latency percentiles of one ping-pong run, in ns. sockperf
/// reports half the round trip (its "latency"); the round trip is twice it.
fn parse_sockperf(text: &str) -> Option<BTreeMap<String, i64>> {
    let mut m = BTreeMap::new();
    for line in text.lines() {
        let value = |l: &str| l.rsplit('=').next()?.trim().parse::<f64>().ok();
        if let Some(rest) = line.split("percentile ").nth(1) {
            let q = rest.split_whitespace().next()?;
            let key = match q {
                "50.000" => "p50",
                "90.000" => "p90",
                "99.000" => "p99",
                "99.900" => "p999",
                "99.990" => "p9999",
                _ => continue,
            };
            m.insert(key.to_string(), (value(line)? * 1000.0).round() as i64);
        } else if line.contains("<MAX> observation") {
            m.insert("max".to_string(), (value(line)? * 1000.0).round() as i64);
        }
    }
    m.contains_key("p50").then_some(m)
}

/// A free UDP port on loopback (bound and released: a small race only).
fn free_udp_port() -> Result<u16> {
    Ok(std::net::UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// Runs `sockperf` with `args` on `core` (the child inherits the spawning
/// thread's placement), returning its output.
fn sockperf_on(core: Option<usize>, args: Vec<String>) -> Result<(Child, PathBuf)> {
    let log = std::env::temp_dir().join(format!("netfi-sockperf-{}-{}.log", std::process::id(), RUN_COUNTER.fetch_add(1, Ordering::Relaxed)));
    let file = std::fs::File::create(&log)?;
    let child = std::thread::scope(|sc| {
        sc.spawn(|| {
            pin(core, None);
            Command::new("sockperf").args(&args).stdin(Stdio::null()).stdout(file.try_clone()?).stderr(file).spawn()
        })
        .join()
        .map_err(|_| anyhow::anyhow!("the spawning thread panicked"))
    })??;
    Ok((child, log))
}

fn ping_pong(core: Option<usize>, port: u16, seconds: f64) -> Result<BTreeMap<String, i64>> {
    let secs = (seconds.round() as u64).max(1).to_string();
    let (mut child, log) = sockperf_on(
        core,
        vec!["ping-pong".into(), "-i".into(), "127.0.0.1".into(), "-p".into(), port.to_string(), "-t".into(), secs, "-m".into(), "64".into()],
    )?;
    loop {
        if child.try_wait()?.is_some() {
            break;
        }
        if stop_requested() {
            let _ = child.kill();
            let _ = child.wait();
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    check_interrupted()?;
    let text = std::fs::read_to_string(&log)?;
    let _ = std::fs::remove_file(&log);
    parse_sockperf(&text).with_context(|| format!("no percentiles in sockperf's output:\n{text}"))
}

/// sockperf ping-pong (64-byte messages) between a client and a server on
/// the benchmark's core: directly, then through `netfi emulator --payload
/// raw` on its own core, the replies coming back through the return path.
///
/// With `halt_poll_ns`, the guest's halt polling is set to it for the
/// interval and put back after: on a VM where it is off, every message a
/// relay on another core hands to a sleeping end wakes a halted vCPU,
/// which costs more than the relay itself.
fn sockperf_interval(s: &Settings, seconds: f64, rep: usize, halt_poll_ns: Option<u64>) -> Result<Value> {
    check_interrupted()?;
    if Command::new("sockperf").arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status().is_err() {
        return Ok(json!({"skipped": "sockperf is not installed (Debian: apt install sockperf)"}));
    }
    let before = std::fs::read_to_string(HALT_POLL_NS).ok();
    if let Some(ns) = halt_poll_ns {
        std::fs::write(HALT_POLL_NS, ns.to_string()).with_context(|| format!("setting {HALT_POLL_NS}"))?;
    }
    let v = sockperf_measure(s, seconds, rep);
    if let (Some(_), Some(b)) = (halt_poll_ns, before) {
        let _ = std::fs::write(HALT_POLL_NS, b.trim());
    }
    v
}

/// The guest's halt polling now, and whether this process may change it.
fn halt_polling() -> (Option<u64>, bool) {
    let now = std::fs::read_to_string(HALT_POLL_NS).ok().and_then(|t| t.trim().parse().ok());
    let writable = now.is_some() && std::fs::OpenOptions::new().write(true).open(HALT_POLL_NS).is_ok();
    (now, writable)
}

fn sockperf_measure(s: &Settings, seconds: f64, rep: usize) -> Result<Value> {
    let halt_poll_ns: Option<u64> = std::fs::read_to_string(HALT_POLL_NS).ok().and_then(|t| t.trim().parse().ok());
    let host = HostTimer::start(s.quiet);
    let server_port = free_udp_port()?;
    let (mut server, server_log) = sockperf_on(s.driver_core, vec!["server".into(), "-i".into(), "127.0.0.1".into(), "-p".into(), server_port.to_string()])?;
    std::thread::sleep(Duration::from_millis(300));
    let result = (|| -> Result<Value> {
        let direct = ping_pong(s.driver_core, server_port, seconds)?;
        let dir = s.out_dir.join("runs").join(format!("sockperf-r{rep}"));
        let _ = std::fs::remove_dir_all(&dir);
        let mut args = emulator_common(s, "Normal", &dir, (seconds * 200_000.0) as u64);
        args.extend([
            "--payload".into(),
            "raw".into(),
            "--ingress".into(),
            "udp://127.0.0.1:0".into(),
            "--egress".into(),
            format!("udp://127.0.0.1:{server_port}"),
        ]);
        let emu = Emulator::spawn(&dir, &args)?;
        let endpoints: Value = serde_json::from_slice(&std::fs::read(dir.join("udp_endpoints.json"))?)?;
        let ingress: SocketAddr = endpoints["ingress"].as_str().context("udp_endpoints.json: no ingress")?.parse()?;
        let via = ping_pong(s.driver_core, ingress.port(), seconds)?;
        let report = emu.finish(Duration::ZERO)?;
        let udp: Value = serde_json::from_slice(&std::fs::read(dir.join("udp.json")).unwrap_or_default()).unwrap_or(Value::Null);
        let added: BTreeMap<String, i64> = via.iter().filter_map(|(k, v)| Some((k.clone(), v - direct.get(k)?))).collect();
        Ok(json!({
            "repetition": rep,
            "seconds": seconds,
            "message_bytes": 64,
            "what": "sockperf ping-pong latency (half the round trip), client and server on the benchmark's core, ns",
            "direct_ns": direct,
            "through_netfi_ns": via,
            "added_ns": added,
            "emulator_frames": report.process.frames,
            "emulator_release_lateness_ns": report.shaping.link.release_lateness_ns,
            "return_path": udp.get("return_path").cloned().unwrap_or(Value::Null),
            "guest_halt_poll_ns": halt_poll_ns,
        }))
    })();
    let _ = server.kill();
    let _ = server.wait();
    let _ = std::fs::remove_file(&server_log);
    let mut v = result?;
    v["host"] = json!(host.stop());
    Ok(v)
}

// ---------------------------------------------------------------------------
// Putting it together.

fn median(mut v: Vec<i64>) -> i64 {
    v.sort_unstable();
    if v.is_empty() {
        0
    } else {
        v[v.len() / 2]
    }
}

const KEYS: [&str; 6] = ["p50", "p90", "p99", "p999", "p9999", "max"];

fn summary_map(s: &Summary) -> BTreeMap<String, i64> {
    KEYS.iter().zip([s.p50, s.p90, s.p99, s.p999, s.p9999, s.max]).map(|(k, v)| (k.to_string(), v as i64)).collect()
}

/// Per percentile: the median over repetitions, and [min, max].
fn combine(maps: &[BTreeMap<String, i64>]) -> (BTreeMap<String, i64>, BTreeMap<String, [i64; 2]>) {
    let mut mid = BTreeMap::new();
    let mut spread = BTreeMap::new();
    for k in KEYS {
        let v: Vec<i64> = maps.iter().filter_map(|m| m.get(k).copied()).collect();
        if v.is_empty() {
            continue;
        }
        spread.insert(k.to_string(), [*v.iter().min().expect("non-empty"), *v.iter().max().expect("non-empty")]);
        mid.insert(k.to_string(), median(v));
    }
    (mid, spread)
}

fn ns(v: i64) -> String {
    if v < 0 {
        format!("−{}", fmt_ns(v.unsigned_abs()))
    } else {
        fmt_ns(v as u64)
    }
}

fn row(label: &str, m: &BTreeMap<String, i64>) -> String {
    let cell = |k: &str| m.get(k).map_or("–".to_string(), |v| ns(*v));
    format!("| {label} | {} | {} | {} | {} | {} | {} |", cell("p50"), cell("p90"), cell("p99"), cell("p999"), cell("p9999"), cell("max"))
}

/// Fails with "interrupted" once Ctrl-C or SIGTERM has been received.
fn check_interrupted() -> Result<()> {
    if stop_requested() {
        bail!("interrupted (Ctrl-C / SIGTERM): the emulators stopped, the core restored, no results written");
    }
    Ok(())
}

fn run(args: &[String]) -> Result<()> {
    let s = Settings::from_env(args)?;
    std::fs::create_dir_all(&s.out_dir).with_context(|| format!("creating {}", s.out_dir.display()))?;
    // Ctrl-C and SIGTERM set a flag that every loop below polls: the
    // benchmark then stops its emulators and runs, restores the core it
    // cleared, and exits without writing half a result.
    netfi::service::signals::install();
    let _ = std::fs::remove_dir_all(s.out_dir.join("hlog"));
    let _ = netfi::transport::cleanup_stale();
    let started = Instant::now();
    let bench_host = HostTimer::start(None);
    println!(
        "netfi overhead benchmark: {} s intervals, {} repetition(s), rates {:?} Hz, parts {}; emulator core {:?}, driving core {:?}; results in {}",
        s.interval_s,
        s.repetitions,
        s.rates_hz,
        s.parts.join(","),
        s.emulator_core,
        s.driver_core,
        s.out_dir.display()
    );
    if s.emulator_core.is_none() {
        println!("  (fewer than 2 cores: nothing is pinned, and the figures mean little)");
    }
    // What an interrupted earlier run left moved is put back first.
    if let Ok(done) = netfi::host::record::restore_orphans(None) {
        for (path, r) in done {
            println!("  (restored {} placement(s) left moved by an interrupted earlier run, from {})", r.undone, path.display());
        }
    }
    let mut isolation = match (s.isolate, s.emulator_core) {
        (true, Some(core)) => match netfi::host::isolate::isolate(core) {
            Ok(iso) => {
                println!("  {} (for the benchmark)", iso.summary());
                Some(iso)
            }
            Err(e) => {
                println!("  (could not clear core {core}: {e}; measuring without)");
                None
            }
        },
        _ => None,
    };

    let mut chains: Vec<ChainResult> = Vec::new();
    let mut floors: Vec<FloorResult> = Vec::new();
    let mut products: Vec<Value> = Vec::new();
    let mut probes: Vec<ProbeResult> = Vec::new();
    let mut sockperfs: Vec<Value> = Vec::new();
    let transports = [Transport::Iceoryx2, Transport::Udp];
    for rep in 0..s.repetitions {
        if s.wants("latency") {
            for &rate in &s.rates_hz {
                for t in transports {
                    // Floor and chain back to back: the same moment of the host.
                    let f = floor_interval(&s, t, rate, s.floor_s, rep)?;
                    println!(
                        "  rep {rep} {:<8} {:>6}  floor (one cross-core hop)     {}  steal {:.2}%  others {:.2} cores",
                        t.name(),
                        rate_label(rate),
                        f.hop_ns.line(),
                        f.host.steal_fraction * 100.0,
                        f.host.others_busy_cores
                    );
                    floors.push(f);
                    let c = chain_interval(&s, t, "Normal", "normal", rate, s.interval_s, rep)?;
                    println!(
                        "  rep {rep} {:<8} {:>6}  chain                          {}  steal {:.2}%  others {:.2} cores",
                        t.name(),
                        rate_label(rate),
                        c.chain_ns.line(),
                        c.host.steal_fraction * 100.0,
                        c.host.others_busy_cores
                    );
                    println!("  rep {rep} {:<8} {:>6}  direct (same run, alternating) {}", t.name(), rate_label(rate), c.direct_ns.line());
                    println!(
                        "  rep {rep} {:<8} {:>6}  added p50 {}  p99 {}  p99.9 {}; release lateness p99 {}; lost chain {} direct {}",
                        t.name(),
                        rate_label(rate),
                        ns(c.added_ns["p50"]),
                        ns(c.added_ns["p99"]),
                        ns(c.added_ns["p999"]),
                        fmt_ns(c.emulator.release_lateness_ns.p99),
                        c.chain_sent.saturating_sub(c.chain_received),
                        c.direct_sent.saturating_sub(c.direct_received)
                    );
                    chains.push(c);
                }
            }
        }
        if s.wants("delay") || s.wants("latency") {
            for p in probe_interval(&s, s.floor_s, rep)? {
                println!(
                    "  rep {rep} probe on core {:?}: {:.1} gaps/s over 10 µs, {:.2}/s over 100 µs, {:.2}/s over 1 ms; {:.3}% of the time lost in gaps over 10 µs; steal {:.2}%  others {:.2} cores",
                    p.core,
                    p.gaps_over_10us_per_s,
                    p.gaps_over_100us_per_s,
                    p.gaps_over_1ms_per_s,
                    p.lost_fraction * 100.0,
                    p.host.steal_fraction * 100.0,
                    p.host.others_busy_cores
                );
                probes.push(p);
            }
        }
        if s.wants("sockperf") {
            // As the machine is set up; and, where guest halt polling is off
            // and may be changed, once more with it on (put back after).
            let (now, writable) = halt_polling();
            let variants: Vec<Option<u64>> = if now == Some(0) && writable { vec![None, Some(SOCKPERF_HALT_POLL_NS)] } else { vec![None] };
            for variant in variants {
                let mut v = sockperf_interval(&s, s.floor_s.max(5.0), rep, variant)?;
                v["variant"] = json!(if variant.is_some() { "halt_polling_on" } else { "as_configured" });
                match v.get("skipped").and_then(Value::as_str) {
                    Some(why) => println!("  rep {rep} sockperf: skipped: {why}"),
                    None => {
                        let g = |k: &str, q: &str| v[k][q].as_i64().map_or("–".to_string(), ns);
                        println!(
                        "  rep {rep} sockperf ping-pong (half round trip): direct p50 {} p99 {}; through netfi p50 {} p99 {}; added p50 {} p99 {} (guest halt polling {} ns)",
                        g("direct_ns", "p50"),
                        g("direct_ns", "p99"),
                        g("through_netfi_ns", "p50"),
                        g("through_netfi_ns", "p99"),
                        g("added_ns", "p50"),
                        g("added_ns", "p99"),
                        v["guest_halt_poll_ns"].as_u64().map_or("unknown".to_string(), |n| n.to_string())
                    );
                    }
                }
                sockperfs.push(v);
            }
        }
        if s.wants("delay") {
            let c = chain_interval(&s, Transport::Iceoryx2, PLM2_DLM2, "plm2_dlm2", 1000.0, s.interval_s, rep)?;
            println!(
                "  rep {rep} iceoryx2 PLM-2 + DLM-2 1k: release lateness {}; end-to-end beyond the injected delay {}",
                c.emulator.release_lateness_ns.line(),
                c.chain_ns.line()
            );
            chains.push(c);
        }
        if s.wants("product") {
            let dir = s.out_dir.join("runs").join(format!("product-normal-1k-r{rep}"));
            let host = HostTimer::start(s.quiet);
            let r = netfi_run(&dir, "Normal", 1000.0, s.interval_s, &[])?;
            let host = host.stop();
            let o = &r.overhead_ns;
            let p = |x: &Option<netfi::metrics::Summary>| {
                x.map(|p| json!({"p50": p.p50, "p90": p.p90, "p99": p.p99, "p999": p.p999, "p9999": p.p9999, "max": p.max}))
            };
            println!(
                "  rep {rep} netfi run Normal 1k: end-to-end extra p50 {} p99 {}; direct hop p50 {} p99 {}; balanced {}",
                o.end_to_end_extra.map_or("?".into(), |x| fmt_ns(x.p50)),
                o.end_to_end_extra.map_or("?".into(), |x| fmt_ns(x.p99)),
                o.direct_hop.map_or("?".into(), |x| fmt_ns(x.p50)),
                o.direct_hop.map_or("?".into(), |x| fmt_ns(x.p99)),
                r.frames.balanced
            );
            products.push(json!({
                "repetition": rep,
                "scenario": "Normal",
                "rate_hz": 1000.0,
                "host": host,
                "balanced": r.frames.balanced,
                "end_to_end_extra_ns": p(&o.end_to_end_extra),
                "direct_hop_ns": p(&o.direct_hop),
                "added_over_direct_ns": o.added_over_direct,
                "ingress_wait_ns": p(&o.ingress_wait),
                "decision_ns": p(&o.decision),
                "release_lateness_ns": p(&o.release_lateness),
                "steal_fraction": r.steal.fraction,
                "out_dir": dir,
            }));
        }
    }

    let mut throughput = BTreeMap::new();
    let mut throughput_fps = BTreeMap::new();
    if s.wants("throughput") {
        for (label, key, scenario) in [("normal", "Normal", "Normal"), ("plm2_dlm2", "PLM-2 + DLM-2", PLM2_DLM2)] {
            let (best, trials) = search(&s, label, scenario, 50_000.0, 3_200_000.0)?;
            println!("  throughput {key}: {best:.0} frames/s sustained for {} s", s.throughput_trial_s);
            let first_fail = trials.iter().filter(|t| !t.sustained).min_by(|a, b| a.rate_hz.total_cmp(&b.rate_hz)).map(|t| t.verdict.clone());
            throughput_fps.insert(key.to_string(), best);
            throughput.insert(key.to_string(), json!({"best_fps": best, "first_failure": first_fail, "trials": trials}));
        }
    }

    // Headline figures: per transport and rate, the median over repetitions.
    let mut added = BTreeMap::<String, BTreeMap<String, Value>>::new();
    let mut added_spread = BTreeMap::<String, BTreeMap<String, Value>>::new();
    let mut chain_fig = BTreeMap::<String, BTreeMap<String, Value>>::new();
    let mut direct_fig = BTreeMap::<String, BTreeMap<String, Value>>::new();
    let mut floor_fig = BTreeMap::<String, BTreeMap<String, Value>>::new();
    let mut lateness_fig = BTreeMap::<String, BTreeMap<String, Value>>::new();
    let mut md_latency = String::new();
    for t in transports {
        for &rate in &s.rates_hz {
            let key = format!("{}", rate as u64);
            let cs: Vec<&ChainResult> = chains.iter().filter(|c| c.transport == t && c.rate_hz == rate && c.scenario == "Normal").collect();
            let fs: Vec<&FloorResult> = floors.iter().filter(|f| f.transport == t && f.rate_hz == rate).collect();
            if cs.is_empty() {
                continue;
            }
            let (a, a_spread) = combine(&cs.iter().map(|c| c.added_ns.clone()).collect::<Vec<_>>());
            let (ch, ch_spread) = combine(&cs.iter().map(|c| summary_map(&c.chain_ns)).collect::<Vec<_>>());
            let (di, _) = combine(&cs.iter().map(|c| summary_map(&c.direct_ns)).collect::<Vec<_>>());
            let (fl, _) = combine(&fs.iter().map(|f| summary_map(&f.hop_ns)).collect::<Vec<_>>());
            let (la, la_spread) = combine(&cs.iter().map(|c| summary_map(&c.emulator.release_lateness_ns)).collect::<Vec<_>>());
            let (h1, _) = combine(&cs.iter().filter_map(|c| c.hop1_ns.as_ref().map(summary_map)).collect::<Vec<_>>());
            let (ins, _) = combine(&cs.iter().filter_map(|c| c.inside_ns.as_ref().map(summary_map)).collect::<Vec<_>>());
            let (h2, _) = combine(&cs.iter().filter_map(|c| c.hop2_ns.as_ref().map(summary_map)).collect::<Vec<_>>());
            added.entry(t.name().into()).or_default().insert(key.clone(), json!(a));
            added_spread.entry(t.name().into()).or_default().insert(key.clone(), json!(a_spread));
            chain_fig.entry(t.name().into()).or_default().insert(key.clone(), json!({"median": ch, "spread": ch_spread}));
            direct_fig.entry(t.name().into()).or_default().insert(key.clone(), json!(di));
            floor_fig.entry(t.name().into()).or_default().insert(key.clone(), json!(fl));
            lateness_fig.entry(t.name().into()).or_default().insert(key.clone(), json!({"median": la, "spread": la_spread}));
            let steal_max = cs.iter().map(|c| c.host.steal_fraction).chain(fs.iter().map(|f| f.host.steal_fraction)).fold(0.0, f64::max);
            let bg_max = cs.iter().map(|c| c.host.others_busy_cores).chain(fs.iter().map(|f| f.host.others_busy_cores)).fold(0.0, f64::max);
            let _ = writeln!(
                md_latency,
                "\n**{} at {} frames/s** ({} repetition(s); steal up to {:.2}%; other processes kept up to {:.2} cores busy during an interval)\n",
                t.name(),
                rate_label(rate),
                cs.len(),
                steal_max * 100.0,
                bg_max
            );
            let _ = writeln!(md_latency, "| one-way latency | p50 | p90 | p99 | p99.9 | p99.99 | max |\n|---|---|---|---|---|---|---|");
            if !fl.is_empty() {
                let _ = writeln!(md_latency, "{}", row("floor: one cross-core hop, no emulator", &fl));
            }
            let _ = writeln!(md_latency, "{}", row("direct, alternating with the chain", &di));
            let _ = writeln!(md_latency, "{}", row("chain through the emulator", &ch));
            let _ = writeln!(md_latency, "{}", row("**added = chain − direct**", &a));
            if !h1.is_empty() {
                let _ = writeln!(md_latency, "{}", row("chain: hop 1 (send → taken by the emulator)", &h1));
                let _ = writeln!(md_latency, "{}", row("chain: inside the emulator (taken → released)", &ins));
                let _ = writeln!(md_latency, "{}", row("chain: hop 2 (released → received)", &h2));
            }
            let _ = writeln!(md_latency, "{}", row("emulator release lateness", &la));
            if cs.len() > 1 {
                let _ = writeln!(
                    md_latency,
                    "\nSpread over repetitions (min – max): added p50 {} – {}, p99 {} – {}; chain p50 {} – {}.",
                    ns(a_spread["p50"][0]),
                    ns(a_spread["p50"][1]),
                    ns(a_spread["p99"][0]),
                    ns(a_spread["p99"][1]),
                    ns(ch_spread["p50"][0]),
                    ns(ch_spread["p50"][1])
                );
            }
        }
    }
    let delays: Vec<&ChainResult> = chains.iter().filter(|c| c.scenario != "Normal").collect();
    let mut md_delay = String::new();
    if !delays.is_empty() {
        let (la, la_spread) = combine(&delays.iter().map(|c| summary_map(&c.emulator.release_lateness_ns)).collect::<Vec<_>>());
        let (ex, _) = combine(&delays.iter().map(|c| summary_map(&c.chain_ns)).collect::<Vec<_>>());
        let (de, _) = combine(&delays.iter().map(|c| summary_map(&c.emulator.decision_ns)).collect::<Vec<_>>());
        lateness_fig.entry("iceoryx2 PLM-2 + DLM-2".into()).or_default().insert("1000".into(), json!({"median": la, "spread": la_spread}));
        let steal_max = delays.iter().map(|c| c.host.steal_fraction).fold(0.0, f64::max);
        let bg_max = delays.iter().map(|c| c.host.others_busy_cores).fold(0.0, f64::max);
        let _ = writeln!(
            md_delay,
            "\n**iceoryx2, PLM-2 then DLM-2, 1 k frames/s** ({} repetition(s); steal up to {:.2}%; other processes kept up to {:.2} cores busy during an interval)\n",
            delays.len(),
            steal_max * 100.0,
            bg_max
        );
        let _ = writeln!(md_delay, "| | p50 | p90 | p99 | p99.9 | p99.99 | max |\n|---|---|---|---|---|---|---|");
        let _ = writeln!(md_delay, "{}", row("release lateness (actual − scheduled)", &la));
        let _ = writeln!(md_delay, "{}", row("decision (taken → fate)", &de));
        let _ = writeln!(md_delay, "{}", row("end to end beyond the injected delay", &ex));
    }

    // The bars of docs/performance.md, reported (never asserted).
    let mut bars = Vec::new();
    let get = |m: &BTreeMap<String, BTreeMap<String, Value>>, t: &str, r: &str, k: &str| {
        m.get(t).and_then(|x| x.get(r)).and_then(|v| v.get(k)).and_then(Value::as_i64)
    };
    if let Some(v) = get(&added, "iceoryx2", "1000", "p50") {
        bars.push(json!({"bar": "added latency p50 at 1 kHz (iceoryx2)", "value_ns": v, "limit_ns": 1000, "met": v <= 1000}));
    }
    if let Some(v) = get(&added, "iceoryx2", "1000", "p99") {
        bars.push(json!({"bar": "added latency p99 at 1 kHz (iceoryx2)", "value_ns": v, "limit_ns": 5000, "met": v <= 5000}));
    }
    for (t, by_rate) in &lateness_fig {
        if let Some(v) = by_rate.get("1000").and_then(|x| x["median"]["p99"].as_i64()) {
            bars.push(json!({"bar": format!("release lateness p99 at 1 kHz ({t})"), "value_ns": v, "limit_ns": 5000, "met": v <= 5000}));
        }
    }
    for (k, v) in &throughput_fps {
        bars.push(json!({"bar": format!("throughput, {k}"), "value_fps": v, "limit_fps": 200_000, "met": *v >= 200_000.0}));
    }
    for &rate in &s.rates_hz {
        let r = format!("{}", rate as u64);
        let ipc = chain_fig.get("iceoryx2").and_then(|x| x.get(&r)).and_then(|v| v["median"]["p50"].as_i64());
        let udp = chain_fig.get("udp").and_then(|x| x.get(&r)).and_then(|v| v["median"]["p50"].as_i64());
        if let (Some(i), Some(u)) = (ipc, udp) {
            let ratio = u as f64 / i.max(1) as f64;
            bars.push(json!({"bar": format!("chain p50, UDP over iceoryx2, at {} frames/s", rate_label(rate)), "value_ratio": ratio, "limit_ratio": 20, "met": ratio >= 20.0}));
        }
    }
    // sockperf: the median over repetitions of each percentile.
    let mut sockperf_figs: BTreeMap<String, Value> = BTreeMap::new();
    for variant in ["as_configured", "halt_polling_on"] {
        let measured: Vec<&Value> = sockperfs.iter().filter(|v| v.get("skipped").is_none() && v["variant"] == variant).collect();
        let sockperf_fig = (!measured.is_empty()).then(|| {
        let fig = |k: &str| {
            let maps: Vec<BTreeMap<String, i64>> = measured.iter().filter_map(|v| serde_json::from_value(v[k].clone()).ok()).collect();
            combine(&maps)
        };
        let (d, d_spread) = fig("direct_ns");
        let (t, t_spread) = fig("through_netfi_ns");
        let (a, a_spread) = fig("added_ns");
        json!({"direct_ns": {"median": d, "spread": d_spread}, "through_netfi_ns": {"median": t, "spread": t_spread}, "added_ns": {"median": a, "spread": a_spread}})
    });
        if let Some(v) = sockperf_fig.as_ref().and_then(|f| f["added_ns"]["median"]["p50"].as_i64()) {
            let halt = measured.first().and_then(|v| v["guest_halt_poll_ns"].as_u64()).map_or("unknown".to_string(), |n| format!("{n} ns"));
            bars.push(json!({"bar": format!("sockperf ping-pong through the UDP bridge, added latency p50 (raw, Normal; guest halt polling {halt})"), "value_ns": v, "limit_ns": 10_000, "met": v <= 10_000}));
        }
        if let Some(mut f) = sockperf_fig {
            f["guest_halt_poll_ns"] = measured.first().map_or(Value::Null, |v| v["guest_halt_poll_ns"].clone());
            f["repetitions"] = json!(measured.len());
            sockperf_figs.insert(variant.to_string(), f);
        }
    }
    check_interrupted()?;
    let host = bench_host.stop();
    let isolation = isolation.as_mut().map(|i| i.restore());
    let doc = json!({
        "schema": "netfi-bench/overhead/1",
        "host": host_facts(&s),
        "settings": s,
        "isolation": isolation,
        "host_over_the_benchmark": host,
        "minutes": started.elapsed().as_secs_f64() / 60.0,
        "added_latency_ns": added,
        "added_latency_spread_ns": added_spread,
        "chain_ns": chain_fig,
        "direct_ns": direct_fig,
        "floor_ns": floor_fig,
        "release_lateness_ns": lateness_fig,
        "throughput_fps": throughput_fps,
        "throughput": throughput,
        "product_run": products,
        "probe_intervals": probes,
        "sockperf": sockperf_figs,
        "sockperf_intervals": sockperfs,
        "bars": bars,
        "chain_intervals": chains,
        "floor_intervals": floors,
    });
    let json_path = s.out_dir.join("overhead.json");
    std::fs::write(&json_path, serde_json::to_vec_pretty(&doc)?).with_context(|| format!("writing {}", json_path.display()))?;

    let mut md = String::new();
    let _ = writeln!(md, "# netfi overhead\n");
    let _ = writeln!(
        md,
        "{} cores ({}), kernel {}, clock source {}; emulator on core {:?}, the benchmark's ends on core {:?}. {} s intervals (floors {} s), {} repetition(s); {:.1} minutes; steal over the whole benchmark {:.2}%.",
        doc["host"]["cores"],
        doc["host"]["cpu_model"].as_str().unwrap_or("?"),
        doc["host"]["kernel"].as_str().unwrap_or("?"),
        doc["host"]["clocksource"].as_str().unwrap_or("?"),
        s.emulator_core,
        s.driver_core,
        s.interval_s,
        s.floor_s,
        s.repetitions,
        started.elapsed().as_secs_f64() / 60.0,
        host.steal_fraction * 100.0
    );
    match &isolation {
        Some(i) => {
            let _ = writeln!(md, "\nThe emulator's core was cleared for the benchmark (`NETFI_BENCH_ISOLATE`, default on), and all put back at the end: {i}.");
        }
        None => {
            let _ = writeln!(md, "\nThe emulator's core was not cleared (`NETFI_BENCH_ISOLATE=0`, or not permitted): other threads could run on it.");
        }
    }
    if !md_latency.is_empty() {
        let _ = writeln!(md, "\n## One-way latency, Normal scenario (nothing injected)\n{md_latency}");
    }
    if !md_delay.is_empty() {
        let _ = writeln!(md, "\n## Under delay\n{md_delay}");
    }
    for f in sockperf_figs.values() {
        let m = |k: &str| serde_json::from_value::<BTreeMap<String, i64>>(f[k]["median"].clone()).unwrap_or_default();
        let halt = f["guest_halt_poll_ns"].as_u64();
        let _ = writeln!(
            md,
            "\n## sockperf ping-pong through the UDP bridge (guest halt polling {})\n\n64-byte messages, client and server on core {:?}, `netfi emulator --payload raw` (Normal) on core {:?}; sockperf's latency (half the round trip; the round trip is twice it); {} repetition(s).\n",
            halt.map_or("not available".to_string(), |n| format!("{n} ns")),
            s.driver_core,
            s.emulator_core,
            f["repetitions"],
        );
        let _ = writeln!(md, "| sockperf latency | p50 | p90 | p99 | p99.9 | p99.99 | max |\n|---|---|---|---|---|---|---|");
        let _ = writeln!(md, "{}", row("direct (client → server)", &m("direct_ns")));
        let _ = writeln!(md, "{}", row("through netfi (client → emulator → server, and back)", &m("through_netfi_ns")));
        let _ = writeln!(md, "{}", row("**added**", &m("added_ns")));
    }
    if !probes.is_empty() {
        let _ = writeln!(md, "\n## What the machine takes from a busy loop on each core\n");
        let _ = writeln!(md, "| repetition | core | gaps over 10 µs /s | over 100 µs /s | over 1 ms /s | time lost in gaps over 10 µs | longest gap | steal | other processes |\n|---|---|---|---|---|---|---|---|---|");
        for p in &probes {
            let _ = writeln!(
                md,
                "| {} | {} | {:.1} | {:.2} | {:.2} | {:.3}% | {} | {:.2}% | {:.2} cores |",
                p.repetition,
                p.core.map_or("-".to_string(), |c| c.to_string()),
                p.gaps_over_10us_per_s,
                p.gaps_over_100us_per_s,
                p.gaps_over_1ms_per_s,
                p.lost_fraction * 100.0,
                fmt_ns(p.gaps_ns.max),
                p.host.steal_fraction * 100.0,
                p.host.others_busy_cores
            );
        }
    }
    if !products.is_empty() {
        let _ = writeln!(md, "\n## `netfi run Normal` as shipped (console and simulator share a core on 2 cores)\n");
        let _ = writeln!(
            md,
            "| repetition | end-to-end extra p50 / p99 | direct hop p50 / p99 | added over direct p50 / p99 | release lateness p99 | steal | other processes |\n|---|---|---|---|---|---|---|"
        );
        for p in &products {
            let g = |k: &str, q: &str| p[k][q].as_i64().map_or("?".into(), ns);
            let _ = writeln!(
                md,
                "| {} | {} / {} | {} / {} | {} / {} | {} | {:.2}% | {:.2} cores |",
                p["repetition"],
                g("end_to_end_extra_ns", "p50"),
                g("end_to_end_extra_ns", "p99"),
                g("direct_hop_ns", "p50"),
                g("direct_hop_ns", "p99"),
                g("added_over_direct_ns", "p50"),
                g("added_over_direct_ns", "p99"),
                g("release_lateness_ns", "p99"),
                p["steal_fraction"].as_f64().unwrap_or(0.0) * 100.0,
                p["host"]["others_busy_cores"].as_f64().unwrap_or(f64::NAN)
            );
        }
    }
    if !throughput.is_empty() {
        let _ = writeln!(md, "\n## Throughput ({} s per trial, `netfi run --no-direct`)\n", s.throughput_trial_s);
        let _ = writeln!(md, "| scenario | sustained, frames/s | first rate not sustained, and why |\n|---|---|---|");
        for (k, v) in &throughput {
            let _ = writeln!(
                md,
                "| {k} | {:.0} | {} |",
                v["best_fps"].as_f64().unwrap_or(0.0),
                v["first_failure"].as_str().unwrap_or("none up to the search's limit")
            );
        }
    }
    if !bars.is_empty() {
        let _ = writeln!(md, "\n## Bars\n\n| bar | value | limit | met |\n|---|---|---|---|");
        for b in &bars {
            let (value, limit) = if let Some(v) = b["value_ns"].as_i64() {
                (ns(v), ns(b["limit_ns"].as_i64().unwrap_or(0)))
            } else if let Some(v) = b["value_fps"].as_f64() {
                (format!("{v:.0} frames/s"), format!("{} frames/s", b["limit_fps"]))
            } else {
                (format!("{:.1}×", b["value_ratio"].as_f64().unwrap_or(0.0)), format!("{}×", b["limit_ratio"]))
            };
            let _ = writeln!(
                md,
                "| {} | {value} | {limit} | {} |",
                b["bar"].as_str().unwrap_or("?"),
                if b["met"].as_bool() == Some(true) { "yes" } else { "**no**" }
            );
        }
    }
    let _ = writeln!(md, "\nHdrHistogram logs: `hlog/`; each run's files: `runs/`. Method: `docs/performance.md`.");
    let md_path = s.out_dir.join("overhead.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    println!("\n{md}");
    println!("written: {} and {}", json_path.display(), md_path.display());
    Ok(())
}
