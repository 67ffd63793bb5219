//! The parametric families the search moves in: which model parameters are
//! free, which are fixed by a documented rule, how a point of the search box
//! becomes model parameters, and how a candidate's metrics are computed —
//! by closed form where one is exact, or by a Monte Carlo estimate with
//! common random numbers.
//!
//! Rules (see `docs/faultdb.md` for the reasoning):
//!
//! - `ge_lomax`: two states with the study's transition matrix
//!   `[[0.95, 0.05], [0.10, 0.90]]` (state 0 Good, state 1 Bad). The Bad
//!   state's Lomax scale is [`BAD_SCALE_RATIO`] times the Good state's, and
//!   both states share one shape `α`. With one target (loss) `α` is fixed at
//!   [`ALPHA_DEFAULT`] and the scale is free; with a second target (mean
//!   loss-run length) `α` is free too, within `[1.5, 101]`. Four free parameters for one or two
//!   numbers would leave a ridge of equally good answers; tying them makes
//!   every target a single, reproducible point and keeps the two states
//!   meaningfully different.
//! - `delay`: `min_ms` is [`DELAY_MIN_FRACTION`] of the target mean (unless
//!   given); the random part is a two-component hyperexponential with the
//!   weights of DLM-2. With one target its rate ratio is DLM-2's too and one
//!   rate scale is free; with a second target (p99 or standard deviation)
//!   both rates are free, the rarer component being the slower one.
//! - `outage`: `unit = "time"`, `p_start = 1`, frames at a fixed rate (1 kHz
//!   unless said otherwise). Windows `U(0, 2000)` ms (CLM-3's, a mean of
//!   1 s) and a free cooldown; with a second target (mean outage length) the
//!   longest window is free too (windows stay `U(0, max)`).
//!
//! "Like a preset" families keep everything of a study preset except one
//! scale: PLM's two `λ` (ratio kept), DLM's two rates (ratio kept), CLM's
//! cooldown.

use super::{FitError, Goal, Kind, Metric};
use crate::model::{
    DelayDist, DelayParams, GeLomax, GeLomaxParams, Millis, OutageParams, OutageUnit, StageRng,
};
use crate::model::ModelSpec;
use rand::{RngExt, SeedableRng};

/// The study's two-state transition matrix (PLM-1..3).
pub use crate::model::presets::STUDY_TRANSITION;
/// The shared Lomax shape of one-target loss fits: the mean of the six
/// shapes of PLM-1..3 (4.259), rounded.
pub const ALPHA_DEFAULT: f64 = 4.26;
/// `λ_bad / λ_good` of fitted loss models.
pub const BAD_SCALE_RATIO: f64 = 4.0;
/// `min_ms / mean` of fitted delays, as in DLM-1 (70/100) and DLM-2 (210/300).
pub const DELAY_MIN_FRACTION: f64 = 0.7;
/// DLM-2's component weights.
pub const DELAY_WEIGHTS: [f64; 2] = [0.89258, 0.10742];
/// DLM-2's rate ratio `λ2/λ1`.
pub const DELAY_RATE_RATIO: f64 = 0.01624 / 0.01081;
/// The window law of fitted outages: `U(0, 2000)` ms.
pub const OUTAGE_WINDOW_MS: (f64, f64) = (0.0, 2000.0);
/// Significant digits parameters are rounded to before they are confirmed
/// and stored: the stored numbers are exactly the ones simulated.
pub const SIGNIFICANT_DIGITS: usize = 7;

/// How a candidate's metrics are computed during the search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Objective {
    /// Closed forms, which are exact for every metric of these families
    /// (Monte Carlo only where a closed form is degenerate).
    #[default]
    Exact,
    /// The study's method: a Monte Carlo estimate per candidate, with common
    /// random numbers (the same draws for every candidate).
    MonteCarlo,
}

impl Objective {
    pub fn name(self) -> &'static str {
        match self {
            Objective::Exact => "exact",
            Objective::MonteCarlo => "monte_carlo",
        }
    }
}

/// Monte Carlo sample sizes of the search's estimator (per candidate): burst
/// cycles for `ge_lomax`, delays for `delay`, windows for `outage`.
pub const MC_SAMPLES_GE_LOMAX: usize = 1 << 18;
pub const MC_SAMPLES_DELAY: usize = 1 << 16;
pub const MC_SAMPLES_OUTAGE: usize = 1 << 16;

#[derive(Debug, Clone, PartialEq)]
pub struct GeLomaxShape {
    pub transition: [[f64; 2]; 2],
    /// Shapes at `a = alpha[0]`; a free shape scales both by `a / alpha[0]`.
    pub alpha: [f64; 2],
    /// `λ_s = scale · lambda_ratio[s]`.
    pub lambda_ratio: [f64; 2],
    pub free_alpha: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct DelayShape {
    pub min_ms: f64,
    pub weights: [f64; 2],
    /// `λ2/λ1` when the ratio is fixed.
    pub rate_ratio: f64,
    pub free_ratio: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct OutageShape {
    pub min_ms: f64,
    pub max_ms: f64,
    pub free_max: bool,
    pub frame_interval_ns: u64,
}

/// A family of parameters with a search box.
#[derive(Debug, Clone, PartialEq)]
pub enum Family {
    GeLomax(GeLomaxShape),
    Delay(DelayShape),
    Outage(OutageShape),
}

/// Search box of log-scales and log-shapes.
const LN_LOMAX_SCALE: (f64, f64) = (-6.907_755_278_982_137, 9.210_340_371_976_184); // 1e-3 .. 1e4 frames
                                                                                    // α − 1 in 0.5 .. 100: below α = 1.5 bursts are so heavy-tailed (a mean that
                                                                                    // is barely finite) that no simulation of practical length realizes the
                                                                                    // long-run loss, so such a fit could never be confirmed.
const LN_ALPHA_MINUS_1: (f64, f64) = (-std::f64::consts::LN_2, 4.605_170_185_988_092);
const LN_RATE_PER_MS: (f64, f64) = (-13.815_510_557_964_274, 6.907_755_278_982_137); // 1e-6 .. 1e3 per ms
const LN_RATE_SPREAD: (f64, f64) = (0.0, 9.210_340_371_976_184); // λ1/λ2 in 1 .. 1e4
const LN_COOLDOWN_MS: (f64, f64) = (-6.907_755_278_982_137, 18.420_680_743_952_367); // 1e-3 .. 1e8 ms
const LN_WINDOW_MAX_MS: (f64, f64) = (0.0, 13.815_510_557_964_274); // 1 .. 1e6 ms

impl Family {
    /// The family a fit of `kind` to `goals` searches in. `like` names a
    /// study preset whose shape to keep; `delay_min_ms` overrides the
    /// minimum-delay rule.
    pub fn new(
        kind: Kind,
        goals: &[Goal],
        like: Option<&str>,
        delay_min_ms: Option<f64>,
        frame_interval_ns: u64,
    ) -> Result<Family, FitError> {
        let second = goals.get(1).map(|g| g.metric);
        let like_spec = match like {
            None => None,
            Some(name) => {
                let canonical = crate::model::presets::canonical_name(name)
                    .ok_or_else(|| FitError::BadRequest { problem: format!("`{name}` is not a study preset") })?;
                let models = crate::model::presets::preset_models(canonical).expect("canonical names are presets");
                let model = models.into_iter().next();
                Some((canonical, model))
            }
        };
        match kind {
            Kind::Jitter => Err(FitError::BadRequest {
                problem: "a jitter fit is solved in closed form, without a family to search (fit::jitter_searched)".into(),
            }),
            Kind::Loss => {
                let mut shape = GeLomaxShape {
                    transition: STUDY_TRANSITION,
                    alpha: [ALPHA_DEFAULT; 2],
                    lambda_ratio: [1.0, BAD_SCALE_RATIO],
                    free_alpha: second == Some(Metric::LossRunMean),
                };
                if let Some((name, model)) = like_spec {
                    match model {
                        Some(ModelSpec::GeLomax(p)) if p.transition.len() == 2 => {
                            shape.transition =
                                [[p.transition[0][0], p.transition[0][1]], [p.transition[1][0], p.transition[1][1]]];
                            shape.alpha = [p.alpha[0], p.alpha[1]];
                            shape.lambda_ratio = [1.0, p.lambda[1] / p.lambda[0]];
                        }
                        _ => return Err(not_like(name, "a loss fit", "PLM-1..3")),
                    }
                }
                Ok(Family::GeLomax(shape))
            }
            Kind::Delay => {
                let target = goals[0].value;
                let mut shape = DelayShape {
                    min_ms: DELAY_MIN_FRACTION * target,
                    weights: DELAY_WEIGHTS,
                    rate_ratio: DELAY_RATE_RATIO,
                    free_ratio: second.is_some(),
                };
                if let Some((name, model)) = like_spec {
                    match model {
                        Some(ModelSpec::Delay(p))
                            if p.dist == DelayDist::Hyperexp && p.weights.as_ref().is_some_and(|w| w.len() == 2) =>
                        {
                            let w = p.weights.as_ref().expect("checked");
                            let r = p.rates_per_ms.as_ref().expect("validated presets have rates");
                            shape.min_ms = p.min_ms.get();
                            shape.weights = [w[0], w[1]];
                            shape.rate_ratio = r[1] / r[0];
                        }
                        _ => return Err(not_like(name, "a delay fit", "DLM-1..3")),
                    }
                }
                if let Some(m) = delay_min_ms {
                    shape.min_ms = m;
                }
                shape.min_ms = round_sig(shape.min_ms);
                if !(shape.min_ms.is_finite() && shape.min_ms >= 0.0 && shape.min_ms < target) {
                    return Err(FitError::BadRequest {
                        problem: format!(
                            "the minimum delay {} ms leaves nothing random for a mean of {target} ms: expected 0 ≤ min_ms < the mean",
                            shape.min_ms
                        ),
                    });
                }
                Ok(Family::Delay(shape))
            }
            Kind::Outage => {
                let mut shape = OutageShape {
                    min_ms: OUTAGE_WINDOW_MS.0,
                    max_ms: OUTAGE_WINDOW_MS.1,
                    free_max: second == Some(Metric::OutageMsMean),
                    frame_interval_ns,
                };
                if let Some((name, model)) = like_spec {
                    match model {
                        Some(ModelSpec::Outage(p)) if p.unit == OutageUnit::Time && p.p_start.get() == 1.0 => {
                            shape.min_ms = p.min_ms.map_or(0.0, Millis::get);
                            shape.max_ms = p.max_ms.expect("validated presets have max_ms").get();
                        }
                        _ => return Err(not_like(name, "an outage fit", "CLM-1..3")),
                    }
                }
                Ok(Family::Outage(shape))
            }
        }
    }

    pub fn kind(&self) -> Kind {
        match self {
            Family::GeLomax(_) => Kind::Loss,
            Family::Delay(_) => Kind::Delay,
            Family::Outage(_) => Kind::Outage,
        }
    }

    /// The search box.
    pub fn bounds(&self) -> Vec<(f64, f64)> {
        match self {
            Family::GeLomax(s) => {
                if s.free_alpha {
                    vec![LN_LOMAX_SCALE, LN_ALPHA_MINUS_1]
                } else {
                    vec![LN_LOMAX_SCALE]
                }
            }
            Family::Delay(s) => {
                if s.free_ratio {
                    vec![LN_RATE_PER_MS, LN_RATE_SPREAD]
                } else {
                    vec![LN_RATE_PER_MS]
                }
            }
            Family::Outage(s) => {
                if s.free_max {
                    vec![LN_COOLDOWN_MS, LN_WINDOW_MAX_MS]
                } else {
                    vec![LN_COOLDOWN_MS]
                }
            }
        }
    }

    /// One line saying what is fixed and what is free.
    pub fn describe(&self) -> String {
        match self {
            Family::GeLomax(s) => format!(
                "ge_lomax, P = {:?}; λ = s·{:?} with s free; α = {} ",
                s.transition,
                s.lambda_ratio,
                if s.free_alpha {
                    format!("a·{:?}/{} with a free", s.alpha, s.alpha[0])
                } else {
                    format!("{:?} fixed", s.alpha)
                }
            )
            .trim_end()
            .to_string(),
            Family::Delay(s) => format!(
                "delay, reorder; min_ms = {} fixed; hyperexp weights {:?}; {}",
                s.min_ms,
                s.weights,
                if s.free_ratio {
                    "rates λ1 ≥ λ2 both free".to_string()
                } else {
                    format!("rates λ1 free, λ2 = {:.6}·λ1", s.rate_ratio)
                }
            ),
            Family::Outage(s) => format!(
                "outage, unit time, p_start 1, {} Hz; window U({}, {}) ms; cooldown free",
                1e9 / s.frame_interval_ns as f64,
                s.min_ms,
                if s.free_max { "max free".to_string() } else { format!("{}", s.max_ms) }
            ),
        }
    }

    /// The model parameters at point `x` of the box, rounded to
    /// [`SIGNIFICANT_DIGITS`] when `round` is set.
    pub fn spec(&self, x: &[f64], round: bool) -> ModelSpec {
        let r = |v: f64| if round { round_sig(v) } else { v };
        match self {
            Family::GeLomax(s) => {
                let scale = x[0].exp();
                let alpha = if s.free_alpha {
                    let a = 1.0 + x[1].exp();
                    [r(a), r(a * s.alpha[1] / s.alpha[0])]
                } else {
                    s.alpha
                };
                ModelSpec::GeLomax(GeLomaxParams::two_state(
                    s.transition,
                    alpha,
                    [r(scale * s.lambda_ratio[0]), r(scale * s.lambda_ratio[1])],
                ))
            }
            Family::Delay(s) => {
                let rate1 = x[0].exp();
                let rate2 = if s.free_ratio { rate1 * (-x[1]).exp() } else { rate1 * s.rate_ratio };
                ModelSpec::Delay(
                    DelayParams::hyperexp(s.min_ms, &s.weights, &[r(rate1), r(rate2)])
                        .expect("min_ms validated in Family::new"),
                )
            }
            Family::Outage(s) => {
                let cooldown = r(x[0].exp());
                let max_ms = if s.free_max { r(x[1].exp()).max(s.min_ms) } else { s.max_ms };
                ModelSpec::Outage(
                    OutageParams::time(1.0, s.min_ms, max_ms, cooldown).expect("finite and ≥ 0 by construction"),
                )
            }
        }
    }

    /// The search objective at `x`: `Σ ((M_k − T_k)/T_k)²` over the goals.
    /// With one goal this has the minimizer of the study's `(M − T)²`; the
    /// relative form lets two goals of different units share one objective.
    pub fn objective(&self, x: &[f64], goals: &[Goal], objective: Objective, crn_seed: u64) -> f64 {
        let spec = self.spec(x, false);
        let metrics: Vec<Metric> = goals.iter().map(|g| g.metric).collect();
        let values = match objective {
            Objective::Exact => metrics_exact(&spec, &metrics, self.frame_interval_ns()),
            Objective::MonteCarlo => metrics_monte_carlo(&spec, &metrics, crn_seed, self.frame_interval_ns()),
        };
        match values {
            Some(v) => goals.iter().zip(v).map(|(g, m)| ((m - g.value) / g.value).powi(2)).sum(),
            None => f64::INFINITY,
        }
    }

    pub fn frame_interval_ns(&self) -> u64 {
        match self {
            Family::Outage(s) => s.frame_interval_ns,
            _ => 1_000_000,
        }
    }
}

fn not_like(name: &str, what: &str, expected: &str) -> FitError {
    FitError::BadRequest {
        problem: format!("preset `{name}` has no shape {what} can keep: expected one of {expected}"),
    }
}

/// `v` rounded to [`SIGNIFICANT_DIGITS`] significant digits.
pub fn round_sig(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    format!("{:.*e}", SIGNIFICANT_DIGITS - 1, v).parse().expect("a formatted float parses")
}

/// The metrics of `spec` by closed form; `None` if the parameters are
/// invalid. A metric with no usable closed form here falls back to the Monte
/// Carlo estimator (only the mean loss run of a two-state chain whose states
/// have equal mean bursts).
pub fn metrics_exact(spec: &ModelSpec, metrics: &[Metric], frame_interval_ns: u64) -> Option<Vec<f64>> {
    let model = spec.build().ok()?;
    let mut out = Vec::with_capacity(metrics.len());
    for &m in metrics {
        let v = match (spec, m) {
            (ModelSpec::GeLomax(p), Metric::LossRate) => {
                let _ = p;
                model.loss_rate_exact(frame_interval_ns)?
            }
            (ModelSpec::GeLomax(p), Metric::LossRunMean) => match mean_loss_run_exact(p) {
                Some(v) => v,
                None => metrics_monte_carlo(spec, &[m], 0x5eed, frame_interval_ns)?[0],
            },
            (ModelSpec::Delay(_), Metric::DelayMsMean) => model.mean_delay_ms_exact(),
            (ModelSpec::Delay(p), Metric::DelayMsStd) => hyperexp(p)?.std_ms(),
            (ModelSpec::Delay(p), Metric::DelayMsP99) => p.min_ms.get() + hyperexp(p)?.quantile_ms(0.99),
            (ModelSpec::Outage(_), Metric::LossRate) => model.loss_rate_exact(frame_interval_ns)?,
            (ModelSpec::Outage(p), Metric::OutageMsMean) => {
                (p.min_ms.map_or(0.0, Millis::get) + p.max_ms.map_or(0.0, Millis::get)) / 2.0
            }
            _ => return None,
        };
        out.push(v);
    }
    Some(out)
}

/// Exact mean loss-run length of a two-state `ge_lomax`.
///
/// Runs of drops are exactly the bursts with `b ≥ 1` (each burst ends with a
/// delivery), so the mean run is `Σ π_s E_s[b] / Σ π_s P_s(b ≥ 1)`, with `π`
/// the long-run distribution of the state at burst draws. The exact loss is
/// `A/(A + 1)` with `A = Σ π_s E_s[b]`, so `A = L/(1 − L)` and, with two
/// states, `π_0 = (A − E_1)/(E_0 − E_1)`. `None` when the two mean bursts are
/// too close for that to be well conditioned, or a mean burst is infinite.
pub fn mean_loss_run_exact(p: &GeLomaxParams) -> Option<f64> {
    if p.transition.len() != 2 {
        return None;
    }
    let m = GeLomax::new(p).ok()?;
    let (e0, e1) = (m.mean_burst(0), m.mean_burst(1));
    if !(e0.is_finite() && e1.is_finite()) || (e0 - e1).abs() < 1e-6 * (e0 + e1).max(1e-300) {
        return None;
    }
    let loss = m.loss_rate_exact();
    if loss <= 0.0 {
        return Some(1.0);
    }
    let a = loss / (1.0 - loss);
    let pi0 = ((a - e1) / (e0 - e1)).clamp(0.0, 1.0);
    let runs = pi0 * m.burst_survival(0, 1) + (1.0 - pi0) * m.burst_survival(1, 1);
    (runs > 0.0).then(|| a / runs)
}

/// A two-component hyperexponential's moments and quantiles.
pub struct Hyperexp {
    pub weights: Vec<f64>,
    pub rates: Vec<f64>,
}

pub fn hyperexp(p: &DelayParams) -> Option<Hyperexp> {
    Some(Hyperexp { weights: p.weights.clone()?, rates: p.rates_per_ms.clone()? })
}

impl Hyperexp {
    pub fn mean_ms(&self) -> f64 {
        self.weights.iter().zip(&self.rates).map(|(w, l)| w / l).sum()
    }

    /// `sqrt(E[X²] − E[X]²)` with `E[X²] = Σ 2 w_i / λ_i²`.
    pub fn std_ms(&self) -> f64 {
        let m = self.mean_ms();
        let m2: f64 = self.weights.iter().zip(&self.rates).map(|(w, l)| 2.0 * w / (l * l)).sum();
        (m2 - m * m).max(0.0).sqrt()
    }

    /// `P(X > x) = Σ w_i e^(−λ_i x)`.
    pub fn survival(&self, x: f64) -> f64 {
        self.weights.iter().zip(&self.rates).map(|(w, l)| w * (-l * x).exp()).sum()
    }

    /// The `q`-quantile, by bisection on the survival function (monotone), to
    /// the resolution of an f64.
    pub fn quantile_ms(&self, q: f64) -> f64 {
        let tail = 1.0 - q;
        let slowest = self.rates.iter().copied().fold(f64::INFINITY, f64::min);
        // `P(X > x) ≤ e^(−λ_min x)`, so the quantile is below `−ln(tail)/λ_min`.
        let (mut lo, mut hi) = (0.0, -tail.ln() / slowest);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if self.survival(mid) > tail {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// Monte Carlo estimates of `metrics` for `spec` with common random numbers:
/// the draws come from `seed` alone and are used the same way for every
/// parameter value (one uniform per purpose, each turned into its value by an
/// inverse CDF that is continuous in the parameters), so two nearby
/// candidates see nearby estimates and the search does not chase noise.
///
/// - `ge_lomax` (two states): burst cycles. Cycle `k` is drawn in state
///   `s_k`: `b_k` from one uniform by the floored-Lomax inverse CDF; the
///   next draw happens `b_k + 1` moves later, so `s_(k+1)` is drawn from row
///   `s_k` of `P^(b_k + 1)` with a second uniform (closed form for two
///   states). The first draw's state is drawn from row 0 of `P`. Exactly the
///   law of docs/spec.md §3.2, sampled per burst rather than per frame.
/// - `delay`: one uniform picks the component, one gives `−ln(1 − V)/λ_i`.
/// - `outage` (`p_start = 1`, time units): window cycles at the fixed frame
///   interval, as in [`super::confirm`].
pub fn metrics_monte_carlo(
    spec: &ModelSpec,
    metrics: &[Metric],
    seed: u64,
    frame_interval_ns: u64,
) -> Option<Vec<f64>> {
    spec.build().ok()?;
    let mut rng = StageRng::seed_from_u64(seed);
    match spec {
        ModelSpec::GeLomax(p) if p.transition.len() == 2 => {
            let (drops, frames, runs) = ge_lomax_cycles(p, MC_SAMPLES_GE_LOMAX, &mut rng);
            metrics
                .iter()
                .map(|m| match m {
                    Metric::LossRate => Some(drops / frames),
                    Metric::LossRunMean => Some(if runs > 0.0 { drops / runs } else { 1.0 }),
                    _ => None,
                })
                .collect()
        }
        ModelSpec::Delay(p) if p.dist == DelayDist::Hyperexp => {
            let h = hyperexp(p)?;
            let min = p.min_ms.get();
            let mut xs: Vec<f64> = (0..MC_SAMPLES_DELAY)
                .map(|_| {
                    let u: f64 = rng.random();
                    let v: f64 = rng.random();
                    let mut i = 0;
                    let mut acc = h.weights[0];
                    while u >= acc && i + 1 < h.weights.len() {
                        i += 1;
                        acc += h.weights[i];
                    }
                    min - (-v).ln_1p() / h.rates[i]
                })
                .collect();
            let n = xs.len() as f64;
            let mean = xs.iter().sum::<f64>() / n;
            let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
            metrics
                .iter()
                .map(|m| match m {
                    Metric::DelayMsMean => Some(mean),
                    Metric::DelayMsStd => Some(var.sqrt()),
                    Metric::DelayMsP99 => {
                        let k = ((0.99 * n).ceil() as usize).min(xs.len()) - 1;
                        let (_, v, _) = xs.select_nth_unstable_by(k, f64::total_cmp);
                        Some(*v)
                    }
                    _ => None,
                })
                .collect()
        }
        ModelSpec::Outage(p) if p.unit == OutageUnit::Time && p.p_start.get() == 1.0 => {
            let cycles = super::confirm::OutageCycles::new(p, frame_interval_ns)?;
            let (mut dropped, mut frames, mut length_ns) = (0u64, 0u64, 0f64);
            for _ in 0..MC_SAMPLES_OUTAGE {
                let c = cycles.next(&mut rng);
                dropped += c.dropped;
                frames += c.frames;
                length_ns += c.length_ns as f64;
            }
            metrics
                .iter()
                .map(|m| match m {
                    Metric::LossRate => Some(dropped as f64 / frames as f64),
                    Metric::OutageMsMean => Some(length_ns / MC_SAMPLES_OUTAGE as f64 / 1e6),
                    _ => None,
                })
                .collect()
        }
        _ => None,
    }
}

/// `n` burst cycles of a two-state `ge_lomax`: (drops, frames, runs).
fn ge_lomax_cycles(p: &GeLomaxParams, n: usize, rng: &mut StageRng) -> (f64, f64, f64) {
    let (p01, p10) = (p.transition[0][1], p.transition[1][0]);
    let total = p01 + p10;
    let mu = 1.0 - total;
    // `P^m[s][other]` for the two states.
    let leave = |s: usize, m: f64| -> f64 {
        if total == 0.0 {
            return 0.0;
        }
        let limit = if s == 0 { p01 / total } else { p10 / total };
        limit * (1.0 - mu.powf(m))
    };
    let neg_inv_alpha = [-1.0 / p.alpha[0], -1.0 / p.alpha[1]];
    let mut s = usize::from(rng.random::<f64>() < p01);
    let (mut drops, mut frames, mut runs) = (0.0, 0.0, 0.0);
    for _ in 0..n {
        let u: f64 = rng.random();
        let v: f64 = rng.random();
        // `1 − U` in (0, 1]: the power is finite and ≥ 1.
        let b = (p.lambda[s] * ((1.0 - u).powf(neg_inv_alpha[s]) - 1.0)).floor().min(1e15);
        drops += b;
        frames += b + 1.0;
        if b >= 1.0 {
            runs += 1.0;
        }
        if v < leave(s, b + 1.0) {
            s = 1 - s;
        }
    }
    (drops, frames, runs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn goal(metric: Metric, value: f64) -> Goal {
        Goal { metric, value }
    }

    #[test]
    fn rounding_keeps_seven_digits() {
        assert_eq!(round_sig(0.123456789), 0.1234568);
        assert_eq!(round_sig(174.99999999999997), 175.0);
        assert_eq!(round_sig(0.0), 0.0);
    }

    #[test]
    fn hyperexp_quantile_and_moments() {
        let h = Hyperexp { weights: vec![1.0], rates: vec![0.5] };
        assert!((h.quantile_ms(0.99) - 100f64.ln() / 0.5).abs() < 1e-9);
        assert!((h.std_ms() - 2.0).abs() < 1e-12);
        let h = Hyperexp { weights: vec![0.3, 0.7], rates: vec![0.1, 2.0] };
        let q = h.quantile_ms(0.99);
        assert!((h.survival(q) - 0.01).abs() < 1e-12);
    }

    #[test]
    fn exact_mean_run_matches_the_monte_carlo_estimate() {
        let p = GeLomaxParams::two_state(STUDY_TRANSITION, [4.604, 3.901], [3.552, 1.466]);
        let exact = mean_loss_run_exact(&p).unwrap();
        let spec = ModelSpec::GeLomax(p.clone());
        let mc = metrics_monte_carlo(&spec, &[Metric::LossRate, Metric::LossRunMean], 9, 1_000_000).unwrap();
        let loss = GeLomax::new(&p).unwrap().loss_rate_exact();
        // 2^18 cycles: a relative standard error well under 1%.
        assert!((mc[0] - loss).abs() < 0.01 * loss, "{} vs {loss}", mc[0]);
        assert!((mc[1] - exact).abs() < 0.02 * exact, "{} vs {exact}", mc[1]);
    }

    #[test]
    fn families_map_the_box_to_valid_parameters() {
        for (kind, goals) in [
            (Kind::Loss, vec![goal(Metric::LossRate, 0.3)]),
            (Kind::Loss, vec![goal(Metric::LossRate, 0.3), goal(Metric::LossRunMean, 3.0)]),
            (Kind::Delay, vec![goal(Metric::DelayMsMean, 100.0)]),
            (Kind::Delay, vec![goal(Metric::DelayMsMean, 100.0), goal(Metric::DelayMsP99, 500.0)]),
            (Kind::Outage, vec![goal(Metric::LossRate, 0.1)]),
            (Kind::Outage, vec![goal(Metric::LossRate, 0.1), goal(Metric::OutageMsMean, 500.0)]),
        ] {
            let f = Family::new(kind, &goals, None, None, 1_000_000).unwrap();
            let b = f.bounds();
            assert_eq!(b.len(), goals.len());
            for corner in [b.iter().map(|r| r.0).collect::<Vec<_>>(), b.iter().map(|r| r.1).collect()] {
                f.spec(&corner, true).build().unwrap();
                assert!(f.objective(&corner, &goals, Objective::Exact, 1).is_finite(), "{kind:?} at {corner:?}");
            }
        }
    }

    #[test]
    fn like_keeps_the_preset_shape() {
        let f = Family::new(Kind::Loss, &[goal(Metric::LossRate, 0.1)], Some("PLM-1"), None, 1_000_000).unwrap();
        let Family::GeLomax(s) = &f else { panic!() };
        assert_eq!(s.alpha, [4.428, 4.966]);
        assert!((s.lambda_ratio[1] - 0.271 / 1.638).abs() < 1e-15);
        let e =
            Family::new(Kind::Delay, &[goal(Metric::DelayMsMean, 100.0)], Some("PLM-1"), None, 1_000_000).unwrap_err();
        assert!(e.to_string().contains("DLM-1..3"), "{e}");
        let e =
            Family::new(Kind::Delay, &[goal(Metric::DelayMsMean, 300.0)], Some("DLM-3"), None, 1_000_000).unwrap_err();
        assert!(e.to_string().contains("min_ms"), "{e}");
    }
}
