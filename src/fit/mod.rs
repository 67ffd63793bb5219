//! Fitting model parameters to targets (docs/spec.md §5), and the fault parameter
//! database built from such fits.
//!
//! A fit takes a kind of fault (`loss` → `ge_lomax`, `delay`, `outage`), a
//! primary target (a loss rate, a mean delay, a lost fraction) and optionally
//! a second one (mean loss-run length; p99 or standard deviation of the
//! delay; mean outage length), and:
//!
//! 1. picks the parametric [`family::Family`] the rules in that module fix
//!    (which parameters are free, which are tied or set by a rule);
//! 2. searches the family's box by differential evolution ([`de`]),
//!    minimizing `Σ ((M_k − T_k)/T_k)²` where `M_k` is the candidate's metric
//!    by closed form where it is exact ([`family::Objective::Exact`], the
//!    default) or by a Monte Carlo estimate with common random numbers
//!    ([`family::Objective::MonteCarlo`], the study's method);
//! 3. rounds the parameters to 7 significant digits and confirms them by an
//!    independent simulation with the model's own code and a seed different
//!    from the search's ([`confirm`]), reporting each metric with its 95%
//!    interval.
//!
//! `jitter` (a mean and a p99 of the delay, with a law and a correlation)
//! needs no search: [`crate::model::jitter::fit_mean_p99`] solves it in
//! closed form (bisection on an exact mean), so step 2 is that solution
//! ([`jitter_searched`]); rounding and confirmation are as above.
//!
//! `fit` builds on [`crate::model`] alone (parameters, presets, stream
//! seeds); `scenario` reads the database ([`db`]) for its target stages, so
//! the dependency between the two goes one way.
//!
//! Contract: everything here except [`run`] is sans-IO and single-threaded —
//! no clock, file or thread — and a pure function of the request and its
//! seed. [`run`] is the thin layer that spreads independent work (a
//! generation's candidates, a confirmation's replicas, a database's entries)
//! over threads with `std::thread::scope`; results never depend on the
//! number of threads. The seed of a fit derives three streams: the search's,
//! the common random numbers of the Monte Carlo objective, and the
//! confirmation's.

pub mod confirm;
pub mod db;
pub mod de;
pub mod family;
pub mod run;

pub use confirm::{Confirmation, Estimate};
pub use family::{Family, Objective};

use crate::model::jitter::{JitterDist, JitterParams};
use crate::model::{DelayParams, GeLomaxParams, OutageParams};
use crate::model::{stream_seed, ModelSpec};
use serde::Serialize;
use std::collections::BTreeMap;

/// The database's acceptance tolerance: a realized value within 0.5%
/// (relative) of its target.
pub const TOLERANCE_REL: f64 = 0.005;

/// The frame rate fits assume unless told otherwise: the paper's 1 kHz
/// (docs/spec.md §1). It matters only to `outage`, whose windows are in time.
pub const DEFAULT_FRAME_RATE_HZ: f64 = 1000.0;

/// The tool version recorded with every fit.
pub const TOOL_VERSION: &str = env!("CARGO_PKG_VERSION");

/// What kind of fault a fit is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// Packet loss, fitted as `ge_lomax`.
    Loss,
    /// Delay, fitted as `delay` (minimum plus hyperexponential).
    Delay,
    /// Communication loss, fitted as `outage`.
    Outage,
    /// Jitter around a mean (docs/spec.md §3.7), fitted as `jitter` to a
    /// mean and a p99 of the delay, in closed form.
    Jitter,
}

impl Kind {
    pub const ALL: [Kind; 3] = [Kind::Loss, Kind::Delay, Kind::Outage];

    pub fn name(self) -> &'static str {
        match self {
            Kind::Loss => "loss",
            Kind::Delay => "delay",
            Kind::Outage => "outage",
            Kind::Jitter => "jitter",
        }
    }

    /// The model a fit of this kind produces.
    pub fn model_name(self) -> &'static str {
        match self {
            Kind::Loss => "ge_lomax",
            Kind::Delay => "delay",
            Kind::Outage => "outage",
            Kind::Jitter => "jitter",
        }
    }

    /// The primary metric: what the positional target of `netfi fit` means.
    pub fn primary(self) -> Metric {
        match self {
            Kind::Loss | Kind::Outage => Metric::LossRate,
            Kind::Delay | Kind::Jitter => Metric::DelayMsMean,
        }
    }
}

/// A quantity a fit can aim at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// Fraction of frames dropped.
    LossRate,
    /// Mean length of maximal runs of consecutive drops, in frames.
    LossRunMean,
    /// Mean injected delay, ms.
    DelayMsMean,
    /// 99th percentile of the injected delay, ms.
    DelayMsP99,
    /// Standard deviation of the injected delay, ms.
    DelayMsStd,
    /// Mean drawn outage window length, ms (as `scenario check` reports it).
    OutageMsMean,
}

impl Metric {
    pub fn name(self) -> &'static str {
        match self {
            Metric::LossRate => "loss_rate",
            Metric::LossRunMean => "loss_run_mean",
            Metric::DelayMsMean => "delay_ms_mean",
            Metric::DelayMsP99 => "delay_ms_p99",
            Metric::DelayMsStd => "delay_ms_std",
            Metric::OutageMsMean => "outage_ms_mean",
        }
    }

    /// Whether `kind` can aim at this metric, and whether as its first target.
    fn fits(self, kind: Kind, first: bool) -> bool {
        match (kind, first) {
            (k, true) => self == k.primary(),
            (Kind::Loss, false) => self == Metric::LossRunMean,
            (Kind::Delay, false) => matches!(self, Metric::DelayMsP99 | Metric::DelayMsStd),
            (Kind::Outage, false) => self == Metric::OutageMsMean,
            (Kind::Jitter, false) => self == Metric::DelayMsP99,
        }
    }
}

/// One target value of one metric.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct Goal {
    pub metric: Metric,
    pub value: f64,
}

/// Everything a fit depends on.
#[derive(Debug, Clone, PartialEq)]
pub struct FitRequest {
    pub kind: Kind,
    /// The primary target first, then at most one more.
    pub goals: Vec<Goal>,
    /// A study preset whose shape to keep (scaling one parameter only).
    pub like: Option<String>,
    /// Overrides the minimum-delay rule (delay fits).
    pub delay_min_ms: Option<f64>,
    pub objective: Objective,
    pub seed: u64,
    /// Frames per second of the simulated stream (only `outage` depends on it).
    pub frame_rate_hz: f64,
    /// The law of a jitter fit (default normal).
    pub jitter_dist: JitterDist,
    /// The lag-1 correlation of a jitter fit, in [0, 1) (default 0); it
    /// leaves the marginal law, so the mean and the p99, as they are.
    pub jitter_correlation: f64,
}

impl FitRequest {
    /// A one-target fit with the default rules.
    pub fn new(kind: Kind, target: f64, seed: u64) -> FitRequest {
        FitRequest {
            kind,
            goals: vec![Goal { metric: kind.primary(), value: target }],
            like: None,
            delay_min_ms: None,
            objective: Objective::Exact,
            seed,
            frame_rate_hz: DEFAULT_FRAME_RATE_HZ,
            jitter_dist: JitterDist::Normal,
            jitter_correlation: 0.0,
        }
    }

    /// Adds a second target.
    pub fn with_goal(mut self, metric: Metric, value: f64) -> FitRequest {
        self.goals.push(Goal { metric, value });
        self
    }

    /// The frame interval in ns.
    pub fn frame_interval_ns(&self) -> u64 {
        (1e9 / self.frame_rate_hz).round() as u64
    }

    /// Checks the targets and settings; the error says what is accepted.
    pub fn validate(&self) -> Result<(), FitError> {
        let bad = |problem: String| Err(FitError::BadRequest { problem });
        if self.goals.is_empty() || self.goals.len() > 2 {
            return bad(format!("{} targets: a fit takes a primary target and at most one more", self.goals.len()));
        }
        if !(self.frame_rate_hz.is_finite() && self.frame_rate_hz >= 1.0 && self.frame_rate_hz <= 1e9) {
            return bad(format!("frame rate {} Hz: expected 1 Hz to 1 GHz", self.frame_rate_hz));
        }
        for (i, g) in self.goals.iter().enumerate() {
            if !g.metric.fits(self.kind, i == 0) {
                let accepted = match (self.kind, i == 0) {
                    (k, true) => k.primary().name(),
                    (Kind::Loss, false) => "loss_run_mean",
                    (Kind::Delay, false) => "delay_ms_p99 or delay_ms_std",
                    (Kind::Outage, false) => "outage_ms_mean",
                    (Kind::Jitter, false) => "delay_ms_p99",
                };
                return bad(format!(
                    "a {} fit cannot aim at {} here: expected {accepted}",
                    self.kind.name(),
                    g.metric.name()
                ));
            }
            let v = g.value;
            let ok = v.is_finite()
                && match g.metric {
                    Metric::LossRate => v > 0.0 && v < 1.0,
                    Metric::LossRunMean => v > 1.0,
                    Metric::DelayMsMean | Metric::DelayMsStd | Metric::OutageMsMean => v > 0.0,
                    Metric::DelayMsP99 => v > self.goals[0].value,
                };
            if !ok {
                let accepted = match g.metric {
                    Metric::LossRate => "a fraction strictly between 0 and 1 (e.g. 0.3 or \"30%\")",
                    Metric::LossRunMean => "a mean run length above 1 frame",
                    Metric::DelayMsMean | Metric::DelayMsStd | Metric::OutageMsMean => "a positive number of ms",
                    Metric::DelayMsP99 => "a p99 above the mean delay",
                };
                return bad(format!("{} = {v}: expected {accepted}", g.metric.name()));
            }
        }
        if self.kind == Kind::Jitter && self.goals.len() != 2 {
            return bad("a jitter fit takes a mean and a p99 of the delay (--p99-ms)".into());
        }
        if self.kind == Kind::Jitter && self.like.is_some() {
            return bad("--like applies to loss, delay and outage fits, not jitter".into());
        }
        if !(0.0..1.0).contains(&self.jitter_correlation) {
            return bad(format!("correlation {}: expected a number in [0, 1)", self.jitter_correlation));
        }
        if let Some(m) = self.delay_min_ms {
            if self.kind != Kind::Delay {
                return bad("a minimum delay applies only to delay fits".into());
            }
            if !(m.is_finite() && m >= 0.0) {
                return bad(format!("minimum delay {m} ms: expected a finite number ≥ 0"));
            }
        }
        Ok(())
    }

    /// The search's stream seed.
    pub fn search_seed(&self) -> u64 {
        stream_seed(self.seed, 0, "fit/search")
    }

    /// The common random numbers of the Monte Carlo objective.
    pub fn crn_seed(&self) -> u64 {
        stream_seed(self.seed, 0, "fit/crn")
    }

    /// The confirmation's seed: different from the search's, so the
    /// confirmation is an independent simulation.
    pub fn confirm_seed(&self) -> u64 {
        stream_seed(self.seed, 0, "fit/confirm")
    }
}

/// Why a fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// The request itself is invalid.
    #[error("{problem}")]
    BadRequest { problem: String },
    /// No point of the family reaches the targets.
    #[error("{kind} targets not reachable with {family}: best found {best}{hint}")]
    Unreachable { kind: &'static str, family: String, best: String, hint: String },
}

/// Fitted parameters of one model (serialized as the model's own fields, the
/// way a scenario stage writes them).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum FittedParams {
    GeLomax(GeLomaxParams),
    Delay(DelayParams),
    Outage(OutageParams),
    Jitter(JitterParams),
}

impl FittedParams {
    fn from_spec(spec: &ModelSpec) -> FittedParams {
        match spec {
            ModelSpec::GeLomax(p) => FittedParams::GeLomax(p.clone()),
            ModelSpec::Delay(p) => FittedParams::Delay(p.clone()),
            ModelSpec::Outage(p) => FittedParams::Outage(p.clone()),
            ModelSpec::Jitter(p) => FittedParams::Jitter(p.clone()),
            other => unreachable!("fits produce ge_lomax, delay, outage or jitter, not {:?}", other.kind()),
        }
    }
}

/// The search's effort.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SearchStats {
    pub generations: usize,
    pub evaluations: usize,
    /// The objective at the best candidate.
    pub objective: f64,
}

/// The outcome of a fit (what `netfi fit --json` prints).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitResult {
    pub model: &'static str,
    pub params: FittedParams,
    /// Target per metric.
    pub target: BTreeMap<&'static str, f64>,
    /// Realized per metric, by the confirmation.
    pub realized: BTreeMap<&'static str, f64>,
    pub realized_ci95: BTreeMap<&'static str, [f64; 2]>,
    /// The long-run value of the stored parameters by closed form.
    pub exact: BTreeMap<&'static str, f64>,
    /// Whether every realized value is within `tolerance_rel` of its target.
    pub within_tolerance: bool,
    pub tolerance_rel: f64,
    /// The fit's seed; the search and the confirmation derive their streams
    /// from it.
    pub seed: u64,
    pub confirm_seed: u64,
    /// Frames the confirmation decided.
    pub frames: u64,
    /// Outage windows the confirmation opened.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub windows: Option<u64>,
    pub frame_rate_hz: f64,
    pub objective: Objective,
    /// What the family fixes and frees.
    pub family: String,
    pub search: SearchStats,
    pub tool_version: &'static str,
    #[serde(skip)]
    pub spec: ModelSpec,
    #[serde(skip)]
    pub estimates: Vec<Estimate>,
}

impl FitResult {
    /// The realized primary metric.
    pub fn primary(&self) -> Estimate {
        self.estimates[0]
    }

    /// The fitted model as a scenario stage (`[[stage]]` table).
    pub fn stage_toml(&self) -> String {
        // A stage without a name is its model: `model = "…"` and the parameters.
        let mut table = toml::to_string(&self.spec).expect("a stage serializes");
        table.insert_str(0, "[[stage]]\n");
        table
    }
}

/// What was found by the search, before confirmation.
#[derive(Debug, Clone)]
pub struct Searched {
    /// What the family fixes and frees ([`Family::describe`]).
    pub family: String,
    pub spec: ModelSpec,
    pub exact: Vec<f64>,
    pub stats: SearchStats,
}

/// Settings of the search for a request.
pub fn search_config(req: &FitRequest) -> de::DeConfig {
    match req.objective {
        // Relative error 1e-8: far inside the tolerance, so the confirmation's
        // noise is all that separates the realized value from the target.
        Objective::Exact => de::DeConfig { tolerance: 1e-16, max_generations: 400, ..de::DeConfig::default() },
        // The estimate's own sampling error (~1e-3) is the floor; searching
        // below it buys nothing.
        Objective::MonteCarlo => de::DeConfig { tolerance: 1e-10, max_generations: 80, ..de::DeConfig::default() },
    }
}

/// The search: differential evolution over the family's box, then a
/// Nelder–Mead polish from its best point. `evaluate` computes a batch of
/// candidates' objective values (it may do so in parallel); the search
/// itself is pure and seeded by [`FitRequest::search_seed`].
pub fn search(
    req: &FitRequest,
    family: &Family,
    evaluate: &mut dyn FnMut(&[Vec<f64>]) -> Vec<f64>,
    on_generation: &mut dyn FnMut(usize, f64),
) -> de::DeResult {
    let config = search_config(req);
    let bounds = family.bounds();
    let mut result = de::minimize(&bounds, &config, req.search_seed(), evaluate, on_generation);
    if result.value > config.tolerance {
        let budget = match req.objective {
            Objective::Exact => 2000,
            Objective::MonteCarlo => 200,
        };
        let (x, v, n) = de::polish(&bounds, &result.best, result.value, config.tolerance, budget, evaluate);
        result.evaluations += n;
        if v < result.value {
            result.best = x;
            result.value = v;
        }
    }
    result
}

/// Builds the family of a validated request.
pub fn family_of(req: &FitRequest) -> Result<Family, FitError> {
    req.validate()?;
    Family::new(req.kind, &req.goals, req.like.as_deref(), req.delay_min_ms, req.frame_interval_ns())
}

/// After the search: rounds the best point's parameters, checks that the
/// targets are reached (by closed form, or by the Monte Carlo objective in
/// that mode) and returns what is to be confirmed.
pub fn conclude(req: &FitRequest, family: Family, result: &de::DeResult) -> Result<Searched, FitError> {
    let spec = family.spec(&result.best, true);
    let metrics: Vec<Metric> = req.goals.iter().map(|g| g.metric).collect();
    let interval = family.frame_interval_ns();
    let exact = family::metrics_exact(&spec, &metrics, interval).ok_or_else(|| FitError::Unreachable {
        kind: req.kind.name(),
        family: family.describe(),
        best: "invalid parameters".into(),
        hint: String::new(),
    })?;
    let reached = match req.objective {
        Objective::Exact => exact.clone(),
        Objective::MonteCarlo => {
            family::metrics_monte_carlo(&spec, &metrics, req.crn_seed(), interval).unwrap_or_else(|| exact.clone())
        }
    };
    // The closed form must sit well inside the tolerance, leaving room for
    // the confirmation's sampling error; the Monte Carlo objective can only
    // be held to the tolerance itself.
    let slack = match req.objective {
        Objective::Exact => TOLERANCE_REL / 5.0,
        Objective::MonteCarlo => TOLERANCE_REL,
    };
    let off = req.goals.iter().zip(&reached).any(|(g, m)| ((m - g.value) / g.value).abs() > slack);
    if off {
        let best = req
            .goals
            .iter()
            .zip(&reached)
            .map(|(g, m)| format!("{} {} (target {})", g.metric.name(), fmt_sig(*m), g.value))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(FitError::Unreachable {
            kind: req.kind.name(),
            family: family.describe(),
            best,
            hint: unreachable_hint(req),
        });
    }
    let stats =
        SearchStats { generations: result.generations, evaluations: result.evaluations, objective: result.value };
    Ok(Searched { family: family.describe(), spec, exact, stats })
}

/// A jitter fit's answer, in place of the search: the law's `sd_ms` and
/// `mean_ms` solving the mean and p99 exactly
/// ([`crate::model::jitter::fit_mean_p99`]), rounded to 7 significant
/// digits, with the request's correlation; and the exact mean and p99 of
/// the rounded parameters.
pub fn jitter_searched(req: &FitRequest) -> Result<Searched, FitError> {
    req.validate()?;
    let (mean_ms, p99_ms) = (req.goals[0].value, req.goals[1].value);
    let unreachable = |e: crate::model::ParamError| FitError::Unreachable {
        kind: req.kind.name(),
        family: jitter_family(req),
        best: format!("no {} jitter: `{}` {}", req.jitter_dist.name(), e.field, e.problem),
        hint: String::new(),
    };
    let solved = crate::model::jitter::fit_mean_p99(req.jitter_dist, mean_ms, p99_ms).map_err(unreachable)?;
    let round = family::round_sig;
    let params = JitterParams::new(round(solved.mean_ms.get()), round(solved.sd_ms), req.jitter_dist)
        .and_then(|p| p.with_correlation(req.jitter_correlation))
        .map_err(unreachable)?;
    let model = crate::model::Jitter::new(&params).map_err(unreachable)?;
    let exact = vec![model.mean_ms_exact(), model.quantile_ms(0.99)];
    let off = req.goals.iter().zip(&exact).any(|(g, m)| ((m - g.value) / g.value).abs() > TOLERANCE_REL / 5.0);
    if off {
        return Err(FitError::Unreachable {
            kind: req.kind.name(),
            family: jitter_family(req),
            best: format!("mean {} ms, p99 {} ms after rounding", fmt_sig(exact[0]), fmt_sig(exact[1])),
            hint: String::new(),
        });
    }
    let stats = SearchStats { generations: 0, evaluations: 0, objective: 0.0 };
    Ok(Searched { family: jitter_family(req), spec: ModelSpec::Jitter(params), exact, stats })
}

fn jitter_family(req: &FitRequest) -> String {
    format!(
        "jitter: {} law, correlation {} (given); mean_ms and sd_ms solved in closed form for the mean and p99",
        req.jitter_dist.name(),
        req.jitter_correlation
    )
}

fn unreachable_hint(req: &FitRequest) -> String {
    match req.goals.get(1).map(|g| g.metric) {
        Some(Metric::LossRunMean) => format!(
            "; with Lomax bursts the mean loss run is at least about 1/(1 − loss) = {:.3} frames, and long runs at low loss need a shape α below the family's bound of 1.5",
            1.0 / (1.0 - req.goals[0].value)
        ),
        Some(Metric::DelayMsStd) | Some(Metric::DelayMsP99) => {
            "; the hyperexponential part has a coefficient of variation of at least 1, so a tighter delay needs a larger minimum (--min-ms)".into()
        }
        _ => String::new(),
    }
}

/// `v` with at most 7 significant digits, for messages.
pub fn fmt_sig(v: f64) -> String {
    format!("{}", family::round_sig(v))
}

/// Builds the result from a search and a finished confirmation.
pub fn assemble(req: &FitRequest, searched: Searched, confirmation: &Confirmation) -> FitResult {
    let estimates = confirmation.estimates();
    let name = |i: usize| req.goals[i].metric.name();
    let n = req.goals.len();
    let within_tolerance =
        req.goals.iter().zip(&estimates).all(|(g, e)| ((e.value - g.value) / g.value).abs() <= TOLERANCE_REL);
    FitResult {
        model: req.kind.model_name(),
        params: FittedParams::from_spec(&searched.spec),
        target: (0..n).map(|i| (name(i), req.goals[i].value)).collect(),
        realized: (0..n).map(|i| (name(i), estimates[i].value)).collect(),
        realized_ci95: (0..n).map(|i| (name(i), estimates[i].ci95)).collect(),
        exact: (0..n).map(|i| (name(i), searched.exact[i])).collect(),
        within_tolerance,
        tolerance_rel: TOLERANCE_REL,
        seed: req.seed,
        confirm_seed: confirmation.seed(),
        frames: confirmation.frames(),
        windows: (req.kind == Kind::Outage).then(|| confirmation.windows()),
        frame_rate_hz: req.frame_rate_hz,
        objective: req.objective,
        family: searched.family,
        search: searched.stats,
        tool_version: TOOL_VERSION,
        spec: searched.spec,
        estimates,
    }
}
