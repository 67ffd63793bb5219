//! Every seed rule of a run, in one place. A run's seed is the one given,
//! else the scenario file's, else a fresh one (printed). Each stream and
//! each reverse path derives its own from it by a fixed rule, so the same
//! run seed gives the same fates everywhere; a seed given for a part (or
//! written in its scenario file) takes precedence. A process started by
//! `netfi run` is given every seed the runner decided and derives none.

use crate::scenario::{splitmix64, ScenarioSpec};

/// A seed for runs given none: from the time and the process id.
pub fn fresh() -> u64 {
    let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0);
    splitmix64(t ^ (u64::from(std::process::id()) << 32))
}

/// A fresh run id: `r` + 10 hex digits.
pub fn fresh_run_id() -> String {
    format!("r{:010x}", fresh() & 0xff_ffff_ffff)
}

/// A run's seed: `given`, else the scenario file's, else a fresh one.
pub fn run(given: Option<u64>, spec: &ScenarioSpec) -> u64 {
    given.or(spec.seed).unwrap_or_else(fresh)
}

/// The seed of stream `k`: the run's seed for stream 0 (so one stream is
/// the run as it would be alone), `splitmix64(seed ^ splitmix64(k))` for
/// the others.
pub fn stream(seed: u64, k: usize) -> u64 {
    if k == 0 {
        seed
    } else {
        splitmix64(seed ^ splitmix64(k as u64))
    }
}

/// The seed of a part of a run (a reverse path) whose own scenario is
/// `spec`: `given`, else the file's, else `splitmix64(seed ^ tag)` from
/// the stream's `seed` and the part's fixed `tag`.
pub fn derived(given: Option<u64>, spec: &ScenarioSpec, seed: u64, tag: u64) -> u64 {
    given.or(spec.seed).unwrap_or_else(|| splitmix64(seed ^ tag))
}

/// What the feedback path's seed is derived from, with the stream's seed,
/// when not given (`"feedback"` in ASCII).
pub const FEEDBACK_TAG: u64 = 0x6665_6564_6261_636b;

/// What the video path's seed is derived from, with the stream's seed,
/// when not given (`"video"` in ASCII).
pub const VIDEO_TAG: u64 = 0x7669_6465_6f00_0000;

/// The tag the UDP return path's seed is derived with (`"return"`).
pub const RETURN_TAG: u64 = 0x7265_7475_726e;

/// The tag a ROS 2 return topic's seed is derived with (`"ros2retu"`).
pub const ROS2_RETURN_TAG: u64 = 0x726f_7332_7265_7475;

/// The seed of the feedback path through `spec` (`--return-seed`).
pub fn feedback(given: Option<u64>, spec: &ScenarioSpec, seed: u64) -> u64 {
    derived(given, spec, seed, FEEDBACK_TAG)
}

/// The seed of the video path through `spec` (`--video-seed`).
pub fn video(given: Option<u64>, spec: &ScenarioSpec, seed: u64) -> u64 {
    derived(given, spec, seed, VIDEO_TAG)
}

/// A seed with no scenario to take one from (a console's synthetic
/// motion, a fit): `given` (by `netfi run`: the stream's), else a fresh one.
pub fn given_or_fresh(given: Option<u64>) -> u64 {
    given.unwrap_or_else(fresh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn given_seeds_win_then_the_file_then_the_rule() {
        let mut spec = crate::scenario::parse_str("", "n.toml", "n").unwrap();
        assert_eq!(derived(Some(5), &spec, 1, 2), 5);
        assert_eq!(derived(None, &spec, 1, 2), splitmix64(1 ^ 2));
        assert_eq!(run(Some(9), &spec), 9);
        spec.seed = Some(7);
        assert_eq!(derived(None, &spec, 1, 2), 7);
        assert_eq!(run(None, &spec), 7);
        assert_eq!(stream(42, 0), 42);
        assert_eq!(stream(42, 3), splitmix64(42 ^ splitmix64(3)));
        assert_ne!(stream(42, 1), stream(42, 2));
        assert_eq!(given_or_fresh(Some(3)), 3);
        spec.seed = None;
        assert_eq!(feedback(None, &spec, 1), splitmix64(1 ^ FEEDBACK_TAG));
        assert_eq!(video(None, &spec, 1), splitmix64(1 ^ VIDEO_TAG));
    }
}
