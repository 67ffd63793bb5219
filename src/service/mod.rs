//! The real-time services: console, emulator and simulator loops, and the
//! runner that starts all three. Unlike the sans-IO core these read the
//! clock, pin cores and talk to transports — through the
//! [`FrameSource`](crate::transport::FrameSource) and
//! [`FrameSink`](crate::transport::FrameSink) traits, so the loops do not
//! depend on which transport carries the frames.
//!
//! | file | what |
//! |---|---|
//! | `args` | the services' command-line arguments, and the argv each renders |
//! | `link` | the link: injector, histograms, trace, written once |
//! | `emulator` | the emulator: one loop over lanes of paths around links, and its wiring |
//! | `schema` | the JSON contracts between the processes |
//! | `seeds` | every seed rule |
//! | `control`, `telemetry` | live control of a running emulator, and its telemetry, off the loop |
//! | `video` | the video stream's flags, the robot's camera, the console's receiver |
//! | `console`, `simulator` | the two ends of a local run |
//! | `plan`, `supervise`, `run`, `report` | `netfi run`: what runs where; when to stop what; the processes; the joined report |

pub mod args;
pub mod console;
pub mod control;
pub mod emulator;
pub mod link;
pub mod plan;
pub mod report;
pub mod run;
pub mod schema;
pub mod seeds;
pub mod signals;
pub mod simulator;
pub mod supervise;
pub mod telemetry;
pub mod video;

/// Why `<out>/<role>.pid` could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{what} {}: {source}", .path.display())]
pub struct PidError {
    /// `creating` (the directory) or `writing` (the file).
    pub what: &'static str,
    /// The directory or the file.
    pub path: std::path::PathBuf,
    /// The kernel's error.
    #[source]
    pub source: std::io::Error,
}

/// Writes `<out>/<role>.pid`, so supervisors and tests can find the process.
pub fn write_pid(out: &std::path::Path, role: &str) -> Result<(), PidError> {
    std::fs::create_dir_all(out).map_err(|source| PidError { what: "creating", path: out.to_path_buf(), source })?;
    let path = out.join(format!("{role}.pid"));
    std::fs::write(&path, std::process::id().to_string()).map_err(|source| PidError { what: "writing", path, source })
}

/// Where a service runs: pinned to `core`, or anywhere but `avoid` (the
/// emulator's busy core), or wherever the scheduler likes.
pub fn place(role: &str, core: Option<usize>, avoid: Option<usize>) -> anyhow::Result<()> {
    if let Some(c) = core {
        anyhow::ensure!(core_affinity::set_for_current(core_affinity::CoreId { id: c }), "could not pin the {role} to core {c}");
    } else if let Some(set) = avoid.and_then(crate::host::cores_except) {
        // SAFETY: `set` is a valid cpu_set_t; pid 0 is the calling thread.
        if unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) } != 0 {
            anyhow::bail!("could not keep the {role} off core {}: {}", avoid.unwrap_or_default(), std::io::Error::last_os_error());
        }
    }
    Ok(())
}

/// Moves the calling thread to SCHED_FIFO at `priority` (1–99), so ordinary
/// processes on its core cannot preempt it. Needs root or CAP_SYS_NICE.
/// Under the kernel's real-time throttling ([`rt_throttling`]) a thread
/// that never sleeps is stopped for the rest of each period once it has
/// used its share: 50 ms of every second by default.
pub fn set_realtime(priority: i32) -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: `param` is a valid sched_param; pid 0 is the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// The kernel's real-time throttling, `(runtime_us, period_us)`, when it is
/// on (`kernel.sched_rt_runtime_us` is not -1): a SCHED_FIFO busy loop is
/// then stopped for `period − runtime` of every period.
pub fn rt_throttling() -> Option<(i64, i64)> {
    let read = |name: &str| std::fs::read_to_string(format!("/proc/sys/kernel/{name}")).ok()?.trim().parse::<i64>().ok();
    let runtime = read("sched_rt_runtime_us")?;
    let period = read("sched_rt_period_us")?;
    (runtime >= 0 && runtime < period).then_some((runtime, period))
}
