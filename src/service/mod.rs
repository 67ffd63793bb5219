//! The real-time services: console, emulator and simulator loops, and the
//! runner that starts all three. Unlike the sans-IO core these read the
//! clock, pin cores and talk to transports — through the [`ports`] traits,
//! so the loops do not depend on which transport carries the frames.

pub mod args;
pub mod console;
pub mod emulator;
pub mod ipc;
pub mod ports;
pub mod report;
pub mod run;
pub mod signals;
pub mod simulator;
pub mod udp;

/// Writes `<out>/<role>.pid`, so supervisors and tests can find the process.
pub fn write_pid(out: &std::path::Path, role: &str) -> anyhow::Result<()> {
    use anyhow::Context;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join(format!("{role}.pid"));
    std::fs::write(&path, std::process::id().to_string()).with_context(|| format!("writing {}", path.display()))
}
