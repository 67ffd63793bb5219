//! The delay check: quantiles of the delays the robot saw against the
//! delays the emulator drew and, for a scenario (or a phase) of one delay
//! stage, the model's analytic law with a 95% band.

use super::{DelayCheck, DelayQuantile};
use crate::model::{delay::Delay, jitter::Jitter, AnyModel};
use crate::scenario::{Phase, Scenario, ScenarioSpec};

/// The quantiles the check reports.
const QUANTILES: [f64; 7] = [0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99];

/// Fewer frames than this make no check.
const FRAMES_MIN: usize = 100;

/// Per delivered and received frame: when it entered the emulator
/// (CLOCK_MONOTONIC ns), the injected delay and the delay the robot saw
/// (receive − console send), in ns.
#[derive(Debug, Default)]
pub struct Delays {
    pub ingress_ns: Vec<u64>,
    pub injected: Vec<u64>,
    pub seen: Vec<u64>,
}

/// The analytic law of a delay: a `delay` or a `jitter` stage.
#[derive(Debug, Clone)]
pub enum Law {
    Delay(Delay),
    Jitter(Jitter),
}

impl Law {
    /// The law of `phase`'s delay: its one delay or jitter stage (behind
    /// loss stages, say); `None` with none or several.
    pub fn of_phase(phase: &Phase) -> Option<Law> {
        let laws: Vec<Law> = phase
            .stages()
            .iter()
            .filter_map(|s| match s.model() {
                AnyModel::Delay(d) => Some(Law::Delay(d.clone())),
                AnyModel::Jitter(j) => Some(Law::Jitter(j.clone())),
                _ => None,
            })
            .collect();
        <[Law; 1]>::try_from(laws).ok().map(|[one]| one)
    }

    /// The law of `scenario`'s delay, when it has one phase (see
    /// [`Law::of_phase`]).
    pub fn of_scenario(scenario: &Scenario) -> Option<Law> {
        match scenario.phases() {
            [phase] => Law::of_phase(phase),
            _ => None,
        }
    }

    /// `P(D ≤ x_ms)`.
    pub fn cdf_ms(&self, x_ms: f64) -> f64 {
        match self {
            Law::Delay(d) => d.cdf_ms(x_ms),
            Law::Jitter(j) => j.cdf_ms(x_ms),
        }
    }

    /// The `q`-quantile in ms.
    pub fn quantile_ms(&self, q: f64) -> f64 {
        match self {
            Law::Delay(d) => d.quantile_ms(q),
            Law::Jitter(j) => j.quantile_ms(q),
        }
    }

    /// Whether frames keep their order (`fifo`): a frame then waits for
    /// the one before it, and the delays drawn lie at or above the law.
    pub fn in_order(&self) -> bool {
        match self {
            Law::Delay(d) => !d.may_reorder(),
            Law::Jitter(j) => !j.may_reorder(),
        }
    }
}

/// The delay law of `spec` run with `seed`: its one delay stage, when it
/// has one phase and one delay stage (behind loss stages, say).
fn law(spec: &ScenarioSpec, seed: u64) -> Option<Law> {
    Law::of_scenario(&Scenario::new(spec, seed).ok()?)
}

/// Quantiles of the delays the robot saw against the delays the emulator
/// drew and, when the scenario is known and is a single delay stage
/// (possibly behind loss stages), against the model's analytic law.
/// `None` under 100 frames, or when nothing was delayed.
pub fn delay_check(spec: Option<&ScenarioSpec>, seed: u64, d: Delays) -> Option<DelayCheck> {
    let model = spec.and_then(|s| law(s, seed));
    delay_check_against(model.as_ref(), d, false)
}

/// [`delay_check`] against the law `model`, when known; `None` under 100
/// frames, or when nothing was delayed, unless `always` (a stretch of a
/// run under a delay law, shown whatever its length).
pub fn delay_check_against(model: Option<&Law>, mut d: Delays, always: bool) -> Option<DelayCheck> {
    let n = d.seen.len();
    if n == 0 || (!always && (n < FRAMES_MIN || d.injected.iter().all(|x| *x == 0))) {
        return None;
    }
    d.injected.sort_unstable();
    d.seen.sort_unstable();
    // Dvoretzky–Kiefer–Wolfowitz: with 95% confidence the empirical
    // distribution is within ε of the true one everywhere.
    let eps = ((2.0f64 / 0.05).ln() / (2.0 * n as f64)).sqrt();
    let pick = |v: &[u64], q: f64| v[((q * n as f64) as usize).min(n - 1)] as f64 / 1e6;
    let quantiles: Vec<DelayQuantile> = QUANTILES
        .into_iter()
        .map(|q| {
            let (injected_ms, seen_ms) = (pick(&d.injected, q), pick(&d.seen, q));
            let model_ms = model.map(|m| m.quantile_ms(q));
            let model_band_ms = model.map(|m| [m.quantile_ms((q - eps).max(1e-9)), m.quantile_ms((q + eps).min(1.0 - 1e-9))]);
            DelayQuantile { q, model_ms, model_band_ms, injected_ms, seen_ms, seen_minus_injected_us: (seen_ms - injected_ms) * 1e3 }
        })
        .collect();
    let worst = quantiles.iter().map(|x| x.seen_minus_injected_us.abs()).fold(0.0, f64::max);
    let injected_within_model_band = model.map(|_| {
        quantiles.iter().all(|x| x.model_band_ms.is_some_and(|[lo, hi]| lo <= x.injected_ms && x.injected_ms <= hi))
    });
    Some(DelayCheck { frames: n as u64, dkw_epsilon: eps, quantiles, max_abs_seen_minus_injected_us: worst, injected_within_model_band })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` delays at the law's own quantiles (what a perfect sampler
    /// draws), each seen `extra_ns` later; `shift_ms` moves the draws off
    /// the law.
    fn delays(spec: &ScenarioSpec, n: usize, extra_ns: u64, shift_ms: f64) -> Delays {
        let m = law(spec, 1).expect("one delay stage");
        let injected: Vec<u64> = (0..n).map(|i| ((m.quantile_ms((i as f64 + 0.5) / n as f64) + shift_ms) * 1e6) as u64).collect();
        let seen = injected.iter().map(|d| d + extra_ns).collect();
        Delays { ingress_ns: Vec::new(), injected, seen }
    }

    #[test]
    fn draws_on_the_law_lie_in_its_band_and_the_transport_is_what_is_left() {
        let spec = crate::scenario::preset("DLM-2").unwrap();
        let dc = delay_check(Some(&spec), 1, delays(&spec, 2000, 4_000, 0.0)).unwrap();
        assert_eq!(dc.frames, 2000);
        assert_eq!(dc.quantiles.len(), QUANTILES.len());
        assert_eq!(dc.injected_within_model_band, Some(true), "{dc:?}");
        // 4 µs each, to the rounding of ns to ms and back.
        assert!((dc.max_abs_seen_minus_injected_us - 4.0).abs() < 0.01, "{dc:?}");
        for q in &dc.quantiles {
            let [lo, hi] = q.model_band_ms.unwrap();
            assert!(lo <= q.model_ms.unwrap() && q.model_ms.unwrap() <= hi, "{q:?}");
        }
        // Draws 50 ms off the law leave its band.
        let off = delay_check(Some(&spec), 1, delays(&spec, 2000, 0, 50.0)).unwrap();
        assert_eq!(off.injected_within_model_band, Some(false), "{off:?}");
    }

    #[test]
    fn no_check_without_enough_delayed_frames_and_no_law_without_the_scenario() {
        let spec = crate::scenario::preset("DLM-2").unwrap();
        assert!(delay_check(Some(&spec), 1, delays(&spec, 99, 0, 0.0)).is_none(), "99 frames make no check");
        let zero = Delays { ingress_ns: vec![], injected: vec![0; 500], seen: vec![1_000; 500] };
        assert!(delay_check(Some(&spec), 1, zero).is_none(), "nothing delayed");
        let unknown = delay_check(None, 1, delays(&spec, 500, 0, 0.0)).unwrap();
        assert_eq!(unknown.injected_within_model_band, None);
        assert!(unknown.quantiles.iter().all(|q| q.model_ms.is_none() && q.model_band_ms.is_none()));
        // Loss then a delay: the delay's law.
        let lossy = crate::scenario::parse_str("[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n", "t", "t").unwrap();
        assert!(law(&lossy, 1).is_some());
        // Two phases, each delayed: no one law to compare with.
        let two = "[[phase]]\nstart_s = 0\npreset = \"DLM-1\"\n[[phase]]\nstart_s = 1\npreset = \"DLM-2\"\n";
        assert!(law(&crate::scenario::parse_str(two, "t", "t").unwrap(), 1).is_none());
    }
}
