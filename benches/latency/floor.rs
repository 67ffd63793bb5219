//! Floor intervals: no emulator; a sender on the driving core and a
//! receiver spinning on the emulator's core exchange frames over one
//! transport: the physical cost of one cross-core hop.

use crate::common::args::{check_interrupted, keep_signals, Placement};
use crate::common::chain::Transport;
use crate::common::drive::{pace, WARMUP_S};
use crate::common::ends::{loopback_port, wire};
use crate::common::host::{pin, HostTimer, HostWindow};
use crate::common::process::{fresh_run_id, ForgetRuns};
use anyhow::{Context, Result};
use netfi::clock::now_ns;
use netfi::metrics::{LatencyHistogram, Summary};
use netfi::sample::{FrameSample, ITP_FRAME_LEN};
use netfi::transport::udp::PeerAddr;
use netfi::transport::{IpcConfig, IpcNode, Port, Role, RunId};
use serde::Serialize;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// One floor interval's results.
#[derive(Debug, Clone, Serialize)]
pub struct FloorResult {
    pub repetition: usize,
    pub transport: Transport,
    pub rate_hz: f64,
    pub seconds: f64,
    pub host: HostWindow,
    pub hop_ns: Summary,
    pub sent: u64,
    pub received: u64,
}

/// The pacing of a floor interval and the placement of its two threads.
#[derive(Debug, Clone, Copy)]
struct Floor {
    /// Frames in all, the first `warm` of them unrecorded.
    frames: u64,
    warm: u64,
    period_ns: f64,
    tx_core: Option<usize>,
    rx_core: Option<usize>,
    rt: Option<i32>,
}

/// What the two threads of a floor interval measured: frames sent, the
/// hop's histogram, frames received, seconds after the warm-up.
type Measured = (u64, LatencyHistogram, u64, f64);

/// A floor interval: a sender on the driving core, a receiver spinning on
/// the emulator's core, one hop of `transport`, no emulator.
pub fn floor_interval(p: &Placement, transport: Transport, rate_hz: f64, seconds: f64, rep: usize) -> Result<FloorResult> {
    check_interrupted()?;
    let warm = (rate_hz * WARMUP_S).ceil() as u64;
    let frames = warm + (rate_hz * seconds).round() as u64;
    let f = Floor { frames, warm, period_ns: 1e9 / rate_hz, tx_core: p.bench_core, rx_core: p.emulator_core, rt: p.rt_priority };
    let host = HostTimer::start(p.quiet);
    let (sent, hist, received, secs) = match transport {
        Transport::Iceoryx2 => floor_ipc(f)?,
        Transport::Udp => floor_udp(f)?,
    };
    let host = host.stop();
    Ok(FloorResult { repetition: rep, transport, rate_hz, seconds: secs, host, hop_ns: hist.summary(), sent, received })
}

/// One iceoryx2 hop: the console's direct port to the simulator's.
fn floor_ipc(f: Floor) -> Result<Measured> {
    let run_id = fresh_run_id();
    let _forget = ForgetRuns(vec![run_id.clone()]);
    let done = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<()>();
    let (rid, done_rx) = (run_id.clone(), done.clone());
    let receiver = std::thread::spawn(move || -> Result<(LatencyHistogram, u64)> {
        pin(f.rx_core, f.rt);
        let node = IpcNode::open(&IpcConfig::new(RunId::new(&rid)?), Role::Simulator)?;
        keep_signals();
        let mut sub = node.subscriber(Port::DIRECT)?;
        let _ = ready_tx.send(());
        let (mut h, mut n) = (LatencyHistogram::new(), 0u64);
        loop {
            match sub.recv_with(|s| (now_ns(), *s)) {
                Ok(Some((_, s))) if s.is_end() => break,
                Ok(Some((t, s))) => {
                    n += 1;
                    if s.console_index >= f.warm {
                        h.record_signed(t as i64 - s.send_ns as i64);
                    }
                }
                _ if done_rx.load(Ordering::Acquire) => break,
                _ => std::hint::spin_loop(),
            }
        }
        Ok((h, n))
    });
    ready_rx.recv_timeout(Duration::from_secs(10)).context("the floor receiver did not start")?;
    let sender = std::thread::spawn(move || -> Result<(u64, f64)> {
        pin(f.tx_core, f.rt);
        let node = IpcNode::open(&IpcConfig::new(RunId::new(&run_id)?), Role::Console)?;
        keep_signals();
        let mut publ = node.publisher(Port::DIRECT)?;
        let t = Instant::now();
        while publ.peers_connected() == 0 {
            anyhow::ensure!(t.elapsed() < Duration::from_secs(10), "the floor receiver did not attach");
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(20));
        let (sent, secs) = pace(f.frames, f.period_ns, f.warm, |i| {
            publ.send_with(|s| {
                s.len = ITP_FRAME_LEN as u32;
                s.console_index = i;
                s.send_ns = now_ns();
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
    Ok((sent, h, n, secs))
}

/// One UDP hop over loopback; the send times kept in a table by sequence.
fn floor_udp(f: Floor) -> Result<Measured> {
    let rx = loopback_port()?;
    let to = PeerAddr::new(rx.local_addr());
    let done = Arc::new(AtomicBool::new(false));
    let sent_ns: Arc<Vec<AtomicU64>> = Arc::new((0..f.frames).map(|_| AtomicU64::new(0)).collect());
    let (sent_r, done_r) = (sent_ns.clone(), done.clone());
    let receiver = std::thread::spawn(move || -> (LatencyHistogram, u64) {
        pin(f.rx_core, f.rt);
        let (mut h, mut n, mut buf) = (LatencyHistogram::new(), 0u64, [0u8; 256]);
        loop {
            match rx.recv_from(&mut buf) {
                Ok(Some(_)) => {
                    let t = now_ns();
                    n += 1;
                    let i = u64::from(u32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]));
                    if i >= f.warm {
                        if let Some(s) = sent_r.get(i as usize) {
                            h.record_signed(t as i64 - s.load(Ordering::Acquire) as i64);
                        }
                    }
                }
                _ if done_r.load(Ordering::Acquire) => break,
                _ => std::hint::spin_loop(),
            }
        }
        (h, n)
    });
    let sender = std::thread::spawn(move || -> Result<(u64, f64)> {
        pin(f.tx_core, f.rt);
        let tx = loopback_port()?;
        Ok(pace(f.frames, f.period_ns, f.warm, |i| {
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
    Ok((sent, h, n, secs))
}
