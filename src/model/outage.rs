//! `outage` (docs/spec.md §3.5): communication-loss windows with a cooldown.
//!
//! Per frame at its stage time `t`: inside a window (`t < window_end`) it is
//! dropped; else inside the cooldown after a window
//! (`t < window_end + cooldown`) it is delivered; else, with probability
//! `p_start`, a window of length `L ~ U(min_ms, max_ms)` opens at `t` and the
//! frame is dropped, otherwise delivered. In `unit = "frames"` the window is
//! `L` frames (a uniform integer in `[min_frames, max_frames]`, at least 1,
//! the opening frame included) and the cooldown `cooldown_frames` frames.
//!
//! Ranges ([`super::units`]): a window is at most one hour (`max_ms`) or
//! [`super::units::MAX_FRAMES`] frames, a cooldown at most one week or as
//! many frames.
//!
//! Draws per frame: one (`p_start`; none when it is 1) at an eligible frame,
//! plus one for `L` when a window opens (none if `L` cannot vary); none
//! inside a window or cooldown.
//!
//! Long-run loss at a fixed frame interval `Δ` ([`Outage::loss_rate_approx`]).
//! The frames from one window opening to the next form independent cycles,
//! so the lost fraction is `E[dropped per cycle] / E[frames per cycle]`
//! (renewal-reward). With the opening frame at `t`, the frames at `t + jΔ`,
//! `j ≥ 0`:
//! - dropped: those with `jΔ < L`, that is `max(1, ⌈L/Δ⌉)`;
//! - then delivered in the cooldown: up to the first `j` with
//!   `jΔ ≥ L + C`, so the window and cooldown take `max(1, ⌈(L + C)/Δ⌉)`
//!   frames;
//! - then eligible frames, each opening with `p_start`: a geometric number of
//!   deliveries, mean `(1 − p_start)/p_start`, before the next opening.
//!
//! `E[max(1, ⌈X/Δ⌉)]` for `X` uniform is the integral of a step function,
//! computed piece by piece in closed form, so the result is exact up to
//! rounding (window lengths are drawn to the nanosecond; that discreteness
//! changes the result by about 1 ns over the window-length range). In frames
//! the cycle is `L + C + G` frames with `L` dropped:
//! `E[L] / (E[L] + C + (1 − p)/p)`. For `p_start = 0` no window ever opens
//! and the loss is 0. For small `Δ` this tends to docs/spec.md §3.5's
//! `E[L] / (E[L] + cooldown)` (`p_start = 1`).

use super::units::{at_most_frames, at_most_ms, ms_to_ns, MAX_COOLDOWN_MS, MAX_DURATION_MS};
use super::{Millis, Model, ParamError, Probability, StageRng, Verdict};
use rand::RngExt;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OutageUnit {
    /// Window length and cooldown in milliseconds of frame time.
    #[default]
    Time,
    /// Window length (uniform integer ≥ 1) and cooldown counted in frames.
    Frames,
}

impl OutageUnit {
    fn name(self) -> &'static str {
        match self {
            OutageUnit::Time => "time",
            OutageUnit::Frames => "frames",
        }
    }
}

/// Parameters as written in a scenario file. `unit = "time"` takes `max_ms`
/// and `cooldown_ms` (and `min_ms`, default 0); `unit = "frames"` takes
/// `max_frames` and `cooldown_frames` (and `min_frames`, default 1). Fields of
/// the other unit are an error.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OutageParams {
    /// Probability that a window opens at a frame outside window and cooldown.
    pub p_start: Probability,
    #[serde(default)]
    pub unit: OutageUnit,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_ms: Option<Millis>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_ms: Option<Millis>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cooldown_ms: Option<Millis>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_frames: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_frames: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cooldown_frames: Option<u64>,
}

impl OutageParams {
    /// Windows in time: `L ~ U(min_ms, max_ms)`, then `cooldown_ms` in which
    /// none opens; a window opens with `p_start` at each eligible frame.
    pub fn time(p_start: f64, min_ms: f64, max_ms: f64, cooldown_ms: f64) -> Result<Self, ParamError> {
        use super::units::millis;
        Ok(OutageParams {
            p_start: super::units::probability("p_start", p_start)?,
            unit: OutageUnit::Time,
            min_ms: Some(millis("min_ms", min_ms)?),
            max_ms: Some(millis("max_ms", max_ms)?),
            cooldown_ms: Some(millis("cooldown_ms", cooldown_ms)?),
            min_frames: None,
            max_frames: None,
            cooldown_frames: None,
        })
    }

    /// Windows counted in frames: `L` uniform in `[min_frames, max_frames]`,
    /// then `cooldown_frames` frames in which none opens.
    pub fn frames(p_start: f64, min_frames: u64, max_frames: u64, cooldown_frames: u64) -> Result<Self, ParamError> {
        Ok(OutageParams {
            p_start: super::units::probability("p_start", p_start)?,
            unit: OutageUnit::Frames,
            min_ms: None,
            max_ms: None,
            cooldown_ms: None,
            min_frames: Some(min_frames),
            max_frames: Some(max_frames),
            cooldown_frames: Some(cooldown_frames),
        })
    }
}

/// Windows opened so far and the sum of their drawn lengths: `total_ns` in
/// `unit = "time"`, `total_frames` in `unit = "frames"` (the other is 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct OutageWindows {
    pub count: u64,
    pub total_ns: u64,
    pub total_frames: u64,
}

#[derive(Debug, Clone)]
enum Clock {
    Time {
        length_min_ns: u64,
        /// `max − min`; the length is `min + ⌊U · span⌋`.
        length_span_ns: u64,
        cooldown_ns: u64,
        /// End of the current (or last) window; frames before it are dropped.
        window_end_ns: u64,
        /// End of its cooldown; frames before it are delivered.
        quiet_end_ns: u64,
    },
    Frames {
        length_min: u64,
        length_max: u64,
        cooldown: u64,
        /// Frames still to drop in the current window.
        drops_left: u64,
        /// Frames still to deliver in the cooldown after it.
        quiet_left: u64,
    },
}

/// A validated `outage` stage, its state and window counters.
#[derive(Debug, Clone)]
pub struct Outage {
    p_start: f64,
    start: rand::distr::Bernoulli,
    clock: Clock,
    windows: OutageWindows,
}

impl Outage {
    pub fn new(params: &OutageParams) -> Result<Self, ParamError> {
        let unit = params.unit;
        let p_start = params.p_start.get();
        let start = rand::distr::Bernoulli::new(p_start)
            .map_err(|e| ParamError::new("p_start", format!("{p_start}: {e}; expected a probability in [0, 1]")))?;
        // The other unit's fields do not apply.
        let foreign = match unit {
            OutageUnit::Time => [("min_frames", params.min_frames.is_some()), ("max_frames", params.max_frames.is_some()), ("cooldown_frames", params.cooldown_frames.is_some())],
            OutageUnit::Frames => [("min_ms", params.min_ms.is_some()), ("max_ms", params.max_ms.is_some()), ("cooldown_ms", params.cooldown_ms.is_some())],
        };
        if let Some((name, _)) = foreign.into_iter().find(|&(_, given)| given) {
            return Err(ParamError::not_for(name, "unit", unit.name()));
        }
        let clock = match unit {
            OutageUnit::Time => {
                let max_ms = params
                    .max_ms
                    .ok_or_else(|| ParamError::new("max_ms", "missing: the longest window in ms (unit = \"time\")"))?
                    .get();
                let min_ms = params.min_ms.map_or(0.0, Millis::get);
                at_most_ms("max_ms", max_ms, MAX_DURATION_MS, "one hour")?;
                if min_ms > max_ms {
                    return Err(ParamError::new(
                        "min_ms",
                        format!("{min_ms} exceeds max_ms = {max_ms}: expected min_ms ≤ max_ms"),
                    ));
                }
                let cooldown_ms = params
                    .cooldown_ms
                    .ok_or_else(|| {
                        ParamError::new(
                            "cooldown_ms",
                            "missing: the time after a window in which none opens, in ms (0 for none)",
                        )
                    })?
                    .get();
                at_most_ms("cooldown_ms", cooldown_ms, MAX_COOLDOWN_MS, "one week")?;
                let (min_ns, max_ns) = (ms_to_ns(min_ms), ms_to_ns(max_ms));
                Clock::Time {
                    length_min_ns: min_ns,
                    length_span_ns: max_ns - min_ns,
                    cooldown_ns: ms_to_ns(cooldown_ms),
                    window_end_ns: 0,
                    quiet_end_ns: 0,
                }
            }
            OutageUnit::Frames => {
                let max = params.max_frames.ok_or_else(|| {
                    ParamError::new("max_frames", "missing: the longest window in frames (unit = \"frames\")")
                })?;
                at_most_frames("max_frames", max)?;
                let min = params.min_frames.unwrap_or(1);
                if min == 0 {
                    return Err(ParamError::new(
                        "min_frames",
                        "0: a window drops at least its opening frame; expected ≥ 1",
                    ));
                }
                if min > max {
                    return Err(ParamError::new(
                        "min_frames",
                        format!("{min} exceeds max_frames = {max}: expected min_frames ≤ max_frames"),
                    ));
                }
                let cooldown = params.cooldown_frames.ok_or_else(|| {
                    ParamError::new(
                        "cooldown_frames",
                        "missing: the frames after a window in which none opens (0 for none)",
                    )
                })?;
                at_most_frames("cooldown_frames", cooldown)?;
                Clock::Frames { length_min: min, length_max: max, cooldown, drops_left: 0, quiet_left: 0 }
            }
        };
        Ok(Outage { p_start, start, clock, windows: OutageWindows::default() })
    }

    /// Long-run lost fraction of frames arriving every `frame_interval_ns`
    /// (module docs; exact up to rounding). `None` for a zero interval in
    /// `unit = "time"`, where every frame shares one instant.
    pub fn loss_rate_approx(&self, frame_interval_ns: u64) -> Option<f64> {
        let p = self.p_start;
        if p == 0.0 {
            return Some(0.0);
        }
        let waiting = (1.0 - p) / p;
        match self.clock {
            Clock::Time { length_min_ns, length_span_ns, cooldown_ns, .. } => {
                if frame_interval_ns == 0 {
                    return None;
                }
                let delta = frame_interval_ns as f64;
                let lo = length_min_ns as f64;
                let hi = lo + length_span_ns as f64;
                let dropped = mean_frames_covering(lo, hi, delta);
                let c = cooldown_ns as f64;
                let held = mean_frames_covering(lo + c, hi + c, delta);
                Some(dropped / (held + waiting))
            }
            Clock::Frames { length_min, length_max, cooldown, .. } => {
                let mean_length = (length_min as f64 + length_max as f64) / 2.0;
                Some(mean_length / (mean_length + cooldown as f64 + waiting))
            }
        }
    }

    /// Windows opened so far and the sum of their drawn lengths.
    pub fn windows(&self) -> OutageWindows {
        self.windows
    }
}

/// `E[max(1, ⌈X/Δ⌉)]` for `X ~ U[lo, hi]` (or `X = lo` when `hi = lo`): the
/// mean number of frames `t + jΔ`, `j ≥ 0`, with `jΔ < X`, counting the
/// frame at `t` even when `X = 0`.
fn mean_frames_covering(lo: f64, hi: f64, delta: f64) -> f64 {
    let steps = |x: f64| (x / delta).ceil().max(1.0);
    if hi <= lo {
        return steps(lo);
    }
    // `G(x) = ∫_0^x max(1, ⌈u/Δ⌉) du`: on `((k−1)Δ, kΔ]` the step is `k`, so
    // `G(x) = Δ·k(k−1)/2 + k·(x − (k−1)Δ)` with `k = max(1, ⌈x/Δ⌉)`.
    let integral = |x: f64| {
        let k = steps(x);
        delta * k * (k - 1.0) / 2.0 + k * (x - (k - 1.0) * delta)
    };
    (integral(hi) - integral(lo)) / (hi - lo)
}

impl Model for Outage {
    #[inline]
    fn decide(&mut self, t_ns: u64, rng: &mut StageRng) -> Verdict {
        match &mut self.clock {
            Clock::Time { length_min_ns, length_span_ns, cooldown_ns, window_end_ns, quiet_end_ns } => {
                if t_ns < *window_end_ns {
                    return Verdict::Drop;
                }
                if t_ns < *quiet_end_ns || !rng.sample(self.start) {
                    return Verdict::PASS;
                }
                let length_ns = if *length_span_ns == 0 {
                    *length_min_ns
                } else {
                    // `U < 1`, so the floor stays below the span.
                    *length_min_ns + (rng.random::<f64>() * *length_span_ns as f64) as u64
                };
                *window_end_ns = t_ns.saturating_add(length_ns);
                *quiet_end_ns = window_end_ns.saturating_add(*cooldown_ns);
                self.windows.count += 1;
                self.windows.total_ns = self.windows.total_ns.saturating_add(length_ns);
                Verdict::Drop
            }
            Clock::Frames { length_min, length_max, cooldown, drops_left, quiet_left } => {
                if *drops_left > 0 {
                    *drops_left -= 1;
                    return Verdict::Drop;
                }
                if *quiet_left > 0 {
                    *quiet_left -= 1;
                    return Verdict::PASS;
                }
                if !rng.sample(self.start) {
                    return Verdict::PASS;
                }
                let length =
                    if length_min == length_max { *length_min } else { rng.random_range(*length_min..=*length_max) };
                *drops_left = length - 1;
                *quiet_left = *cooldown;
                self.windows.count += 1;
                self.windows.total_frames = self.windows.total_frames.saturating_add(length);
                Verdict::Drop
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn ms(v: f64) -> Millis {
        Millis::new(v).unwrap()
    }

    fn time(p_start: f64, min_ms: f64, max_ms: f64, cooldown_ms: f64) -> OutageParams {
        OutageParams::time(p_start, min_ms, max_ms, cooldown_ms).unwrap()
    }

    fn frames(p_start: f64, min: u64, max: u64, cooldown: u64) -> OutageParams {
        OutageParams::frames(p_start, min, max, cooldown).unwrap()
    }

    fn field(p: OutageParams) -> String {
        Outage::new(&p).unwrap_err().field
    }

    #[test]
    fn parses_the_clm_preset_and_defaults() {
        let p: OutageParams = toml::from_str("p_start = 1\nmin_ms = 0\nmax_ms = 3000\ncooldown_ms = 8500").unwrap();
        assert_eq!(p, time(1.0, 0.0, 3000.0, 8500.0));
        let p: OutageParams = toml::from_str("p_start = 1\nmax_ms = 3000\ncooldown_ms = 8500").unwrap();
        Outage::new(&p).unwrap();
        let p: OutageParams =
            toml::from_str("p_start = \"2%\"\nunit = \"frames\"\nmax_frames = 30\ncooldown_frames = 100").unwrap();
        Outage::new(&p).unwrap();
        assert!(toml::from_str::<OutageParams>("p_start = 1\nmax_ms = 1\ncooldown = 2").is_err());
    }

    #[test]
    fn rejects_bad_parameters() {
        let mut p = time(1.0, 0.0, 10.0, 1.0);
        p.max_ms = None;
        assert_eq!(field(p), "max_ms");
        let mut p = time(1.0, 0.0, 10.0, 1.0);
        p.cooldown_ms = None;
        assert_eq!(field(p), "cooldown_ms");
        assert_eq!(field(time(1.0, 20.0, 10.0, 1.0)), "min_ms");
        for (name, set) in [
            ("min_frames", (|p: &mut OutageParams| p.min_frames = Some(1)) as fn(&mut OutageParams)),
            ("max_frames", |p| p.max_frames = Some(1)),
            ("cooldown_frames", |p| p.cooldown_frames = Some(1)),
        ] {
            let mut p = time(1.0, 0.0, 10.0, 1.0);
            set(&mut p);
            assert_eq!(field(p), name);
        }

        let mut p = frames(1.0, 1, 10, 1);
        p.max_frames = None;
        assert_eq!(field(p), "max_frames");
        let mut p = frames(1.0, 1, 10, 1);
        p.cooldown_frames = None;
        assert_eq!(field(p), "cooldown_frames");
        assert_eq!(field(frames(1.0, 0, 10, 1)), "min_frames");
        assert_eq!(field(frames(1.0, 11, 10, 1)), "min_frames");
        for (name, set) in [
            ("min_ms", (|p: &mut OutageParams| p.min_ms = Some(ms(1.0))) as fn(&mut OutageParams)),
            ("max_ms", |p| p.max_ms = Some(ms(1.0))),
            ("cooldown_ms", |p| p.cooldown_ms = Some(ms(1.0))),
        ] {
            let mut p = frames(1.0, 1, 10, 1);
            set(&mut p);
            assert_eq!(field(p), name);
        }
        let mut p = frames(1.0, 1, 10, 1);
        p.min_frames = None;
        Outage::new(&p).unwrap();
    }

    /// The frames of a 1 kHz stream around one window, as a string.
    fn fates(m: &mut Outage, rng: &mut StageRng, from_ms: u64, to_ms: u64) -> String {
        (from_ms..to_ms).map(|i| if m.decide(i * 1_000_000, rng) == Verdict::Drop { 'x' } else { '.' }).collect()
    }

    #[test]
    fn window_then_cooldown_then_next_window() {
        // L = 3.5 ms exactly, cooldown 2 ms, p_start 1: the opening frame at 0
        // and those at 1, 2, 3 ms are dropped (t < 3.5 ms); 4 and 5 ms fall in
        // the cooldown (t < 5.5 ms); 6 ms opens the next window.
        let mut m = Outage::new(&time(1.0, 3.5, 3.5, 2.0)).unwrap();
        let mut rng = StageRng::seed_from_u64(1);
        assert_eq!(fates(&mut m, &mut rng, 0, 13), "xxxx..xxxx..x");
        assert_eq!(m.windows(), OutageWindows { count: 3, total_ns: 10_500_000, total_frames: 0 });
    }

    #[test]
    fn cooldown_end_is_exclusive_and_windows_start_at_frames() {
        // L = 2 ms, cooldown 1 ms: frames at 0, 1 ms dropped; at 2 ms the
        // cooldown holds; at 3 ms (= window end + cooldown) a window opens.
        let mut m = Outage::new(&time(1.0, 2.0, 2.0, 1.0)).unwrap();
        let mut rng = StageRng::seed_from_u64(1);
        assert_eq!(fates(&mut m, &mut rng, 0, 9), "xx.xx.xx.");
        // An empty window still drops its opening frame.
        let mut m = Outage::new(&time(1.0, 0.0, 0.0, 0.0)).unwrap();
        assert_eq!(fates(&mut m, &mut rng, 0, 5), "xxxxx");
    }

    #[test]
    fn no_cooldown_before_the_first_window() {
        let mut m = Outage::new(&time(1.0, 1.0, 1.0, 100.0)).unwrap();
        let mut rng = StageRng::seed_from_u64(1);
        assert_eq!(m.decide(0, &mut rng), Verdict::Drop);
    }

    #[test]
    fn never_opens_with_p_start_zero() {
        let mut m = Outage::new(&time(0.0, 1.0, 5.0, 1.0)).unwrap();
        let mut rng = StageRng::seed_from_u64(1);
        assert!((0..10_000).all(|i| m.decide(i * 1_000, &mut rng) == Verdict::PASS));
        assert_eq!(m.loss_rate_approx(1_000_000), Some(0.0));
        assert_eq!(m.windows().count, 0);
    }

    #[test]
    fn frames_unit_counts_frames() {
        let mut m = Outage::new(&frames(1.0, 3, 3, 2)).unwrap();
        let mut rng = StageRng::seed_from_u64(1);
        // Time does not matter in frames: all frames at one instant.
        let got: String = (0..12).map(|_| if m.decide(0, &mut rng) == Verdict::Drop { 'x' } else { '.' }).collect();
        assert_eq!(got, "xxx..xxx..xx");
        assert_eq!(m.windows(), OutageWindows { count: 3, total_ns: 0, total_frames: 9 });
        assert_eq!(m.loss_rate_approx(0), Some(0.6));
        let mut m = Outage::new(&frames(1.0, 1, 4, 0)).unwrap();
        assert!((0..1000).all(|_| m.decide(0, &mut rng) == Verdict::Drop));
    }

    #[test]
    fn window_lengths_stay_in_range() {
        let mut m = Outage::new(&time(1.0, 2.0, 5.0, 0.0)).unwrap();
        let mut rng = StageRng::seed_from_u64(6);
        let mut last = m.windows();
        for i in 0..200_000u64 {
            m.decide(i * 100_000, &mut rng);
            let w = m.windows();
            if w.count > last.count {
                let length = w.total_ns - last.total_ns;
                assert!((2_000_000..5_000_000).contains(&length), "{length}");
            }
            last = w;
        }
        assert!(last.count > 4_000, "{}", last.count);
    }

    #[test]
    fn covering_frames_integral() {
        // Fixed lengths: exact counts.
        assert_eq!(mean_frames_covering(0.0, 0.0, 1.0), 1.0);
        assert_eq!(mean_frames_covering(3.5, 3.5, 1.0), 4.0);
        assert_eq!(mean_frames_covering(3.0, 3.0, 1.0), 3.0);
        // U[0, 2Δ]: 1 on [0, Δ], 2 on (Δ, 2Δ]: mean 1.5.
        assert!((mean_frames_covering(0.0, 2.0, 1.0) - 1.5).abs() < 1e-15);
        // Against a fine Riemann sum.
        let (lo, hi, delta) = (0.3, 7.9, 1.7);
        let n = 1_000_000;
        let riemann: f64 = (0..n)
            .map(|i| {
                let x = lo + (hi - lo) * (i as f64 + 0.5) / n as f64;
                (x / delta).ceil().max(1.0)
            })
            .sum::<f64>()
            / n as f64;
        assert!((mean_frames_covering(lo, hi, delta) - riemann).abs() < 1e-5);
    }

    #[test]
    fn clm_presets_at_1_khz() {
        // docs/spec.md §4: CLM-1 and CLM-2 give about 15% and 33% by E[L]/(E[L] + C).
        // On a 1 ms grid with L ~ U(0, N ms), a window drops (N + 1)/2 frames
        // on average and, with the cooldown, spans C/Δ + (N + 1)/2 frames.
        for (p, approx, exact) in [
            (time(1.0, 0.0, 3000.0, 8500.0), 1500.0 / 10000.0, 1500.5 / 10000.5),
            (time(1.0, 0.0, 1000.0, 1000.0), 500.0 / 1500.0, 500.5 / 1500.5),
            (time(1.0, 0.0, 2000.0, 1000.0), 1000.0 / 2000.0, 1000.5 / 2000.5),
        ] {
            let loss = Outage::new(&p).unwrap().loss_rate_approx(1_000_000).unwrap();
            assert!((loss - exact).abs() < 1e-12, "{loss} vs {exact}");
            assert!((loss - approx).abs() < 3e-4, "{loss} vs {approx}");
        }
        assert_eq!(Outage::new(&time(1.0, 0.0, 3000.0, 8500.0)).unwrap().loss_rate_approx(0), None);
    }

    #[test]
    fn value_stability() {
        let mut m = Outage::new(&time(0.2, 1.0, 4.0, 2.0)).unwrap();
        let mut rng = StageRng::seed_from_u64(42);
        assert_eq!(fates(&mut m, &mut rng, 0, 64), PINNED_TIME);
        assert_eq!(m.windows(), PINNED_TIME_WINDOWS);
        let mut m = Outage::new(&frames(0.2, 1, 4, 2)).unwrap();
        let mut rng = StageRng::seed_from_u64(42);
        assert_eq!(fates(&mut m, &mut rng, 0, 64), PINNED_FRAMES);
    }
    const PINNED_TIME: &str = "......xxx.......xxx....xxx...xxxx.....xxx.....xxx...........xxx.";
    const PINNED_TIME_WINDOWS: OutageWindows = OutageWindows { count: 7, total_ns: 18_934_241, total_frames: 0 };
    const PINNED_FRAMES: &str = "......xxx.......xx....xxx...xxxx.....xx.....xxx...........xx...x";
}
