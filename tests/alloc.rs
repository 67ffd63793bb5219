//! Zero allocations per frame in steady state: a counting global allocator
//! watches the emulator's forward link (decide, queue, release, with its
//! histograms and trace) over many frames after a warm-up, driven through
//! in-memory ports. Its own binary, because the allocator is process-wide.

use netfi::sample::FrameSample;
use netfi::scenario::{self, Scenario};
use netfi::service::emulator::forward::Forward;
use netfi::service::emulator::lane::Lane;
use netfi::service::emulator::path::Path;
use netfi::service::link::Link;
use netfi::transport::MemoryPort;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The count is process-wide and the test harness runs tests on threads of
/// their own: one test's set-up would land in another's measured window.
/// Each test holds this for its whole length, so they run one at a time.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The forward path of `link` between in-memory ports with room for
/// `source` and `sink` frames (its trace is not written).
fn forward(link: Link<FrameSample>, source: usize, sink: usize) -> Path<Forward<MemoryPort, MemoryPort>> {
    let chan = Forward::new(MemoryPort::with_capacity(source), MemoryPort::with_capacity(sink), false, true);
    Path::of(link, chan, 0, std::env::temp_dir().join("netfi-alloc-unused.csv"), false)
}

type MemoryLane = Lane<Forward<MemoryPort, MemoryPort>>;

/// PLM-2 then a 10–20 µs reordering delay: every release path is taken.
const PLM2_SHORT_REORDER: &str = "[[stage]]\npreset = \"PLM-2\"\n[[stage]]\nmodel = \"delay\"\nmin_ms = 0.01\ndist = \"uniform\"\njitter_ms = 0.01\norder = \"reorder\"\n";

/// Feeds `lane` `items` items spaced like 200 kHz (5 µs of turns each, so
/// the 10–20 µs delays release in turn): `feed(lane, i)` puts item `i` in
/// and says how many came out since the last. No allocation in the second
/// half, and more than half released.
fn assert_no_allocation_per_item(lane: &mut MemoryLane, items: u64, what: &str, mut feed: impl FnMut(&mut MemoryLane, u64) -> u64) {
    let (mut before, mut released) = (0, 0u64);
    for i in 0..items {
        if i == items / 2 {
            before = allocations();
        }
        released += feed(lane, i);
        let t = netfi::clock::now_ns() + 5_000;
        while netfi::clock::now_ns() < t {
            lane.turn();
        }
    }
    let n = allocations() - before;
    assert_eq!(n, 0, "{n} allocations in {} {what}", items / 2);
    assert!(released > items / 2, "only {released} {what} released");
}

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    let guard = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    // The test that held it has just ended: the harness now records its
    // result and starts the next test's thread, which allocates. Let that
    // pass before this test counts.
    std::thread::sleep(std::time::Duration::from_millis(100));
    guard
}

/// Runs `frames` frames at 1 kHz (simulated time) through the emulator's
/// link and returns the allocations made during the last `measured` of them,
/// and the frames released.
fn allocations_in_steady_state(scenario_text: &str, frames: u64, measured: u64) -> (u64, u64) {
    let spec = scenario::parse_str(scenario_text, "alloc.toml", "alloc").unwrap();
    let link = Link::new(Scenario::new(&spec, 3).unwrap(), 1 << 16, frames).unwrap();
    let mut fwd = forward(link, 4, 1 << 17);
    let mut template = FrameSample::ZERO;
    netfi::frame::ItpFrame::default().write_to_sample(&mut template);
    let mut before = 0;
    let mut released = 0;
    let t0 = netfi::clock::now_ns();
    for i in 0..frames {
        if i == frames - measured {
            before = allocations();
        }
        let now = t0 + i * 1_000_000;
        fwd.release_due(now);
        released += fwd.chan.sink.queue.len() as u64;
        fwd.chan.sink.queue.clear();
        let mut sample = template;
        sample.console_index = i;
        sample.send_ns = now;
        fwd.chan.source.queue.push_back(sample);
        fwd.take(|| now);
    }
    (allocations() - before, released)
}

#[test]
fn the_emulator_link_does_not_allocate_per_frame() {
    let _serial = one_at_a_time();
    let pipelines = [
        ("PLM-2 → DLM-2", "[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n"),
        ("every model", "[[stage]]\nmodel = \"bernoulli\"\np = 0.01\n[[stage]]\nmodel = \"markov4\"\np13 = 0.01\np31 = 0.3\n[[stage]]\nmodel = \"gilbert_elliott\"\np = 0.01\n[[stage]]\npreset = \"CLM-2\"\n[[stage]]\nmodel = \"delay\"\nmin_ms = 10\ndist = \"uniform\"\njitter_ms = 5\norder = \"fifo\"\n"),
        ("phases", "[[phase]]\npreset = \"DLM-3\"\n[[phase]]\nstart_s = 100\npreset = \"PLM-1\"\n"),
        // Copies and flips: a copy is a second queue entry and trace row,
        // a flip is applied to the sample's bytes in place.
        // A link stage: its queue, and the emulator's sampling of it second
        // by second (1.33 Mbit/s offered to 2 Mbit/s).
        ("rate link", "[[stage]]\nmodel = \"rate\"\nrate_bit_s = 2_000_000\noverhead_bytes = 42\n[[stage]]\npreset = \"PLM-2\"\n"),
        ("duplicate + corrupt", "[[stage]]\nmodel = \"duplicate\"\np = 0.05\n[[stage]]\nmodel = \"corrupt\"\np = 0.1\n[[stage]]\nmodel = \"duplicate\"\np = 0.02\n[[stage]]\nmodel = \"bernoulli\"\np = 0.01\n[[stage]]\nmodel = \"delay\"\nmin_ms = 10\ndist = \"uniform\"\njitter_ms = 5\norder = \"reorder\"\n"),
    ];
    for (name, text) in pipelines {
        // 300 s of frames; the last 200 s measured, well past the queue's fill-up.
        let (n, released) = allocations_in_steady_state(text, 300_000, 200_000);
        assert_eq!(n, 0, "{name}: {n} allocations in 200000 frames");
        assert!(released > 100_000, "{name}: only {released} frames released");
    }
}

/// The feedback path (robot → console) polled by the emulator's loop:
/// zero allocations per feedback sample either, through a delaying return
/// scenario.
#[test]
fn the_feedback_path_does_not_allocate_per_sample() {
    let _serial = one_at_a_time();
    use netfi::sample::FeedbackSample;
    use netfi::transport::MemoryPort;
    let spec = scenario::parse_str(PLM2_SHORT_REORDER, "alloc.toml", "alloc").unwrap();
    let frames = 200_000u64;
    let link = Link::new(Scenario::new(&spec, 5).unwrap(), 1 << 16, frames).unwrap();
    use netfi::service::channel::feedback::Feedback;
    type Memory = MemoryPort<FeedbackSample>;
    let chan = Feedback::new(Memory::with_capacity(4), Memory::with_capacity(1 << 17));
    let path = Path::of(link, chan, 5, std::env::temp_dir().join("netfi-alloc-unused.csv"), false);
    let normal = Link::new(Scenario::new(&scenario::parse_str("", "n.toml", "n").unwrap(), 1).unwrap(), 16, 16).unwrap();
    let mut lane = Lane::new(forward(normal, 4, 16), vec![Box::new(path)]);
    assert_no_allocation_per_item(&mut lane, frames, "feedback samples", |lane, i| {
        let fb = lane.reverse[0].as_any_mut().downcast_mut::<Path<Feedback<Memory, Memory>>>().unwrap();
        let (inp, out) = fb.chan.ports_mut();
        let released = out.queue.len() as u64;
        out.queue.clear();
        inp.queue.push_back(FeedbackSample { robot_index: i, send_ns: netfi::clock::now_ns(), ..FeedbackSample::ZERO });
        released
    });
}

#[test]
fn a_live_switch_and_a_pause_do_not_allocate_in_the_loop() {
    let _one = one_at_a_time();
    let parse = |t: &str| scenario::parse_str(t, "alloc.toml", "alloc").unwrap();
    let (a, b) = (parse("[[stage]]\npreset = \"PLM-2\"\n"), parse("[[stage]]\npreset = \"DLM-1\"\n"));
    let mut sc = Scenario::new(&a, 3).unwrap();
    sc.reserve_phases(scenario::MAX_RUN_PHASES);
    let mut inj: netfi::injector::Injector<u64> =
        netfi::injector::Injector::try_with_order(sc, 1 << 16, netfi::scheduler::QueueOrder::Reorder).unwrap();
    // Built off the loop, as the control thread does.
    let mut timelines: Vec<_> = (0..20).map(|i| scenario::Timeline::new(if i % 2 == 0 { &b } else { &a }, 0).unwrap()).collect();
    let mut retired = Vec::with_capacity(timelines.len());
    let before = allocations();
    for i in 0..20_000u64 {
        let now = i * 1_000_000;
        while inj.pop_due(now).is_some() {}
        if i % 1000 == 999 {
            let t = timelines.pop().unwrap();
            retired.push(inj.switch(now, None, t).unwrap());
            inj.set_paused(i % 3000 == 2999);
        }
        inj.ingress(now, i);
    }
    let made = allocations() - before;
    assert_eq!(made, 0, "{made} allocations across 20 switches");
    assert_eq!(inj.scenario().phases().len(), 21);
}

/// The whole turn of the loop, as the service runs it (clock, release,
/// take, and the accounting of its busy turns), over in-memory ports: no
/// allocation per frame either.
#[test]
fn the_loop_turn_does_not_allocate_per_frame() {
    let _serial = one_at_a_time();
    let spec = scenario::parse_str(PLM2_SHORT_REORDER, "alloc.toml", "alloc").unwrap();
    let frames = 100_000u64;
    let mut lane = Lane::new(forward(Link::new(Scenario::new(&spec, 7).unwrap(), 1 << 16, frames).unwrap(), 4, 1 << 10), Vec::new());
    let mut template = FrameSample::ZERO;
    netfi::frame::ItpFrame::default().write_to_sample(&mut template);
    assert_no_allocation_per_item(&mut lane, frames, "frames", |lane, i| {
        let ports = &mut lane.forward.chan;
        let released = ports.sink.queue.len() as u64;
        ports.sink.queue.clear();
        let mut sample = template;
        sample.console_index = i;
        sample.send_ns = netfi::clock::now_ns();
        ports.source.queue.push_back(sample);
        released
    });
    let busy = lane.loop_busy();
    assert!(busy.busy_turns > 0 && busy.busy_turns < busy.turns, "{busy:?}");
    assert_eq!(busy.frames, frames);
}

/// The loop of several streams (`netfi emulator --streams N`): its rounds
/// allocate nothing per frame either, three streams with scenarios of
/// their own (loss, reordering delay, copies and flips) through in-memory
/// ports.
#[test]
fn the_loop_of_several_streams_does_not_allocate_per_frame() {
    let _serial = one_at_a_time();
    use netfi::service::emulator::spin::round;
    let delay = "[[stage]]\nmodel = \"delay\"\nmin_ms = 0.01\ndist = \"uniform\"\njitter_ms = 0.01\norder = \"reorder\"\n";
    let texts = [
        format!("[[stage]]\npreset = \"PLM-2\"\n{delay}"),
        format!("[[stage]]\nmodel = \"bernoulli\"\np = 0.01\n[[stage]]\nmodel = \"gilbert_elliott\"\np = 0.01\n{}", delay.replace("reorder", "fifo")),
        format!("[[stage]]\nmodel = \"duplicate\"\np = 0.05\n[[stage]]\nmodel = \"corrupt\"\np = 0.1\n{delay}"),
    ];
    let frames = 200_000u64;
    let mut lanes: Vec<Lane<Forward<MemoryPort, MemoryPort>>> = texts
        .iter()
        .enumerate()
        .map(|(k, text)| {
            let spec = scenario::parse_str(text, "alloc.toml", "alloc").unwrap();
            let mut lane = Lane::new(forward(Link::new(Scenario::new(&spec, 3 + k as u64).unwrap(), 1 << 16, frames).unwrap(), 4, 1 << 17), Vec::new());
            // As the loop of several streams sets it: no stream waits for a release.
            lane.release_spin_ns = 0;
            lane
        })
        .collect();
    let mut template = FrameSample::ZERO;
    netfi::frame::ItpFrame::default().write_to_sample(&mut template);
    let (mut before, mut released, mut due) = (0, [0u64; 3], u64::MAX);
    for i in 0..frames {
        if i == frames / 2 {
            before = allocations();
        }
        for (l, r) in lanes.iter_mut().zip(released.iter_mut()) {
            let ports = &mut l.forward.chan;
            *r += ports.sink.queue.len() as u64;
            ports.sink.queue.clear();
            let mut sample = template;
            sample.console_index = i;
            sample.send_ns = netfi::clock::now_ns();
            ports.source.queue.push_back(sample);
        }
        // Spaced like 200 kHz per stream: the 10–20 µs delays release in turn.
        let t = netfi::clock::now_ns() + 5_000;
        while netfi::clock::now_ns() < t {
            due = round(&mut lanes, due);
        }
    }
    let n = allocations() - before;
    assert_eq!(n, 0, "{n} allocations in {} frames of each of 3 streams", frames / 2);
    // PLM-2 loses about 30%; the others about 2%.
    assert!(released.iter().all(|&r| r > frames / 2), "released {released:?} of {frames} each");
}

/// The ROS 2 writer's copies: with the DDS layer holding on to its last
/// 1000 messages (a reliable writer's history) and messages of 40 to 240
/// bytes with one of 60 kB in every 97, no allocation once its arenas are
/// there (25 of 64 KiB here, in place after 30 000 messages; with messages of
/// one size, after the first history's worth).
#[test]
fn the_ros2_writers_copies_do_not_allocate_per_message() {
    let _one = one_at_a_time();
    let mut buffers = netfi::transport::ros2::OutBuffers::new();
    let mut held = std::collections::VecDeque::with_capacity(1001);
    let message = vec![7u8; 60_000];
    let len = |i: usize| if i % 97 == 0 { 60_000 } else { 40 + i % 200 };
    let mut before = 0;
    for i in 0..60_000 {
        if i == 40_000 {
            before = allocations();
        }
        let b = buffers.copy(&message[..len(i)]);
        assert_eq!(&b[..], &message[..len(i)]);
        if held.len() == 1000 {
            held.pop_front();
        }
        held.push_back(b);
    }
    let n = allocations() - before;
    assert_eq!(n, 0, "{n} allocations in 20 000 copies ({} arenas)", buffers.arenas());
}
