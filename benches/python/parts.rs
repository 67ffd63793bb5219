//! One part: `netfi emulator` (Normal both ways), the Python robot, then
//! the Python console for the interval; the host sampled meanwhile;
//! everything read back.

use crate::common::args::{Placement, ROOT};
use crate::common::host::{HostTimer, HostWindow};
use crate::common::out::Out;
use crate::common::process::{fresh_run_id, read_json, Build, Emulator, EmulatorSpec};
use crate::windows::{Sampler, Window};
use crate::args::Args;
use anyhow::{bail, Context, Result};
use netfi::service::args::EndsArgs;
use netfi::transport::udp::UdpArgs;
use netfi::transport::Payload;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The Python programs of the benchmark.
const BENCH_PY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/clients/python/bench");

/// What one part measured.
#[derive(Debug)]
pub struct Part {
    pub transport: &'static str,
    pub dir: PathBuf,
    /// Robot records (`ROBOT_FIELDS` of clients/python/bench/common.py).
    pub robot: Vec<[i64; 8]>,
    /// Console records (`CONSOLE_FIELDS`).
    pub console: Vec<[i64; 12]>,
    pub console_summary: Value,
    pub robot_summary: Value,
    pub emulator: Value,
    pub windows: Vec<Window>,
    pub host: HostWindow,
}

/// Whether the interpreter can import the bindings and the client module;
/// why not when it cannot.
pub fn python_missing(python: &str) -> Option<String> {
    let code = format!("import sys; sys.path.insert(0, {:?}); import iceoryx2, netfi_iox", format!("{ROOT}/clients/python"));
    match Command::new(python).args(["-c", &code]).output() {
        Ok(o) if o.status.success() => None,
        Ok(o) => Some(String::from_utf8_lossy(&o.stderr).trim().lines().last().unwrap_or("").to_string()),
        Err(e) => Some(format!("{python}: {e}")),
    }
}

fn python(a: &Args, script: &str, dir: &Path, who: &str, core: Option<usize>, extra: &[String]) -> Result<Child> {
    let log = std::fs::File::create(dir.join(format!("{who}.log")))?;
    let mut c = Command::new(&a.python);
    c.arg(format!("{BENCH_PY}/{script}")).args(extra);
    c.arg("--records").arg(dir.join(format!("{who}.bin"))).arg("--summary").arg(dir.join(format!("{who}.json")));
    if let Some(core) = core {
        c.args(["--core", &core.to_string()]);
    }
    if let Some(nice) = a.python_nice {
        c.args(["--nice", &nice.to_string()]);
    }
    c.stdin(Stdio::null()).stdout(log.try_clone()?).stderr(log).spawn().with_context(|| format!("starting {} {script}", a.python))
}

/// Waits for `child` up to `limit`; kills it after.
fn wait(mut child: Child, who: &str, limit: Duration, dir: &Path) -> Result<()> {
    let t0 = Instant::now();
    loop {
        if let Some(status) = child.try_wait()? {
            if !status.success() {
                bail!("the Python {who} ended with {status}; see {}", dir.join(format!("{who}.log")).display());
            }
            return Ok(());
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            bail!("the Python {who} did not finish within {} s; see {}", limit.as_secs(), dir.join(format!("{who}.log")).display());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Waits until the robot has written its ready file; its content.
fn ready(robot: &mut Child, path: &Path) -> Result<Value> {
    let t0 = Instant::now();
    loop {
        if let Ok(text) = std::fs::read_to_string(path) {
            if let Ok(v) = serde_json::from_str(&text) {
                return Ok(v);
            }
        }
        if let Some(status) = robot.try_wait()? {
            bail!("the Python robot ended before it was ready ({status})");
        }
        if t0.elapsed() > Duration::from_secs(30) {
            let _ = robot.kill();
            bail!("the Python robot was not ready after 30 s");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The part over `transport` ("iceoryx2" or "udp").
pub fn run(a: &Args, p: &Placement, build: &Build, out: &Out, transport: &'static str) -> Result<Part> {
    let dir = out.run_dir(transport)?;
    let host = HostTimer::start(p.quiet);
    let ready_path = dir.join("robot.ready");
    let robot_args = |extra: &[String]| {
        let mut v = vec!["--transport".to_string(), transport.into(), "--ready".into(), ready_path.display().to_string(), "--timeout-s".into(), (a.seconds + 90.0).to_string()];
        v.extend(extra.iter().cloned());
        v
    };
    let (emu, robot, routes) = if transport == "iceoryx2" {
        let run_id = fresh_run_id();
        let ids = vec!["--run-id".to_string(), run_id.clone(), "--direct-run-id".into(), format!("{run_id}-direct")];
        let emu = start_emulator(a, p, build, &dir, Some(&run_id), EndsArgs::default(), UdpArgs::default())?;
        let mut robot = python(a, "robot.py", &dir, "robot", p.other_core, &robot_args(&ids))?;
        ready(&mut robot, &ready_path)?;
        (emu, robot, ids)
    } else {
        // The robot's sockets first: the emulator's egress is the robot's
        // chain port.
        let mut robot = python(a, "robot.py", &dir, "robot", p.other_core, &robot_args(&[]))?;
        let ports = ready(&mut robot, &ready_path)?;
        let port = |k: &str| ports[k].as_u64().with_context(|| format!("robot.ready: no {k} port"));
        let ends = EndsArgs { ingress: "udp://127.0.0.1:0".parse()?, egress: format!("udp://127.0.0.1:{}", port("chain")?).parse()?, idle_end_ms: Some(500.0) };
        let udp = UdpArgs { payload: Payload::Itp, console_from: Some("first".parse()?), ..UdpArgs::default() };
        let emu = start_emulator(a, p, build, &dir, None, ends, udp)?;
        let routes = vec!["--chain-to".into(), emu.udp_ingress()?.to_string(), "--direct-to".into(), format!("127.0.0.1:{}", port("direct")?)];
        (emu, robot, routes)
    };
    let sampler = Sampler::start(a.window_s);
    let mut args = vec!["--transport".to_string(), transport.into(), "--rate-hz".into(), a.rate_hz.to_string(), "--duration-s".into(), a.seconds.to_string()];
    args.extend(routes);
    let console = python(a, "console.py", &dir, "console", p.bench_core, &args)?;
    let limit = Duration::from_secs_f64(a.seconds + 60.0);
    let done = wait(console, "console", limit, &dir).and_then(|_| wait(robot, "robot", Duration::from_secs(30), &dir));
    let windows = sampler.stop(a.quiet_steal, a.quiet_others);
    let report = emu.finish(Duration::from_secs(10));
    done?;
    Ok(Part {
        transport,
        robot: records(&dir.join("robot.bin"))?,
        console: records(&dir.join("console.bin"))?,
        console_summary: read_json(&dir.join("console.json"))?,
        robot_summary: read_json(&dir.join("robot.json"))?,
        emulator: report?,
        windows,
        host: host.stop(),
        dir,
    })
}

/// `netfi emulator` with Normal both ways (the forward scenario, and the
/// feedback loop's or the UDP return path's), on the emulator's core.
fn start_emulator(a: &Args, p: &Placement, build: &Build, dir: &Path, run_id: Option<&str>, ends: EndsArgs, udp: UdpArgs) -> Result<Emulator> {
    let expected = (a.rate_hz * (a.seconds + 1.0)) as u64 + 16;
    let emu_dir = dir.join("emulator");
    let spec = EmulatorSpec { scenario: "Normal", dir: &emu_dir, expected_frames: expected, run_id, feedback: true, queue_capacity: None, ends, udp, streams: 1 };
    let mut args = spec.args(p);
    args.channels.feedback.return_scenario = Some("Normal".into());
    build.emulator_of(&args)
}

fn records<const N: usize>(path: &Path) -> Result<Vec<[i64; N]>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(bytes
        .chunks_exact(8 * N)
        .map(|r| std::array::from_fn(|i| i64::from_le_bytes(r[8 * i..8 * i + 8].try_into().expect("8 bytes"))))
        .collect())
}
