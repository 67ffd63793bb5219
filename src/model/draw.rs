//! Uniform draws as 53-bit integers, compared against integer thresholds.
//!
//! A probability `p` becomes the threshold `round(p · 2^53)`, and an event of
//! probability `p` happens when a draw `r = next_u64() >> 11` is below it. This
//! is the same uniform that `rng.random::<f64>()` gives (`r · 2^-53`), but the
//! per-frame comparison is an integer one: exact, branch-free where a state
//! picks among several targets, and identical on every platform.

use super::StageRng;
use rand::Rng;

/// The threshold of a certain event: no 53-bit draw reaches it.
pub(crate) const ALWAYS: u64 = 1 << 53;

/// A uniform integer in `[0, 2^53)`.
#[inline(always)]
pub(crate) fn u53(rng: &mut StageRng) -> u64 {
    rng.next_u64() >> 11
}

/// The threshold of probability `p` (clamped to `[0, 1]`).
pub(crate) fn threshold(p: f64) -> u64 {
    let scaled = (p * ALWAYS as f64).round();
    if scaled <= 0.0 {
        0
    } else if scaled >= ALWAYS as f64 {
        ALWAYS
    } else {
        scaled as u64
    }
}
