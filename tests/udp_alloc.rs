//! Zero allocations per datagram on the UDP bridge's hot path: a counting
//! global allocator watches the emulator's loop turns — the UDP source (raw
//! mode, into the arena), the forward link with its histograms and trace,
//! the UDP sink, and the return path (untouched, and through a link of its
//! own) — over many datagrams after a warm-up. Its own binary, because the
//! allocator is process-wide; everything runs on one thread.

use netfi::scenario::{self, Scenario};
use netfi::service::emulator::forward::Forward;
use netfi::transport::udp::ConsoleAddr;
use netfi::service::emulator::lane::Lane;
use netfi::service::emulator::path::Path;
use netfi::service::channel::feedback::UdpReturn;
use netfi::service::link::Link;
use netfi::transport::udp::{Arena, ConsolePolicy, PeerAddr, UdpOptions, UdpPort, UdpSink, UdpSource};
use std::cell::RefCell;
use std::rc::Rc;
use std::time::Instant;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

fn bind() -> UdpPort {
    UdpPort::bind("127.0.0.1:0".parse().unwrap(), &UdpOptions { reuse_address: false, buffer_bytes: Some(1 << 20) })
        .unwrap()
}

/// Polls `f` until it yields, at most 5 s.
fn until<T>(mut f: impl FnMut() -> Option<T>) -> T {
    let t0 = Instant::now();
    loop {
        if let Some(x) = f() {
            return x;
        }
        assert!(t0.elapsed().as_secs() < 5, "a loopback datagram never arrived");
    }
}

/// Sends `datagrams` console → bridge → robot → bridge → console, one at a
/// time, through `scenario` forward and `return_scenario` (or untouched)
/// back, turning the emulator's loop; returns the allocations made during
/// the last `measured`, and the replies the console got.
fn allocations_in_steady_state(
    scenario_text: &str,
    return_scenario: Option<&str>,
    datagrams: u64,
    measured: u64,
) -> (u64, u64) {
    let spec = scenario::parse_str(scenario_text, "alloc.toml", "alloc").unwrap();
    let capacity = 256;
    let arena = Rc::new(RefCell::new(Arena::new(capacity + 1)));
    let (console, robot, mut egress) = (bind(), bind(), bind());
    // As `transport::open` sets them up: each side takes datagrams from its
    // one peer (the filter is on the receive path the loop turns).
    egress.accept_only(robot.local_addr());
    let shared = ConsoleAddr::default();
    let source = UdpSource::new(bind(), Some(arena.clone()), ConsolePolicy::Named(console.local_addr()), shared.clone());
    let (from_robot, to_console) = (egress.try_clone().unwrap(), source.port().try_clone().unwrap());
    let to_bridge = PeerAddr::new(source.local_addr());
    let unused = std::env::temp_dir().join("netfi-udp-alloc-unused.csv");
    let back = scenario::parse_str(return_scenario.unwrap_or(""), "return.toml", "return").unwrap();
    let chan = UdpReturn::new(from_robot, to_console, None, shared.clone(), return_scenario.is_some(), capacity);
    let ret = Path::of(Link::new(Scenario::new(&back, 4).unwrap(), capacity, datagrams).unwrap(), chan, 4, unused.clone(), false);
    let sink = UdpSink::new(egress, robot.local_addr(), Some(arena));
    let chan = Forward::new(source, sink, false, true);
    let fwd = Path::of(Link::new(Scenario::new(&spec, 3).unwrap(), capacity, datagrams).unwrap(), chan, 3, unused, false);
    let mut lane = Lane::new(fwd, vec![Box::new(ret)]);
    let payload = [0x5au8; 300];
    let mut buf = vec![0u8; 1 << 16];
    let mut before = 0;
    let mut replies = 0;
    for i in 0..datagrams {
        if i == datagrams - measured {
            before = allocations();
        }
        console.send_to(&payload, &to_bridge).unwrap();
        let link = &lane.forward.link;
        let (entered, released) = (link.next_ingress_index(), link.released());
        // In, then out (PLM-2 delays nothing): released, or dropped.
        until(|| {
            lane.turn();
            let link = &lane.forward.link;
            (link.next_ingress_index() > entered && link.held() == 0).then_some(())
        });
        if lane.forward.link.released() == released {
            continue;
        }
        let d = until(|| robot.recv_from(&mut buf).unwrap());
        robot.send_to(&buf[..52], &PeerAddr::new(d.from)).unwrap();
        // The reply goes back (or is dropped, or held) in the loop's turns;
        // drain what reaches the console.
        for _ in 0..64 {
            lane.turn();
            if console.recv_from(&mut buf).unwrap().is_some() {
                replies += 1;
                break;
            }
        }
    }
    (allocations() - before, replies)
}

#[test]
fn the_udp_bridge_does_not_allocate_per_datagram() {
    let plm = "[[stage]]\npreset = \"PLM-2\"\n";
    let back = "[[stage]]\nmodel = \"bernoulli\"\np = 0.3\n[[stage]]\nmodel = \"delay\"\nmin_ms = 0.01\ndist = \"uniform\"\njitter_ms = 0.02\norder = \"reorder\"\n";
    for (name, forward, ret) in
        [("PLM-2, return untouched", plm, None), ("PLM-2, return through loss and delay", plm, Some(back))]
    {
        let (n, replies) = allocations_in_steady_state(forward, ret, 6000, 4000);
        assert_eq!(n, 0, "{name}: {n} allocations in 4000 datagrams");
        // PLM-2 passes about 70% forward, and the way back about 70% of those.
        assert!(replies > 2000, "{name}: only {replies} replies came back");
    }
}
