//! Zero allocations per datagram on the UDP bridge's hot path: a counting
//! global allocator watches the UDP source (raw mode, into the arena), the
//! injector, the UDP sink and the return path (untouched, and through a
//! scenario of its own) over many datagrams after a warm-up. Its own binary,
//! because the allocator is process-wide; everything runs on one thread.

use netfi::injector::{Fate, Injector};
use netfi::sample::FrameSample;
use netfi::scenario::{self, Scenario};
use netfi::service::ports::{FrameSink, FrameSource};
use netfi::service::udp::{Arena, ReturnPath, UdpSink, UdpSource};
use netfi::transport::udp::{PeerAddr, UdpOptions, UdpPort};
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
/// back; returns the allocations made during the last `measured`, and the
/// replies the console got.
fn allocations_in_steady_state(
    scenario_text: &str,
    return_scenario: Option<&str>,
    datagrams: u64,
    measured: u64,
) -> (u64, u64) {
    let spec = scenario::parse_str(scenario_text, "alloc.toml", "alloc").unwrap();
    let capacity = 256;
    let mut inj: Injector<FrameSample> = Injector::new(Scenario::new(&spec, 3).unwrap(), capacity);
    let arena = Rc::new(RefCell::new(Arena::new(capacity + 1)));
    let (console, robot, egress) = (bind(), bind(), bind());
    let ret_port = egress.try_clone().unwrap();
    let ret = match return_scenario {
        None => ReturnPath::untouched(ret_port, None),
        Some(text) => {
            let spec = scenario::parse_str(text, "return.toml", "return").unwrap();
            ReturnPath::shaped(ret_port, None, Scenario::new(&spec, 4).unwrap(), 4, capacity, datagrams)
        }
    };
    let mut source = UdpSource::new(bind(), Some(arena.clone())).with_return_path(ret);
    let mut sink = UdpSink::new(egress, robot.local_addr(), Some(arena));
    let to_bridge = PeerAddr::new(source.local_addr());
    let payload = [0x5au8; 300];
    let mut buf = vec![0u8; 1 << 16];
    let mut sample = FrameSample::ZERO;
    let mut before = 0;
    let mut replies = 0;
    for i in 0..datagrams {
        if i == datagrams - measured {
            before = allocations();
        }
        console.send_to(&payload, &to_bridge).unwrap();
        until(|| source.try_recv(&mut sample).unwrap().then_some(()));
        let now = netfi::clock::now_ns();
        match inj.ingress(now, sample).fate {
            Fate::Dropped(_) => source.dropped(&sample),
            Fate::Scheduled { .. } => {
                let r = until(|| inj.pop_due(netfi::clock::now_ns()));
                sink.send_with(&r.item, |s| s.release_ns = netfi::clock::now_ns()).unwrap();
                let d = until(|| robot.recv_from(&mut buf).unwrap());
                robot.send_to(&buf[..52], &PeerAddr::new(d.from)).unwrap();
                // The reply goes back (or is dropped, or held) inside the
                // source's polls; drain what reaches the console.
                for _ in 0..64 {
                    std::hint::black_box(source.try_recv(&mut sample).unwrap());
                    if console.recv_from(&mut buf).unwrap().is_some() {
                        replies += 1;
                        break;
                    }
                }
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
