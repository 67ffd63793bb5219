//! Integration tests of the iceoryx2 transport, in one process where
//! possible; scenarios that need a process to die re-run this test binary as
//! a child (see [`child_process_entry`]).
//!
//! Every test uses its own run id (with this process's pid), so tests run in
//! parallel, and concurrent runs of this binary, never share a channel. A
//! test that leaves a killed peer behind to clean up itself holds
//! [`machine::not_beside_a_run`]: a run's start-up clean-up would remove it
//! first.

use crate::common::machine;
use std::io::{BufRead, BufReader, Read};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use netfi::sample::{FrameSample, ITP_FRAME_LEN};
use netfi::transport::{
    cleanup_dead_nodes, cleanup_dead_runs, Port, FrameSendError, IpcConfig, IpcNode,
    PublisherOpenError, Role, RunId, ServiceOpenError, SubscriberOpenError, MAX_SUBSCRIBERS_PER_CHANNEL,
    SUBSCRIBER_BUFFER_FRAMES,
};

/// Environment variable that turns this binary into a child process; its
/// value is `<mode>:<run id>`.
const CHILD_ENV: &str = "NETFI_TRANSPORT_TEST_CHILD";
/// Frames the `publish` child sends before announcing itself.
const CHILD_FRAMES: u64 = 10;
/// Upper bound on waiting for a child or a condition; only guards against a
/// hung test, it asserts nothing about speed.
const WATCHDOG: Duration = Duration::from_secs(60);

/// The configuration of a run private to one test. Declare it before the
/// test's nodes and children, so that it is dropped after them.
fn unique_config(tag: &str) -> TestRun {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let run = format!("t{}-{tag}-{n}", std::process::id());
    TestRun(IpcConfig::new(
        RunId::new(&run).expect("test run ids are valid"),
    ))
}

/// A test's run; removes the run's last iceoryx2 file when the test ends.
struct TestRun(IpcConfig);

impl std::ops::Deref for TestRun {
    type Target = IpcConfig;

    fn deref(&self) -> &IpcConfig {
        &self.0
    }
}

impl Drop for TestRun {
    /// iceoryx2 keeps one small shared-memory segment per file prefix (a
    /// node counter) that no node removes; with a run id per test, they would
    /// pile up in /dev/shm.
    fn drop(&mut self) {
        // SAFETY: the run id is this test's alone, and every node of the run
        // has been dropped or belonged to a child that has exited or been
        // killed, so no process uses the segment any more.
        let _ = unsafe {
            iceoryx2::testing::remove_global_mgmt_segment::<iceoryx2::prelude::ipc::Service>(
                self.0.iceoryx2(),
            )
        };
    }
}

/// A frame whose every field and wire byte depends on `i`.
fn frame(i: u64) -> FrameSample {
    let mut f = FrameSample::ZERO;
    f.console_index = i;
    f.send_ns = 1_000_000 + i * 1_000;
    f.ingress_index = i.wrapping_mul(3);
    f.len = ITP_FRAME_LEN as u32;
    for (k, b) in f.wire.iter_mut().enumerate() {
        *b = (i as usize).wrapping_mul(31).wrapping_add(k) as u8;
    }
    f
}

fn drain(sub: &mut netfi::transport::FrameSubscriber) -> Vec<FrameSample> {
    let mut out = Vec::new();
    while let Some(f) = sub.try_recv().expect("receive") {
        out.push(f);
    }
    out
}

fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let start = Instant::now();
    while !cond() {
        assert!(start.elapsed() < WATCHDOG, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn frames_arrive_intact_and_in_order() {
    let config = unique_config("order");
    let node = IpcNode::open(&config, Role::Tool).unwrap();
    let mut sub = node.subscriber(Port::CONSOLE).unwrap();
    let mut publisher = node.publisher(Port::CONSOLE).unwrap();
    assert_eq!(publisher.peers_connected(), 1);
    assert_eq!(sub.peers_connected(), 1);
    assert_eq!(sub.capacity(), SUBSCRIBER_BUFFER_FRAMES);

    let n = 1_000u64;
    for i in 0..n {
        let delivered = if i % 2 == 0 {
            publisher.send(&frame(i)).unwrap()
        } else {
            publisher
                .send_with(|s| {
                    *s = frame(i);
                })
                .unwrap()
        };
        assert_eq!(delivered, 1);
    }
    let received = drain(&mut sub);
    let expected: Vec<_> = (0..n).map(frame).collect();
    assert_eq!(received, expected);
    assert_eq!(publisher.stats().sent, n);
    assert_eq!(publisher.stats().queue_full, 0);
    assert_eq!(sub.stats().received, n);
}

#[test]
fn send_with_starts_from_a_zeroed_sample() {
    let config = unique_config("zero");
    let node = IpcNode::open(&config, Role::Tool).unwrap();
    let mut sub = node.subscriber(Port::EMULATOR).unwrap();
    let mut publisher = node.publisher(Port::EMULATOR).unwrap();
    // Fill the pool's samples with non-zero content first, so that a sample
    // reused without zeroing would show through.
    for i in 0..64 {
        publisher.send(&frame(i + 1)).unwrap();
    }
    drain(&mut sub);
    for _ in 0..64 {
        publisher.send_with(|s| s.release_ns = 7).unwrap();
    }
    let received = drain(&mut sub);
    assert_eq!(received.len(), 64);
    for f in received {
        assert_eq!(
            f,
            FrameSample {
                release_ns: 7,
                ..FrameSample::ZERO
            }
        );
    }
}

#[test]
fn recv_with_lends_the_sample_in_place() {
    let config = unique_config("view");
    let node = IpcNode::open(&config, Role::Tool).unwrap();
    let mut sub = node.subscriber(Port::CONSOLE).unwrap();
    let mut publisher = node.publisher(Port::CONSOLE).unwrap();
    assert_eq!(sub.recv_with(|f| f.console_index).unwrap(), None);
    publisher.send(&frame(42)).unwrap();
    let got = sub.recv_with(|f| (f.console_index, f.payload().to_vec()));
    assert_eq!(
        got.unwrap(),
        Some((42, frame(42).wire[..ITP_FRAME_LEN].to_vec()))
    );
    assert_eq!(sub.try_recv().unwrap(), None);
}

#[test]
fn concurrent_runs_do_not_see_each_other() {
    let config_a = unique_config("iso-a");
    let config_b = unique_config("iso-b");
    assert_ne!(config_a.prefix(), config_b.prefix());
    let node_a = IpcNode::open(&config_a, Role::Tool).unwrap();
    let node_b = IpcNode::open(&config_b, Role::Tool).unwrap();
    let mut sub_a = node_a.subscriber(Port::CONSOLE).unwrap();
    let mut sub_b = node_b.subscriber(Port::CONSOLE).unwrap();
    // One publisher per channel and run: the second run's publisher must not
    // take the first run's slot.
    let mut pub_a = node_a.publisher(Port::CONSOLE).unwrap();
    let mut pub_b = node_b.publisher(Port::CONSOLE).unwrap();
    assert_eq!(pub_a.peers_connected(), 1);
    assert_eq!(pub_b.peers_connected(), 1);

    for i in 0..100 {
        assert_eq!(pub_a.send(&frame(i)).unwrap(), 1);
        assert_eq!(pub_b.send(&frame(1_000 + i)).unwrap(), 1);
    }
    let got_a: Vec<u64> = drain(&mut sub_a).iter().map(|f| f.console_index).collect();
    let got_b: Vec<u64> = drain(&mut sub_b).iter().map(|f| f.console_index).collect();
    assert_eq!(got_a, (0..100).collect::<Vec<_>>());
    assert_eq!(got_b, (1_000..1_100).collect::<Vec<_>>());

    // Each run's scan sees only its own node.
    assert_eq!(node_a.reap_dead_peers().unwrap().alive, 1);
    assert_eq!(node_b.reap_dead_peers().unwrap().alive, 1);
}

/// Sends more frames than a subscriber's queue holds while it does not read.
/// `attached`: the subscriber has polled since the publisher appeared (the
/// usual case); otherwise its queue fills before it has attached.
fn burst_beyond_the_queue(attached: bool) {
    let config = unique_config(if attached { "burst-a" } else { "burst-u" });
    let node = IpcNode::open(&config, Role::Tool).unwrap();
    let mut sub = node.subscriber(Port::CONSOLE).unwrap();
    let mut publisher = node.publisher(Port::CONSOLE).unwrap();
    if attached {
        assert_eq!(sub.try_recv().unwrap(), None);
    }

    let extra = 1_000u64;
    let total = SUBSCRIBER_BUFFER_FRAMES as u64 + extra;
    let mut refused = 0u64;
    for i in 0..total {
        match publisher.send(&frame(i)) {
            Ok(1) => assert!(i < SUBSCRIBER_BUFFER_FRAMES as u64, "frame {i} accepted"),
            Err(FrameSendError::QueueFull {
                channel, capacity, ..
            }) => {
                assert_eq!(channel, Port::CONSOLE);
                assert_eq!(capacity, SUBSCRIBER_BUFFER_FRAMES);
                assert!(i >= SUBSCRIBER_BUFFER_FRAMES as u64, "frame {i} refused");
                refused += 1;
            }
            other => panic!("frame {i}: unexpected {other:?}"),
        }
    }
    // Exactly the frames beyond capacity were refused, each reported.
    assert_eq!(refused, extra);
    let stats = publisher.stats();
    assert_eq!(stats.sent, total);
    assert_eq!(stats.queue_full, extra);

    // The queue kept the oldest frames, intact and in order: nothing was
    // overwritten.
    let received = drain(&mut sub);
    assert_eq!(received.len(), SUBSCRIBER_BUFFER_FRAMES);
    for (i, f) in received.iter().enumerate() {
        assert_eq!(*f, frame(i as u64));
    }

    // Once drained, sending works again.
    assert_eq!(publisher.send(&frame(total)).unwrap(), 1);
    assert_eq!(sub.try_recv().unwrap(), Some(frame(total)));
}

#[test]
fn burst_beyond_the_queue_of_an_attached_subscriber_is_refused_and_counted() {
    burst_beyond_the_queue(true);
}

#[test]
fn burst_beyond_the_queue_of_an_unattached_subscriber_is_refused_and_counted() {
    burst_beyond_the_queue(false);
}

#[test]
fn sending_without_subscriber_is_counted() {
    let config = unique_config("nosub");
    let node = IpcNode::open(&config, Role::Console).unwrap();
    let mut publisher = node.publisher(Port::CONSOLE).unwrap();
    assert_eq!(publisher.peers_connected(), 0);
    assert_eq!(publisher.send(&frame(0)).unwrap(), 0);
    assert_eq!(publisher.stats().unsubscribed, 1);
    // A late subscriber gets no history: commands are never replayed.
    let mut sub = node.subscriber(Port::CONSOLE).unwrap();
    assert_eq!(sub.try_recv().unwrap(), None);
    assert_eq!(publisher.send(&frame(1)).unwrap(), 1);
    assert_eq!(sub.try_recv().unwrap(), Some(frame(1)));
}

#[test]
fn port_limits_are_enforced_with_clear_errors() {
    let config = unique_config("limits");
    let node = IpcNode::open(&config, Role::Tool).unwrap();
    let _first = node.publisher(Port::CONSOLE).unwrap();
    let err = node.publisher(Port::CONSOLE).unwrap_err();
    assert!(
        matches!(err, PublisherOpenError::PublisherTaken { .. }),
        "{err:?}"
    );
    let message = err.to_string();
    let service = config.service_name(Port::CONSOLE);
    assert!(message.contains(&service), "{message}");
    assert!(message.contains("console"), "{message}");

    let _subs: Vec<_> = (0..MAX_SUBSCRIBERS_PER_CHANNEL)
        .map(|_| node.subscriber(Port::CONSOLE).unwrap())
        .collect();
    let err = node.subscriber(Port::CONSOLE).unwrap_err();
    assert!(
        matches!(err, SubscriberOpenError::SubscribersTaken { .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains(&service), "{err}");
}

#[test]
fn a_channel_of_another_sample_type_is_refused() {
    use iceoryx2::prelude::{ipc, NodeBuilder, ServiceName};

    let config = unique_config("compat");
    // A process built with another payload type got there first.
    let other = NodeBuilder::new()
        .config(config.iceoryx2())
        .create::<ipc::Service>()
        .unwrap();
    let _service = other
        .service_builder(&ServiceName::new(&config.service_name(Port::CONSOLE)).unwrap())
        .publish_subscribe::<u64>()
        .create()
        .unwrap();

    let node = IpcNode::open(&config, Role::Console).unwrap();
    let err = node.publisher(Port::CONSOLE).unwrap_err();
    assert!(
        matches!(err, PublisherOpenError::Open(ServiceOpenError::Incompatible { .. })),
        "{err:?}"
    );
    assert!(err
        .to_string()
        .contains(&config.service_name(Port::CONSOLE)));
    let err = node.subscriber(Port::CONSOLE).unwrap_err();
    assert!(
        matches!(err, SubscriberOpenError::Open(ServiceOpenError::Incompatible { .. })),
        "{err:?}"
    );
    // The other channel is unaffected.
    node.publisher(Port::EMULATOR).unwrap();
}

#[test]
fn gracefully_restarted_publisher_reconnects() {
    let config = unique_config("restart");
    let consumer = IpcNode::open(&config, Role::Emulator).unwrap();
    let mut sub = consumer.subscriber(Port::CONSOLE).unwrap();
    for generation in 0..3u64 {
        let producer = IpcNode::open(&config, Role::Console).unwrap();
        let mut publisher = producer.publisher(Port::CONSOLE).unwrap();
        assert_eq!(sub.peers_connected(), 1);
        // Polling attaches the subscriber to the new publisher.
        assert_eq!(sub.try_recv().unwrap(), None);
        for i in 0..10 {
            assert_eq!(publisher.send(&frame(generation * 100 + i)).unwrap(), 1);
        }
        drop(publisher);
        drop(producer);
        assert_eq!(sub.peers_connected(), 0);
        // Frames sent before the publisher left are still delivered.
        let got: Vec<u64> = drain(&mut sub).iter().map(|f| f.console_index).collect();
        assert_eq!(
            got,
            (generation * 100..generation * 100 + 10).collect::<Vec<_>>()
        );
    }
}

// ---------------------------------------------------------------------------
// Scenarios with a child process.

/// Not a test of its own: when [`CHILD_ENV`] is set, this binary was started
/// by another test to play a peer.
///
/// - `publish:<run>`: open a console node and publisher, send
///   [`CHILD_FRAMES`] frames, print `READY`, then wait to be killed.
/// - `subscribe:<run>`: open a simulator node and a subscriber of the
///   emulator channel, print `READY`, then wait to be killed without reading.
/// - `until_signal:<run>`: open a console node, print `READY`, poll
///   [`IpcNode::termination_requested`], print `STOPPING` and return.
#[test]
fn child_process_entry() {
    let Ok(spec) = std::env::var(CHILD_ENV) else {
        return;
    };
    let (mode, run) = spec.split_once(':').expect("<mode>:<run>");
    let config = IpcConfig::new(RunId::new(run).unwrap());
    let role = if mode == "subscribe" {
        Role::Simulator
    } else {
        Role::Console
    };
    let node = IpcNode::open(&config, role).unwrap();
    match mode {
        "subscribe" => {
            let _sub = node.subscriber(Port::EMULATOR).unwrap();
            println!("READY");
            loop {
                std::thread::sleep(Duration::from_secs(1));
            }
        }
        "publish" => {
            let mut publisher = node.publisher(Port::CONSOLE).unwrap();
            for i in 0..CHILD_FRAMES {
                publisher.send(&frame(i)).unwrap();
            }
            println!("READY");
            loop {
                std::thread::sleep(Duration::from_secs(1));
            }
        }
        "until_signal" => {
            println!("READY");
            while !node.termination_requested() {
                std::thread::sleep(Duration::from_millis(1));
            }
            // Latched: asking again still says yes.
            assert!(node.termination_requested());
            println!("STOPPING");
        }
        other => panic!("unknown child mode {other}"),
    }
}

/// A child running [`child_process_entry`], and its stdout.
struct ChildPeer {
    child: Child,
    stdout: BufReader<ChildStdout>,
}

impl ChildPeer {
    fn spawn(mode: &str, config: &IpcConfig) -> Self {
        let exe = std::env::current_exe().unwrap();
        let mut child = Command::new(exe)
            .arg(crate::common::test_name(module_path!(), "child_process_entry"))
            .args([
                "--exact",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_ENV, format!("{mode}:{}", config.run_id()))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stdout = BufReader::new(child.stdout.take().unwrap());
        let mut peer = Self { child, stdout };
        peer.expect_line("READY");
        peer
    }

    fn pid(&self) -> i32 {
        self.child.id() as i32
    }

    /// Reads stdout until `line`; fails with the child's stderr if the child
    /// ends first. The watchdog kills a child that hangs.
    fn expect_line(&mut self, line: &str) {
        let pid = self.child.id();
        let (done_tx, done_rx) = mpsc::channel::<()>();
        let watchdog = std::thread::spawn(move || {
            if done_rx.recv_timeout(WATCHDOG).is_err() {
                let _ = Command::new("kill")
                    .args(["-KILL", &pid.to_string()])
                    .status();
            }
        });
        let mut buf = String::new();
        let found = loop {
            buf.clear();
            if self.stdout.read_line(&mut buf).unwrap() == 0 {
                break false;
            }
            // libtest prints the test's name without a newline first.
            if buf.trim_end().ends_with(line) {
                break true;
            }
        };
        let _ = done_tx.send(());
        watchdog.join().unwrap();
        if !found {
            let mut stderr = String::new();
            if let Some(mut e) = self.child.stderr.take() {
                let _ = e.read_to_string(&mut stderr);
            }
            panic!("child ended before printing {line}; its stderr:\n{stderr}");
        }
    }

    fn kill_9(mut self) {
        // `Child::kill` sends SIGKILL on Unix: no destructor runs.
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }
}

impl Drop for ChildPeer {
    /// A failing test must not leave its child running.
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[test]
fn killed_publisher_is_reaped_and_can_be_replaced() {
    let _machine = machine::not_beside_a_run();
    let config = unique_config("kill");
    let node = IpcNode::open(&config, Role::Emulator).unwrap();
    let mut sub = node.subscriber(Port::CONSOLE).unwrap();

    let child = ChildPeer::spawn("publish", &config);
    let child_pid = child.pid();
    assert_eq!(sub.peers_connected(), 1);
    child.kill_9();

    // The dead console stays registered until someone reaps it...
    assert_eq!(sub.peers_connected(), 1);
    // ...and the frames it sent before dying are still there.
    let got: Vec<u64> = drain(&mut sub).iter().map(|f| f.console_index).collect();
    assert_eq!(got, (0..CHILD_FRAMES).collect::<Vec<_>>());

    let report = node.reap_dead_peers().unwrap();
    assert_eq!(report.failed, vec![], "{report:?}");
    assert_eq!(report.removed.len(), 1, "{report:?}");
    let dead = &report.removed[0];
    assert_eq!(dead.role, Some(Role::Console));
    assert_eq!(dead.pid, Some(child_pid));
    assert_eq!(dead.node_name, config.node_name(Role::Console));
    assert_eq!(report.alive, 1);
    assert_eq!(sub.peers_connected(), 0);

    // The channel's single publisher slot is free again: a restarted console
    // connects and its frames arrive.
    let console = IpcNode::open(&config, Role::Console).unwrap();
    assert!(console.startup_cleanup().is_clean());
    let mut publisher = console.publisher(Port::CONSOLE).unwrap();
    assert_eq!(sub.peers_connected(), 1);
    assert_eq!(publisher.send(&frame(77)).unwrap(), 1);
    assert_eq!(sub.try_recv().unwrap(), Some(frame(77)));

    assert!(node.reap_dead_peers().unwrap().is_clean());
}

#[test]
fn killed_subscriber_is_reported_then_reaped() {
    let _machine = machine::not_beside_a_run();
    let config = unique_config("killsub");
    let node = IpcNode::open(&config, Role::Emulator).unwrap();
    let mut publisher = node.publisher(Port::EMULATOR).unwrap();
    let child = ChildPeer::spawn("subscribe", &config);
    let child_pid = child.pid();
    assert_eq!(publisher.peers_connected(), 1);
    child.kill_9();

    // Until it is reaped the dead simulator's queue still takes frames; once
    // full, every frame is reported as refused rather than vanishing.
    for i in 0..SUBSCRIBER_BUFFER_FRAMES as u64 {
        assert_eq!(publisher.send(&frame(i)).unwrap(), 1, "frame {i}");
    }
    assert!(matches!(
        publisher.send(&frame(0)),
        Err(FrameSendError::QueueFull { .. })
    ));
    assert_eq!(publisher.stats().queue_full, 1);

    let report = node.reap_dead_peers().unwrap();
    assert_eq!(report.removed.len(), 1, "{report:?}");
    assert_eq!(report.removed[0].role, Some(Role::Simulator));
    assert_eq!(report.removed[0].pid, Some(child_pid));
    assert_eq!(publisher.peers_connected(), 0);
    assert_eq!(publisher.send(&frame(1)).unwrap(), 0);

    // A restarted simulator receives from the next frame on.
    let simulator = IpcNode::open(&config, Role::Simulator).unwrap();
    let mut sub = simulator.subscriber(Port::EMULATOR).unwrap();
    assert_eq!(publisher.send(&frame(2)).unwrap(), 1);
    assert_eq!(sub.try_recv().unwrap(), Some(frame(2)));
    assert_eq!(sub.try_recv().unwrap(), None);
}

#[test]
fn leftovers_of_a_killed_run_are_removed_at_start_up() {
    let _machine = machine::not_beside_a_run();
    let config = unique_config("leftover");
    ChildPeer::spawn("publish", &config).kill_9();

    // Nothing of this process is attached to the run yet.
    let first_look = cleanup_dead_nodes(&config).unwrap();
    assert_eq!(first_look.removed.len(), 1, "{first_look:?}");
    assert_eq!(first_look.removed[0].role, Some(Role::Console));
    assert_eq!(first_look.alive, 0);

    // Opening a node scans again; nothing is left, and the channel opens.
    let node = IpcNode::open(&config, Role::Console).unwrap();
    assert!(
        node.startup_cleanup().is_clean(),
        "{:?}",
        node.startup_cleanup()
    );
    let _publisher = node.publisher(Port::CONSOLE).unwrap();
}

#[test]
fn dead_runs_are_found_by_their_files() {
    let _machine = machine::not_beside_a_run();
    let config = unique_config("anyrun");
    ChildPeer::spawn("publish", &config).kill_9();
    // Only this test's run is selected: other tests (and other processes on
    // the host) own the rest and check their own clean-ups.
    let reports = cleanup_dead_runs(|run| run == config.run_id()).unwrap();
    assert_eq!(reports.len(), 1, "{reports:?}");
    let (run, report) = &reports[0];
    assert_eq!(run, config.run_id());
    assert_eq!(report.removed.len(), 1, "{report:?}");
    assert_eq!(report.removed[0].role, Some(Role::Console));
    assert!(cleanup_dead_runs(|run| run == config.run_id())
        .unwrap()
        .is_empty());
}

/// The files under `dirs` (searched through) whose names start with `prefix`.
fn files_with_prefix(prefix: &str) -> Vec<std::path::PathBuf> {
    let mut dirs = vec![std::path::PathBuf::from("/dev/shm"), netfi::transport::ipc::user_root_dir()];
    let mut found = Vec::new();
    while let Some(dir) = dirs.pop() {
        for e in std::fs::read_dir(&dir).into_iter().flatten().filter_map(|e| e.ok()) {
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                dirs.push(e.path());
            } else if e.file_name().to_string_lossy().starts_with(prefix) {
                found.push(e.path());
            }
        }
    }
    found
}

/// Every file of a run whose processes all died goes, also one no node
/// owns; a live run's stay, also one no node owns.
#[test]
fn a_dead_runs_files_are_removed_and_a_live_ones_kept() {
    let _machine = machine::not_beside_a_run();
    let live = unique_config("sweep-live");
    let dead = unique_config("sweep-dead");
    let node = IpcNode::open(&live, Role::Simulator).unwrap();
    let _sub = node.subscriber(Port::EMULATOR).unwrap();
    ChildPeer::spawn("publish", &dead).kill_9();
    let long_ago = std::time::SystemTime::now() - Duration::from_secs(3600);
    let stray = |config: &IpcConfig| {
        let path = std::path::PathBuf::from(format!("/dev/shm/{}{}_7.data", config.prefix(), "0".repeat(40)));
        let f = std::fs::File::create(&path).unwrap();
        f.set_times(std::fs::FileTimes::new().set_modified(long_ago)).unwrap();
        path
    };
    let (live_stray, dead_stray) = (stray(&live), stray(&dead));
    assert!(!files_with_prefix(dead.prefix()).is_empty());

    let swept = netfi::transport::ipc::remove_dead_run_files(|r| r == live.run_id() || r == dead.run_id()).unwrap();
    let live_left = live_stray.exists();
    let _ = std::fs::remove_file(&live_stray);
    let _ = std::fs::remove_file(&dead_stray);
    assert_eq!(swept.len(), 1, "{swept:?}");
    assert_eq!(&swept[0].0, dead.run_id());
    assert!(swept[0].1 >= 1);
    let left = files_with_prefix(dead.prefix());
    assert!(left.is_empty(), "left of the dead run: {left:?}");
    assert!(live_left, "a live run's file was removed");
    // The live run works on.
    assert!(node.reap_dead_peers().unwrap().is_clean());
}

#[test]
fn node_open_reports_what_it_cleaned() {
    let _machine = machine::not_beside_a_run();
    let config = unique_config("report");
    let child = ChildPeer::spawn("publish", &config);
    let pid = child.pid();
    child.kill_9();
    let node = IpcNode::open(&config, Role::Console).unwrap();
    let report = node.startup_cleanup();
    assert_eq!(report.removed.len(), 1, "{report:?}");
    assert_eq!(report.removed[0].pid, Some(pid));
    let shown = report.removed[0].to_string();
    assert!(shown.starts_with("console ("), "{shown}");
    assert!(shown.ends_with(&format!("pid {pid})")), "{shown}");
    // The publisher slot of the killed console is free.
    let _publisher = node.publisher(Port::CONSOLE).unwrap();
}

/// The signals a process catches, from `/proc/<pid>/status`.
fn caught_signals(pid: i32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .unwrap();
    u64::from_str_radix(line.trim(), 16).unwrap()
}

#[test]
fn sigint_is_latched_as_a_termination_request() {
    const SIGINT: u32 = 2;
    const SIGTERM: u32 = 15;
    let config = unique_config("sigint");
    let mut child = ChildPeer::spawn("until_signal", &config);
    // The handlers are installed when the node opens, before READY.
    let caught = caught_signals(child.pid());
    assert_ne!(
        caught & (1 << (SIGINT - 1)),
        0,
        "SIGINT not caught: {caught:x}"
    );
    assert_ne!(
        caught & (1 << (SIGTERM - 1)),
        0,
        "SIGTERM not caught: {caught:x}"
    );

    let status = Command::new("kill")
        .args(["-INT", &child.pid().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    child.expect_line("STOPPING");
    let exit = child.child.wait().unwrap();
    assert!(exit.success(), "child exited with {exit:?}");
}

// ---------------------------------------------------------------------------
// Measurement.

/// Steal and total jiffies of all CPUs, from the first line of `/proc/stat`.
fn cpu_steal_and_total() -> (u64, u64) {
    let stat = std::fs::read_to_string("/proc/stat").unwrap();
    let fields: Vec<u64> = stat
        .lines()
        .next()
        .unwrap()
        .split_whitespace()
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect();
    // user nice system idle iowait irq softirq steal guest guest_nice; guest
    // time is already counted in user and nice.
    let total: u64 = fields.iter().take(8).sum();
    (fields[7], total)
}

/// Nanoseconds the calling thread has spent on a CPU and waiting on a run
/// queue, from `/proc/thread-self/schedstat`.
fn thread_schedstat() -> (u64, u64) {
    let stat = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap();
    let mut fields = stat.split_whitespace().map(|v| v.parse::<u64>().unwrap());
    (fields.next().unwrap(), fields.next().unwrap())
}

/// One-way latency of one publisher → subscriber hop between two threads of
/// one process, at a paced 100 kHz, with a busy-polling receiver. Both ends
/// read `std::time::Instant` (CLOCK_MONOTONIC on Linux) relative to one
/// shared origin; the stamp is taken inside `send_with`, the receive time
/// inside `recv_with`.
///
/// `cargo test --test all -- --ignored --nocapture transport::latency`
#[test]
#[ignore = "measurement, not a check; run explicitly with --ignored --nocapture"]
fn latency_one_hop_between_threads() {
    use hdrhistogram::Histogram;
    let _machine = machine::alone();

    const WARMUP: u64 = 10_000;
    const SAMPLES: u64 = 100_000;
    const PERIOD_NS: u64 = 10_000;

    let config = unique_config("latency");
    let origin = Instant::now();
    let now_ns = move || origin.elapsed().as_nanos() as u64;
    let (ready_tx, ready_rx) = mpsc::channel();
    let receiver_config = config.clone();
    let receiver = std::thread::spawn(move || {
        let node = IpcNode::open(&receiver_config, Role::Simulator).unwrap();
        let mut sub = node.subscriber(Port::CONSOLE).unwrap();
        ready_tx.send(()).unwrap();
        let sched_before = thread_schedstat();
        let mut histogram = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3).unwrap();
        let mut expected = 0u64;
        while expected < WARMUP + SAMPLES {
            let got = sub
                .recv_with(|s| (s.console_index, now_ns().saturating_sub(s.send_ns)))
                .unwrap();
            if let Some((index, latency_ns)) = got {
                assert_eq!(index, expected, "frame lost or reordered");
                if index >= WARMUP {
                    histogram.record(latency_ns.max(1)).unwrap();
                }
                expected += 1;
            } else {
                std::hint::spin_loop();
            }
        }
        let sched_after = thread_schedstat();
        (
            histogram,
            sched_after.0 - sched_before.0,
            sched_after.1 - sched_before.1,
        )
    });
    ready_rx.recv().unwrap();

    let node = IpcNode::open(&config, Role::Console).unwrap();
    let mut publisher = node.publisher(Port::CONSOLE).unwrap();
    wait_until("the receiver to connect", || {
        publisher.peers_connected() == 1
    });

    let (steal_before, total_before) = cpu_steal_and_total();
    let mut next_ns = now_ns();
    for i in 0..WARMUP + SAMPLES {
        while now_ns() < next_ns {
            std::hint::spin_loop();
        }
        publisher
            .send_with(|s| {
                s.console_index = i;
                s.send_ns = now_ns();
            })
            .unwrap();
        next_ns += PERIOD_NS;
    }
    let (histogram, on_cpu_ns, waiting_ns) = receiver.join().unwrap();
    let (steal_after, total_after) = cpu_steal_and_total();
    let steal = steal_after - steal_before;
    let total = total_after - total_before;

    println!(
        "one hop, {} samples at {} kHz: p50 {} ns, p99 {} ns, p99.9 {} ns, max {} ns, mean {:.0} ns",
        histogram.len(),
        1_000_000 / PERIOD_NS,
        histogram.value_at_quantile(0.50),
        histogram.value_at_quantile(0.99),
        histogram.value_at_quantile(0.999),
        histogram.max(),
        histogram.mean(),
    );
    println!(
        "steal during the measurement: {steal} of {total} jiffies ({:.2} %)",
        100.0 * steal as f64 / total.max(1) as f64
    );
    println!(
        "receiver thread: {} ms on a CPU, {} ms runnable but waiting for one ({:.0} % of its time)",
        on_cpu_ns / 1_000_000,
        waiting_ns / 1_000_000,
        100.0 * waiting_ns as f64 / (on_cpu_ns + waiting_ns).max(1) as f64
    );

    // The transport's own cost, free of scheduling: one frame sent and
    // received back to back on one thread.
    let mut local_pub = node.publisher(Port::EMULATOR).unwrap();
    let mut local_sub = node.subscriber(Port::EMULATOR).unwrap();
    let mut cost = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3).unwrap();
    for i in 0..WARMUP + SAMPLES {
        let start = Instant::now();
        local_pub.send_with(|s| s.console_index = i).unwrap();
        let got = local_sub.recv_with(|s| s.console_index).unwrap();
        let elapsed_ns = start.elapsed().as_nanos() as u64;
        assert_eq!(got, Some(i));
        if i >= WARMUP {
            cost.record(elapsed_ns.max(1)).unwrap();
        }
    }
    println!(
        "send + receive on one thread, {} samples: p50 {} ns, p99 {} ns, p99.9 {} ns, max {} ns",
        cost.len(),
        cost.value_at_quantile(0.50),
        cost.value_at_quantile(0.99),
        cost.value_at_quantile(0.999),
        cost.max(),
    );
}
