//! The range of every numeric flag of `netfi run` and the services, and
//! the value parsers that check it where the flag is parsed, so a value out
//! of range is refused before anything starts. An error names the range;
//! clap puts the flag and the value given before it.

use clap::builder::RangedU64ValueParser;
use crate::model::units::show;

/// The frame rates a run accepts, Hz: 0.001 Hz to the console's highest
/// (1 MHz, [`crate::motion::MAX_RATE_HZ`]), so a rate the console would
/// refuse is refused before anything starts.
pub const RATE_HZ_RANGE: std::ops::RangeInclusive<f64> = 0.001..=crate::motion::MAX_RATE_HZ;

/// Default frame rate of a run, Hz.
pub const DEFAULT_RATE_HZ: f64 = 1000.0;

/// The longest run: a week, in seconds.
pub const MAX_RUN_S: f64 = 604_800.0;

/// The most frames a run may stream: a week at 10 MHz, rounded up.
pub const MAX_RUN_FRAMES: u64 = 10_000_000_000_000;

/// The longest a process waits for a peer or for the robot's feedback: an
/// hour, in seconds.
pub const MAX_WAIT_S: f64 = 3600.0;

/// The longest gap the simulator may be told is not yet a stall, and the
/// longest telemetry interval: an hour, in milliseconds.
pub const MAX_INTERVAL_MS: u64 = 3_600_000;

/// The longest idle time before a UDP ingress ends the run: a week, in
/// milliseconds.
pub const MAX_IDLE_END_MS: f64 = 604_800_000.0;

/// The longest nap between two polls of a console or robot: a second, in
/// microseconds.
pub const MAX_NAP_US: u64 = 1_000_000;

/// The highest core number a flag may name: the kernel's CPU set holds
/// `CPU_SETSIZE` CPUs.
pub const MAX_CORE: u64 = libc::CPU_SETSIZE as u64 - 1;

/// The largest kernel buffer a UDP socket may ask for, bytes: 1 GiB (the
/// kernel takes an `int`, and doubles it).
pub const MAX_UDP_BUFFER_BYTES: u64 = 1 << 30;

/// The most streams one run may carry (`--streams`).
pub const MAX_STREAMS: u32 = 64;

/// Parses `--rate-hz`: a finite rate in [`RATE_HZ_RANGE`].
pub fn parse_rate_hz(text: &str) -> Result<f64, String> {
    let r: f64 = text.trim().parse().map_err(|_| format!("--rate-hz takes a number of Hz, got `{text}`"))?;
    if r.is_finite() && RATE_HZ_RANGE.contains(&r) {
        Ok(r)
    } else {
        Err(format!("--rate-hz must be between 0.001 Hz and 1 MHz (1000000 Hz), got {r}"))
    }
}

/// Parses a time flag named `_s`: seconds, or a number with its unit
/// (`250ms`, `10s`, `2min`).
pub fn seconds(text: &str) -> Result<f64, String> {
    crate::model::parse_duration(text, crate::model::TimeUnit::S)
}

/// Parses a time flag named `_ms`: milliseconds, or a number with its unit
/// (`500us`, `250ms`, `2s`).
pub fn millis(text: &str) -> Result<f64, String> {
    crate::model::parse_duration(text, crate::model::TimeUnit::Ms)
}

/// `v` (in `unit`) when it is above 0 and at most `max` (`what`: the
/// limit in words).
fn positive_at_most(v: f64, max: f64, unit: &str, what: &str) -> Result<f64, String> {
    if v > 0.0 && v <= max {
        Ok(v)
    } else {
        Err(format!("must be more than 0 {unit} and at most {what} ({} {unit}), got {} {unit}", show(max), show(v)))
    }
}

/// Parses how long a run streams (`--duration-s`): more than 0 s, at most
/// [`MAX_RUN_S`].
pub fn run_seconds(text: &str) -> Result<f64, String> {
    positive_at_most(seconds(text)?, MAX_RUN_S, "s", "a week")
}

/// Parses how long a process waits (`--wait-for-peer-s`,
/// `--feedback-wait-s`): 0 to [`MAX_WAIT_S`].
pub fn wait_seconds(text: &str) -> Result<f64, String> {
    let s = seconds(text)?;
    if s <= MAX_WAIT_S {
        Ok(s)
    } else {
        Err(format!("must be from 0 to an hour ({} s), got {} s", show(MAX_WAIT_S), show(s)))
    }
}

/// Parses a wait given in milliseconds (`--ros2-linger-ms`): 0 to an hour.
pub fn wait_millis(text: &str) -> Result<f64, String> {
    let ms = millis(text)?;
    if ms <= MAX_WAIT_S * 1e3 {
        Ok(ms)
    } else {
        Err(format!("must be from 0 to an hour ({} ms), got {} ms", show(MAX_WAIT_S * 1e3), show(ms)))
    }
}

/// Parses the simulator's `--stall-ms`: more than 0, at most an hour.
pub fn stall_millis(text: &str) -> Result<f64, String> {
    positive_at_most(millis(text)?, MAX_INTERVAL_MS as f64, "ms", "an hour")
}

/// Parses the emulator's `--idle-end-ms`: more than 0, at most a week.
pub fn idle_end_millis(text: &str) -> Result<f64, String> {
    positive_at_most(millis(text)?, MAX_IDLE_END_MS, "ms", "a week")
}

/// `--frames`: 1 to [`MAX_RUN_FRAMES`].
pub fn frames() -> RangedU64ValueParser<u64> {
    RangedU64ValueParser::new().range(1..=MAX_RUN_FRAMES)
}

/// The highest `--capture-max-records`: 2^32 records.
pub const MAX_CAPTURE_RECORDS: u64 = 1 << 32;

/// `--capture-max-records`: 1 to [`MAX_CAPTURE_RECORDS`].
pub fn capture_max_records() -> RangedU64ValueParser<u64> {
    RangedU64ValueParser::new().range(1..=MAX_CAPTURE_RECORDS)
}

/// A core number: 0 to [`MAX_CORE`].
pub fn core() -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::new().range(0..=MAX_CORE)
}

/// `--queue-capacity`: 1 to the release queue's largest,
/// [`crate::scheduler::MAX_CAPACITY`].
pub fn queue_capacity() -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::new().range(1..=crate::scheduler::MAX_CAPACITY as u64)
}

/// `--telemetry-ms`: 0 (none) to an hour.
pub fn telemetry_ms() -> RangedU64ValueParser<u64> {
    RangedU64ValueParser::new().range(0..=MAX_INTERVAL_MS)
}

/// `--nap-us`: 0 to a second.
pub fn nap_us() -> RangedU64ValueParser<u64> {
    RangedU64ValueParser::new().range(0..=MAX_NAP_US)
}

/// `--udp-buffer-bytes`: 1 to [`MAX_UDP_BUFFER_BYTES`].
pub fn udp_buffer_bytes() -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::new().range(1..=MAX_UDP_BUFFER_BYTES)
}

/// `--expected-frames`: 1 to [`MAX_RUN_FRAMES`].
pub fn expected_frames() -> RangedU64ValueParser<u64> {
    RangedU64ValueParser::new().range(1..=MAX_RUN_FRAMES)
}

/// `--rt-priority`: SCHED_FIFO's 1 to 99.
pub fn rt_priority() -> clap::builder::RangedI64ValueParser<i32> {
    clap::value_parser!(i32).range(1..=99)
}

/// `--streams`: 1 to [`MAX_STREAMS`].
pub fn streams() -> RangedU64ValueParser<u32> {
    RangedU64ValueParser::new().range(1..=MAX_STREAMS as u64)
}
