//! The emulator process: `netfi emulator`, started for an interval and
//! stopped after it, its report read back.

use crate::args::Settings;
use crate::NETFI;
use anyhow::{bail, Context, Result};
use netfi::service::args::{ControlArgs, EmulatorArgs};
use netfi::service::emulator::EmulatorReport;
use netfi::transport::udp::DEFAULT_UDP_BUFFER_BYTES;
use netfi::transport::{Endpoint, Payload};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The arguments every interval's emulator shares: `scenario` with seed 1,
/// writing to `dir`, on the emulator's core (and at the real-time priority,
/// when one is set). The transports' flags go after [`argv`]'s.
pub fn args(s: &Settings, scenario: &str, dir: &Path, expected_frames: u64, run_id: Option<String>) -> EmulatorArgs {
    let iceoryx2 = run_id.is_some();
    EmulatorArgs {
        run_id,
        scenario: scenario.into(),
        seed: Some(1),
        queue_capacity: None,
        core: s.emulator_core,
        no_pin: s.emulator_core.is_none(),
        rt_priority: s.rt_priority,
        isolate: false,
        drop_bad_checksum: false,
        expected_frames,
        out: dir.to_path_buf(),
        ingress: Endpoint::Iceoryx2,
        egress: Endpoint::Iceoryx2,
        payload: Payload::Itp,
        egress_bind: None,
        console_from: None,
        // The benchmark measures the forward path, as it always has (the
        // flag names the iceoryx2 feedback loop: a UDP chain, which has no
        // run id, refuses it).
        no_feedback: iceoryx2,
        wait_for_peer_s: None,
        return_scenario: None,
        return_seed: None,
        return_to: None,
        no_return: false,
        idle_end_ms: None,
        udp_buffer_bytes: DEFAULT_UDP_BUFFER_BYTES,
        control: ControlArgs { telemetry_ms: s.telemetry_ms, reorder_queue: false, no_control: s.telemetry_ms == 0 || !iceoryx2 },
        stream: Default::default(),
        video: Default::default(),
        ros2: Default::default(),
    }
}

/// `netfi emulator` and `args` (the iceoryx2 flags), then `udp`: the UDP
/// endpoints and options, which [`EmulatorArgs::to_argv`] leaves out.
pub fn argv(args: &EmulatorArgs, udp: &[String]) -> Vec<String> {
    let mut a = vec!["emulator".to_string()];
    a.extend(args.to_argv());
    a.extend(udp.iter().cloned());
    a
}

/// Removes the management segments of its runs when dropped, once all
/// their processes have ended: two processes that drop their nodes at the
/// same moment (the emulator on its end marker, this benchmark's ends) each
/// see the other's node and leave the segment in `/dev/shm`. Declared
/// before the [`Emulator`] of those runs, it is dropped after it, however
/// the interval ends (an interrupt included).
pub struct ForgetRuns(pub Vec<String>);

impl Drop for ForgetRuns {
    fn drop(&mut self) {
        for id in &self.0 {
            if let Ok(run) = netfi::transport::RunId::new(id) {
                netfi::transport::ipc::remove_run_segment_if_unused(&run);
            }
        }
    }
}

/// A running emulator process, stopped when dropped.
pub struct Emulator {
    child: Child,
    dir: PathBuf,
}

impl Emulator {
    /// Starts `netfi` with `args`, writing to `dir`, and waits until it is
    /// ready.
    pub fn spawn(dir: &Path, args: &[String]) -> Result<Emulator> {
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
            // An emulator of many streams sets each up first.
            if t0.elapsed() > Duration::from_secs(120) {
                e.stop();
                bail!("the emulator was not ready after 120 s; see {}", dir.join("emulator.log").display());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Ok(e)
    }

    /// The address of the emulator's UDP ingress, from the
    /// `udp_endpoints.json` it wrote.
    pub fn udp_ingress(&self) -> Result<std::net::SocketAddr> {
        let endpoints: serde_json::Value = serde_json::from_slice(&std::fs::read(self.dir.join("udp_endpoints.json"))?)?;
        Ok(endpoints["ingress"].as_str().context("udp_endpoints.json: no ingress")?.parse()?)
    }

    /// Waits up to `wait` for the emulator to end by itself, then stops it;
    /// returns its report.
    pub fn finish(self, wait: Duration) -> Result<EmulatorReport> {
        let dir = self.dir.clone();
        self.end(wait);
        read_report(&dir)
    }

    /// [`Emulator::finish`] of an emulator of `n` streams (`--streams`):
    /// each stream's report.
    pub fn finish_streams(self, wait: Duration, n: usize) -> Result<Vec<EmulatorReport>> {
        let dir = self.dir.clone();
        self.end(wait);
        (0..n).map(|k| read_report(&netfi::service::plan::stream_dir(&dir, n, k))).collect()
    }

    /// Waits up to `wait` for the emulator to end by itself, then stops it.
    fn end(mut self, wait: Duration) {
        let t0 = Instant::now();
        while t0.elapsed() < wait {
            if let Ok(Some(_)) = self.child.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        self.stop();
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

/// The `emulator.json` in `dir`; its per-frame trace, not needed here (and
/// large at 100 kHz), is removed.
fn read_report(dir: &Path) -> Result<EmulatorReport> {
    let path = dir.join("emulator.json");
    let report: EmulatorReport = serde_json::from_slice(&std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?)
        .with_context(|| format!("parsing {}", path.display()))?;
    let _ = std::fs::remove_file(dir.join("trace_emulator.csv"));
    Ok(report)
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop();
    }
}
