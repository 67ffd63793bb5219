//! `jitter` (docs/spec.md §3.7): a delay around a mean with a standard
//! deviation, of a normal, Pareto or Pareto-normal law as netem names them,
//! optionally correlated from frame to frame, released in `reorder` or
//! `fifo` order as for `delay`.
//!
//! # The law
//!
//! `D = max(0, mean_ms + sd_ms · S)`, with `S` a *standardized* variate
//! (mean 0, variance 1) of the chosen law, written as a monotone function of a
//! standard normal `Z`, `S = h(Z)`:
//!
//! - `normal`: `S = Z`.
//! - `pareto`: `P = Φ(−Z)^(−1/3)`, which is Pareto with shape 3 and scale 1
//!   (`P = (1 − U)^(−1/3)`, `U = Φ(Z)` uniform): netem's table (iproute2's
//!   `pareto.c`) uses shape 3. `E[P] = 3/2`, `Var P = 3/4`, so
//!   `S = (P − 3/2) / √(3/4)`. `S ≥ −1/√3`: a Pareto delay never falls more
//!   than `0.577 · sd_ms` below its mean, and has a heavy upper tail
//!   (`P(S > s) ~ s^−3`).
//! - `paretonormal`: iproute2's `paretonormal.c` takes, at each quantile
//!   `u`, a quarter of the normal quantile plus three quarters of its scaled
//!   Pareto quantile: `T = Z/4 + (P − 3/2)`, the *comonotone* mixture (both
//!   parts from the same `u`). `Var T = 1/16 + 3/4 + ½·Cov(Z, P)`, with
//!   `Cov(Z, P) = ⅓ ∫ φ(z)² Φ(−z)^(−4/3) dz = 0.587 470 748 478…`, so
//!   `sd T = 1.051 777 245 54…` and `S = T / sd T`.
//!
//! So `mean_ms` and `sd_ms` are the exact mean and standard deviation of the
//! delay before the clamp. netem's tables are *not* standardized: its Pareto
//! table holds `(4/3)(P − 3/2)` (standard deviation 1.155, not 1) clipped at
//! 4, its normal table is clipped at ±4 by its 16-bit entries, and each table
//! has 4096 steps; netfi's draws are the continuous laws above.
//!
//! **Clamp.** A negative draw is clamped to 0 (the frame goes on at once), an
//! atom at 0 of mass `P(mean_ms + sd_ms·S < 0)`; the law above 0 is unchanged.
//! The mean therefore rises to `E[D] = E[max(0, mean_ms + sd_ms·S)]`, which
//! [`Jitter::mean_ms_exact`] gives (closed form for `normal`:
//! `m·Φ(m/s) + s·φ(m/s)`; by quadrature over `z` otherwise). Clamping is
//! chosen over truncation (redrawing) because it keeps every frame at or
//! after its own arrival with the law untouched where it is positive, and
//! its effect on the mean is stated exactly. `D` is also capped at
//! [`MAX_DRAW_MS`] (10^10 ms), which no accepted parameters reach with a
//! probability above 10^-10 per frame; the mean ignores the cap.
//!
//! # Correlation
//!
//! `correlation = ρ ∈ [0, 1)` makes `Z` a stationary Gaussian AR(1) process,
//! `Z_n = ρ·Z_{n−1} + √(1 − ρ²)·ε_n`, `ε_n` independent standard normals,
//! `Z_0 = ε_0`. Each `Z_n` is exactly standard normal, so every frame's delay
//! has exactly the law above (a Gaussian copula): the correlation changes
//! which delays follow which, never their distribution. Lag-1 correlation:
//! for `normal` (before the clamp) Pearson's is exactly `ρ`; for any of the
//! laws Spearman's rank correlation is `(6/π)·asin(ρ/2)`, and the normal
//! scores `Φ⁻¹(F(D_n))` have lag-1 correlation `ρ`. The sequence is counted
//! in frames reaching the stage, whatever their spacing.
//!
//! netem's correlation is different, and wrong for this purpose: it mixes
//! the new uniform draw with the previous one, `U_n = (1 − ρ)·V_n + ρ·U_{n−1}`,
//! and looks up the table at `U_n`. `U_n` is no longer uniform: its variance
//! is `(1 − ρ)/(1 + ρ)` times a uniform's, piled toward the median, so the
//! realized jitter is narrower than asked (at 25% correlation the index's
//! spread shrinks to 77%, at 75% to 38%), and the same mixing is why netem's
//! `loss 10% 25%` realizes far less than 10% loss.
//!
//! # Draws
//!
//! With `sd_ms = 0` the delay is the constant `mean_ms` and the stage draws
//! nothing. Otherwise one standard normal (ziggurat) per frame.

use super::delay::{DelayStage, Order, Releases};
use super::units::{at_most_ms, ms_to_ns, MAX_DURATION_MS};
use super::{Millis, ParamError, Probability, StageRng};
use rand::RngExt;
use serde::{Deserialize, Serialize};

/// The largest delay a draw can give, in ms (10^10 ms, about 116 days), as
/// for `delay`'s slowest component.
pub const MAX_DRAW_MS: f64 = 1e10;

/// `Cov(Z, P)` for `P = Φ(−Z)^(−1/3)`: `⅓ ∫ φ(z)² Φ(−z)^(−4/3) dz`
/// (checked by quadrature in the tests).
pub const PARETONORMAL_COV: f64 = 0.587_470_748_478_335_4;

/// The standard deviation of netem's Pareto-normal mixture `Z/4 + P − 3/2`.
pub const PARETONORMAL_SD: f64 = 1.051_777_245_541_644;

/// The standard deviation of a Pareto variate of shape 3 and scale 1: `√(3/4)`.
const PARETO_SD: f64 = 0.866_025_403_784_438_6;

/// The law of the standardized variate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum JitterDist {
    /// `S = Z`.
    Normal,
    /// Pareto of shape 3, standardized.
    Pareto,
    /// netem's `Z/4 + (P − 3/2)` (comonotone), standardized.
    Paretonormal,
}

impl JitterDist {
    pub const ALL: [JitterDist; 3] = [JitterDist::Normal, JitterDist::Pareto, JitterDist::Paretonormal];

    /// The name in scenario files and in `tc … distribution NAME`.
    pub const fn name(self) -> &'static str {
        match self {
            JitterDist::Normal => "normal",
            JitterDist::Pareto => "pareto",
            JitterDist::Paretonormal => "paretonormal",
        }
    }

    /// `S = h(z)`: the standardized variate at the normal score `z`
    /// (increasing in `z`).
    #[inline]
    pub fn standard(self, z: f64) -> f64 {
        match self {
            JitterDist::Normal => z,
            JitterDist::Pareto => (pareto_of(z) - 1.5) / PARETO_SD,
            JitterDist::Paretonormal => (0.25 * z + pareto_of(z) - 1.5) / PARETONORMAL_SD,
        }
    }
}

/// `Φ(−z)^(−1/3)`: the Pareto(3, 1) variate at normal score `z`. Both
/// functions are libm's (pure Rust, not the platform's), so a draw is the same
/// on every platform.
#[inline]
fn pareto_of(z: f64) -> f64 {
    1.0 / libm::cbrt(normal_sf(z))
}

/// The standard normal upper tail `Φ(−z) = P(Z > z)`, accurate to a few ulps
/// in both tails (libm's `erfc`).
#[inline]
pub fn normal_sf(z: f64) -> f64 {
    0.5 * libm::erfc(z * std::f64::consts::FRAC_1_SQRT_2)
}

/// The standard normal distribution function `Φ(z)`.
#[inline]
pub fn normal_cdf(z: f64) -> f64 {
    normal_sf(-z)
}

/// The standard normal density `φ(z)`.
#[inline]
pub fn normal_pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

/// The standard normal quantile `Φ⁻¹(q)`, `0 < q < 1`: Acklam's rational
/// approximation (relative error 1.2·10^-9) refined by one Halley step on
/// [`normal_cdf`], which brings it to about machine precision.
pub fn normal_quantile(q: f64) -> f64 {
    if q <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if q >= 1.0 {
        return f64::INFINITY;
    }
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] =
        [7.784_695_709_041_462e-3, 3.224_671_290_700_398e-1, 2.445_134_137_142_996, 3.754_408_661_907_416];
    const LOW: f64 = 0.024_25;
    let x = if q < LOW {
        let r = (-2.0 * q.ln()).sqrt();
        (((((C[0] * r + C[1]) * r + C[2]) * r + C[3]) * r + C[4]) * r + C[5])
            / ((((D[0] * r + D[1]) * r + D[2]) * r + D[3]) * r + 1.0)
    } else if q <= 1.0 - LOW {
        let s = q - 0.5;
        let r = s * s;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * s
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        let r = (-2.0 * (1.0 - q).ln()).sqrt();
        -(((((C[0] * r + C[1]) * r + C[2]) * r + C[3]) * r + C[4]) * r + C[5])
            / ((((D[0] * r + D[1]) * r + D[2]) * r + D[3]) * r + 1.0)
    };
    // Halley: e = Φ(x) − q; u = e/φ(x); x ← x − u/(1 + x·u/2). The error is
    // taken on the smaller tail so it keeps its relative precision.
    let e = if x > 0.0 { (1.0 - q) - normal_sf(x) } else { normal_cdf(x) - q };
    let u = e / normal_pdf(x);
    x - u / (1.0 + x * u / 2.0)
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct JitterParams {
    /// The delay's mean before the clamp at 0.
    pub mean_ms: Millis,
    /// The delay's standard deviation before the clamp (≥ 0; 0 is constant).
    pub sd_ms: f64,
    /// The law: `normal`, `pareto` or `paretonormal`.
    pub dist: JitterDist,
    /// Lag-1 correlation of the normal scores, in `[0, 1)` (`0.25` or `"25%"`).
    #[serde(default = "no_correlation", skip_serializing_if = "is_zero")]
    pub correlation: Probability,
    #[serde(default)]
    pub order: Order,
}

fn no_correlation() -> Probability {
    Probability::new(0.0).expect("0 is a probability")
}

fn is_zero(p: &Probability) -> bool {
    p.get() == 0.0
}

impl JitterParams {
    /// Uncorrelated jitter of law `dist`, in `reorder` order (the values are
    /// checked by [`Jitter::new`]).
    pub fn new(mean_ms: f64, sd_ms: f64, dist: JitterDist) -> Result<Self, ParamError> {
        Ok(JitterParams {
            mean_ms: super::units::millis("mean_ms", mean_ms)?,
            sd_ms,
            dist,
            correlation: no_correlation(),
            order: Order::Reorder,
        })
    }

    /// The same jitter with lag-1 correlation `rho` (checked by [`Jitter::new`]).
    pub fn with_correlation(self, rho: f64) -> Result<Self, ParamError> {
        Ok(JitterParams { correlation: super::units::probability("correlation", rho)?, ..self })
    }

    /// The same jitter released in `order`.
    pub fn with_order(self, order: Order) -> Self {
        JitterParams { order, ..self }
    }
}

/// The jitter of law `dist` whose delay (clamp included) has mean
/// `mean_ms` and 99th percentile `p99_ms`, in `reorder` order without
/// correlation (set those after). Exact, by bisection on `sd_ms`: with the
/// 99th percentile held at `p99_ms` (`mean = p99_ms − sd·h(z₀.₉₉)`), the
/// clamped mean falls as `sd_ms` grows. Needs `0 < mean_ms < p99_ms`; the
/// error names the field that cannot be met.
pub fn fit_mean_p99(dist: JitterDist, mean_ms: f64, p99_ms: f64) -> Result<JitterParams, ParamError> {
    if !(mean_ms.is_finite() && mean_ms > 0.0 && mean_ms <= MAX_DURATION_MS) {
        return Err(ParamError::new("mean_ms", format!("{}: expected a mean delay above 0 and at most one hour", super::units::show(mean_ms))));
    }
    if !(p99_ms.is_finite() && p99_ms > mean_ms && p99_ms <= MAX_DURATION_MS) {
        return Err(ParamError::new("p99_ms", format!("{}: expected a 99th percentile above the mean ({mean_ms} ms) and at most one hour", super::units::show(p99_ms))));
    }
    let h99 = dist.standard(normal_quantile(0.99));
    let build = |sd: f64| -> Result<Jitter, ParamError> {
        // sd ≤ sd_max keeps m ≥ 0 up to rounding.
        Jitter::new(&JitterParams::new((p99_ms - sd * h99).max(0.0), sd, dist)?)
    };
    // The largest sd that keeps the unclamped mean ≥ 0, and the mean there.
    let sd_max = (p99_ms / h99).min(MAX_DURATION_MS);
    let lowest = build(sd_max)?.mean_ms_exact();
    if mean_ms < lowest {
        return Err(ParamError::new(
            "mean_ms",
            format!("{mean_ms} ms: with a 99th percentile of {p99_ms} ms a {} jitter has a mean of at least {lowest:.4} ms", dist.name()),
        ));
    }
    let (mut lo, mut hi) = (0.0, sd_max);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if build(mid)?.mean_ms_exact() > mean_ms {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let sd = 0.5 * (lo + hi);
    JitterParams::new((p99_ms - sd * h99).max(0.0), sd, dist)
}

/// A validated `jitter` stage and its state (the last normal score, and the
/// last release for `fifo`).
#[derive(Debug, Clone)]
pub struct Jitter {
    dist: JitterDist,
    mean_ms: f64,
    sd_ms: f64,
    rho: f64,
    /// `√(1 − ρ²)`.
    innovation: f64,
    releases: Releases,
    clamped_mean_ms: f64,
    /// The previous frame's normal score; NaN before the first frame.
    z_last: f64,
}

impl Jitter {
    pub fn new(params: &JitterParams) -> Result<Self, ParamError> {
        let mean_ms = params.mean_ms.get();
        at_most_ms("mean_ms", mean_ms, MAX_DURATION_MS, "one hour")?;
        let sd_ms = params.sd_ms;
        if !(sd_ms.is_finite() && sd_ms >= 0.0) {
            return Err(ParamError::new(
                "sd_ms",
                format!("{}: a standard deviation must be a finite number of ms ≥ 0", super::units::show(sd_ms)),
            ));
        }
        at_most_ms("sd_ms", sd_ms, MAX_DURATION_MS, "one hour")?;
        let rho = params.correlation.get();
        if !(0.0..1.0).contains(&rho) {
            return Err(ParamError::new(
                "correlation",
                format!("{rho} is out of range: expected a correlation in [0, 1) (1 would repeat the first draw forever)"),
            ));
        }
        let mut j = Jitter {
            dist: params.dist,
            mean_ms,
            sd_ms,
            rho,
            innovation: (1.0 - rho * rho).sqrt(),
            releases: Releases::new(params.order),
            clamped_mean_ms: mean_ms,
            z_last: f64::NAN,
        };
        j.clamped_mean_ms = j.clamped_mean();
        Ok(j)
    }

    pub fn dist(&self) -> JitterDist {
        self.dist
    }

    /// The lag-1 correlation `ρ` of the normal scores.
    pub fn correlation(&self) -> f64 {
        self.rho
    }

    /// Spearman's lag-1 rank correlation of the delays, `(6/π)·asin(ρ/2)`
    /// (exact for a continuous law, i.e. when the clamp does not bite).
    pub fn rank_correlation_exact(&self) -> f64 {
        6.0 / std::f64::consts::PI * (self.rho / 2.0).asin()
    }

    /// Whether frames can leave out of their arrival order.
    pub fn may_reorder(&self) -> bool {
        !self.releases.fifo() && self.sd_ms > 0.0
    }

    /// `E[D]` in ms, the clamp at 0 included.
    pub fn mean_ms_exact(&self) -> f64 {
        self.clamped_mean_ms
    }

    /// `P(D = 0)`: the mass the clamp puts at 0.
    pub fn clamped_fraction_exact(&self) -> f64 {
        if self.sd_ms == 0.0 {
            return 0.0;
        }
        // S < −m/s  ⇔  Z < h⁻¹(−m/s).
        let threshold = -self.mean_ms / self.sd_ms;
        let z = self.score_of(threshold);
        normal_cdf(z)
    }

    /// The `q`-quantile of `D` in ms (`0 < q < 1`): `max(0, m + s·h(Φ⁻¹(q)))`.
    pub fn quantile_ms(&self, q: f64) -> f64 {
        (self.mean_ms + self.sd_ms * self.dist.standard(normal_quantile(q))).clamp(0.0, MAX_DRAW_MS)
    }

    /// `P(D ≤ x)` for `x` in ms.
    pub fn cdf_ms(&self, x_ms: f64) -> f64 {
        if x_ms < 0.0 {
            return 0.0;
        }
        if self.sd_ms == 0.0 {
            return if x_ms >= self.mean_ms { 1.0 } else { 0.0 };
        }
        normal_cdf(self.score_of((x_ms - self.mean_ms) / self.sd_ms))
    }

    /// `h⁻¹(s)`: the normal score whose standardized variate is `s`, by
    /// bisection (h is increasing).
    fn score_of(&self, s: f64) -> f64 {
        if self.dist == JitterDist::Normal {
            return s;
        }
        let (mut lo, mut hi) = (-40.0f64, 40.0f64);
        if self.dist.standard(lo) >= s {
            return f64::NEG_INFINITY;
        }
        if self.dist.standard(hi) <= s {
            return f64::INFINITY;
        }
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if self.dist.standard(mid) < s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// `E[max(0, m + s·h(Z))]`: closed form for `normal`, else composite
    /// Simpson over `z ∈ [−12, 12]` (the rest of the line carries less than
    /// 10^-15 of the mean).
    fn clamped_mean(&self) -> f64 {
        let (m, s) = (self.mean_ms, self.sd_ms);
        if s == 0.0 {
            return m;
        }
        if self.dist == JitterDist::Normal {
            let k = m / s;
            return m * normal_cdf(k) + s * normal_pdf(k);
        }
        const N: usize = 24_000;
        let (a, b) = (-12.0, 12.0);
        let step = (b - a) / N as f64;
        let f = |z: f64| (m + s * self.dist.standard(z)).max(0.0) * normal_pdf(z);
        let mut sum = f(a) + f(b);
        for i in 1..N {
            let z = a + i as f64 * step;
            sum += if i % 2 == 1 { 4.0 } else { 2.0 } * f(z);
        }
        sum * step / 3.0
    }
}

impl DelayStage for Jitter {
    /// Draws one delay in ns (without the `fifo` hold), moving the AR(1)
    /// state.
    #[inline]
    fn draw_ns(&mut self, rng: &mut StageRng) -> u64 {
        if self.sd_ms == 0.0 {
            return ms_to_ns(self.mean_ms);
        }
        let e: f64 = rng.sample(rand_distr::StandardNormal);
        let z = if self.z_last.is_nan() { e } else { self.rho * self.z_last + self.innovation * e };
        self.z_last = z;
        let d_ms = self.mean_ms + self.sd_ms * self.dist.standard(z);
        // `clamp` keeps NaN out: h is finite or +∞ for finite z.
        ms_to_ns(d_ms.clamp(0.0, MAX_DRAW_MS))
    }

    #[inline]
    fn releases(&mut self) -> &mut Releases {
        &mut self.releases
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Model, Verdict};
    use rand::SeedableRng;

    fn jitter(mean_ms: f64, sd_ms: f64, dist: JitterDist) -> JitterParams {
        JitterParams::new(mean_ms, sd_ms, dist).unwrap()
    }

    fn field(p: JitterParams) -> String {
        Jitter::new(&p).unwrap_err().field
    }

    fn delay_of(v: Verdict) -> u64 {
        match v {
            Verdict::Pass { delay_ns } => delay_ns,
            other => panic!("a jitter stage only passes, got {other:?}"),
        }
    }

    /// Simpson on [a, b] with n (even) intervals.
    fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
        let h = (b - a) / n as f64;
        let mut s = f(a) + f(b);
        for i in 1..n {
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(a + i as f64 * h);
        }
        s * h / 3.0
    }

    #[test]
    fn the_normal_primitives_match_known_values() {
        assert!((normal_cdf(1.96) - 0.975_002_104_851_780).abs() < 1e-14);
        assert!((normal_sf(8.0) / 6.220_960_574_271_785e-16 - 1.0).abs() < 1e-12);
        for q in [1e-12, 1e-6, 0.001, 0.02, 0.3, 0.5, 0.77, 0.975, 0.999_999] {
            let z = normal_quantile(q);
            let back = if z > 0.0 { 1.0 - normal_sf(z) } else { normal_cdf(z) };
            assert!((back / q - 1.0).abs() < 1e-12, "q {q}: z {z}, Φ(z) {back}");
        }
        assert!((normal_quantile(0.975) - 1.959_963_984_540_054).abs() < 1e-12);
    }

    #[test]
    fn the_pareto_normal_constants_are_the_integrals() {
        let cov = simpson(|z| normal_pdf(z).powi(2) * normal_sf(z).powf(-4.0 / 3.0), -12.0, 12.0, 48_000) / 3.0;
        assert!((cov - PARETONORMAL_COV).abs() < 1e-10, "{cov}");
        let var = 1.0 / 16.0 + 0.75 + 0.5 * PARETONORMAL_COV;
        assert!((var.sqrt() - PARETONORMAL_SD).abs() < 1e-13);
        assert!((PARETO_SD - 0.75f64.sqrt()).abs() < 1e-16);
    }

    #[test]
    fn every_law_is_standardized() {
        for dist in JitterDist::ALL {
            let mean = simpson(|z| dist.standard(z) * normal_pdf(z), -12.0, 12.0, 48_000);
            let var = simpson(|z| dist.standard(z).powi(2) * normal_pdf(z), -12.0, 12.0, 48_000);
            // The Pareto tail beyond z = 12 carries ~1e-21 of the mean; its
            // variance converges slowly (shape 3 has no third moment), so 1e-6.
            assert!(mean.abs() < 1e-9, "{dist:?}: mean {mean}");
            assert!((var - 1.0).abs() < 1e-6, "{dist:?}: variance {var}");
        }
        assert!((JitterDist::Pareto.standard(f64::NEG_INFINITY) + 1.0 / 3f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn the_clamp_raises_the_mean_by_the_stated_amount() {
        // Normal, mean 10, sd 20: E[max(0, D)] = mΦ(m/s) + sφ(m/s).
        let j = Jitter::new(&jitter(10.0, 20.0, JitterDist::Normal)).unwrap();
        let expected = 10.0 * normal_cdf(0.5) + 20.0 * normal_pdf(0.5);
        assert!((j.mean_ms_exact() - expected).abs() < 1e-12);
        assert!((j.clamped_fraction_exact() - normal_cdf(-0.5)).abs() < 1e-12);
        // Far from 0 the clamp does nothing.
        for dist in JitterDist::ALL {
            let j = Jitter::new(&jitter(100.0, 10.0, dist)).unwrap();
            assert!((j.mean_ms_exact() - 100.0).abs() < 1e-7, "{dist:?}: {}", j.mean_ms_exact());
        }
        // Pareto: S ≥ −1/√3, so D > 0 while sd < √3·mean; past that the clamp bites.
        let p = Jitter::new(&jitter(10.0, 17.0, JitterDist::Pareto)).unwrap();
        assert_eq!(p.clamped_fraction_exact(), 0.0);
        let p = Jitter::new(&jitter(10.0, 40.0, JitterDist::Pareto)).unwrap();
        // P(D = 0) = P(P < 1.5 − 10/(40·√(3/4)) ... ) = 1 − P^−3 at that point.
        let x = 1.5 - 10.0 / 40.0 * PARETO_SD;
        assert!((p.clamped_fraction_exact() - (1.0 - x.powi(-3))).abs() < 1e-9);
        assert!(p.mean_ms_exact() > 10.0);
    }

    #[test]
    fn quantiles_and_distribution_function_agree() {
        for dist in JitterDist::ALL {
            let j = Jitter::new(&jitter(100.0, 20.0, dist)).unwrap();
            for q in [0.01, 0.5, 0.9, 0.99] {
                let x = j.quantile_ms(q);
                assert!((j.cdf_ms(x) - q).abs() < 1e-9, "{dist:?} q {q}: x {x}");
            }
        }
        // Pareto quantile by hand: P = (1 − q)^(−1/3).
        let j = Jitter::new(&jitter(100.0, 20.0, JitterDist::Pareto)).unwrap();
        let by_hand = 100.0 + 20.0 * (0.01f64.powf(-1.0 / 3.0) - 1.5) / PARETO_SD;
        assert!((j.quantile_ms(0.99) - by_hand).abs() < 1e-8);
    }

    #[test]
    fn fit_to_a_mean_and_a_p99() {
        for dist in JitterDist::ALL {
            for (mean, p99) in [(100.0, 150.0), (40.0, 120.0)] {
                let p = fit_mean_p99(dist, mean, p99).unwrap();
                let j = Jitter::new(&p).unwrap();
                assert!((j.mean_ms_exact() - mean).abs() < 1e-6, "{dist:?}: mean {}", j.mean_ms_exact());
                assert!((j.quantile_ms(0.99) - p99).abs() < 1e-6, "{dist:?}: p99 {}", j.quantile_ms(0.99));
            }
        }
        // Normal 4.65 sd from 0: the textbook answer, up to the clamp's
        // ~10^-6 ms.
        let p = fit_mean_p99(JitterDist::Normal, 100.0, 150.0).unwrap();
        assert!((p.sd_ms - 50.0 / normal_quantile(0.99)).abs() < 1e-4 && (p.mean_ms.get() - 100.0).abs() < 1e-4, "{p:?}");
        assert_eq!(fit_mean_p99(JitterDist::Normal, 100.0, 90.0).unwrap_err().field, "p99_ms");
        assert_eq!(fit_mean_p99(JitterDist::Normal, 0.0, 90.0).unwrap_err().field, "mean_ms");
        // A Pareto jitter cannot have a mean far below its p99's reach.
        assert_eq!(fit_mean_p99(JitterDist::Pareto, 1.0, 1000.0).unwrap_err().field, "mean_ms");
    }

    #[test]
    fn rejects_bad_parameters() {
        assert_eq!(field(jitter(10.0, -1.0, JitterDist::Normal)), "sd_ms");
        assert_eq!(field(jitter(10.0, f64::NAN, JitterDist::Normal)), "sd_ms");
        assert_eq!(field(jitter(10.0, 3_600_001.0, JitterDist::Normal)), "sd_ms");
        assert_eq!(field(jitter(3_600_001.0, 1.0, JitterDist::Normal)), "mean_ms");
        let one = jitter(10.0, 1.0, JitterDist::Pareto).with_correlation(1.0).unwrap();
        let e = Jitter::new(&one).unwrap_err();
        assert_eq!(e.field, "correlation");
        assert!(e.problem.contains("[0, 1)"), "{e}");
        assert_eq!(jitter(10.0, 1.0, JitterDist::Pareto).with_correlation(-0.1).unwrap_err().field, "correlation");
        assert!(Jitter::new(&jitter(10.0, 0.0, JitterDist::Normal).with_correlation(0.999).unwrap()).is_ok());
    }

    #[test]
    fn parses_from_toml() {
        let p: JitterParams =
            toml::from_str("mean_ms = 100\nsd_ms = 20\ndist = \"paretonormal\"\ncorrelation = \"25%\"\norder = \"fifo\"")
                .unwrap();
        assert_eq!(p, jitter(100.0, 20.0, JitterDist::Paretonormal).with_correlation(0.25).unwrap().with_order(Order::Fifo));
        assert!(toml::from_str::<JitterParams>("mean_ms = 1\nsd_ms = 1\ndist = \"uniform\"").is_err());
        assert!(toml::from_str::<JitterParams>("mean_ms = 1\nsd_ms = 1").is_err());
    }

    #[test]
    fn constant_jitter_draws_nothing_and_never_reorders() {
        let mut j = Jitter::new(&jitter(1.5, 0.0, JitterDist::Normal)).unwrap();
        assert!(!j.may_reorder());
        let mut rng = StageRng::seed_from_u64(1);
        let before = rng.clone();
        assert_eq!(j.decide(10, &mut rng), Verdict::Pass { delay_ns: 1_500_000 });
        assert_eq!(rng, before);
    }

    #[test]
    fn fifo_holds_behind_the_previous_release() {
        let p = jitter(5.0, 3.0, JitterDist::Normal).with_correlation(0.3).unwrap();
        let mut f = Jitter::new(&p.clone().with_order(Order::Fifo)).unwrap();
        let mut r = Jitter::new(&p).unwrap();
        assert!(r.may_reorder() && !f.may_reorder());
        let mut rng_f = StageRng::seed_from_u64(3);
        let mut rng_r = rng_f.clone();
        let (mut last, mut held) = (0u64, 0u32);
        for i in 0..10_000u64 {
            let t = i * 1_000_000;
            let fifo = t + delay_of(f.decide(t, &mut rng_f));
            let own = t + delay_of(r.decide(t, &mut rng_r));
            assert_eq!(fifo, own.max(last));
            held += (fifo > own) as u32;
            last = fifo;
        }
        assert!(held > 100, "{held}");
    }

    #[test]
    fn delays_are_never_negative() {
        let mut j = Jitter::new(&jitter(1.0, 50.0, JitterDist::Paretonormal).with_correlation(0.5).unwrap()).unwrap();
        let mut rng = StageRng::seed_from_u64(9);
        let zeros = (0..10_000).filter(|_| j.draw_ns(&mut rng) == 0).count();
        // P(D = 0) is about 0.45 here; all that matters is that the clamp bites.
        assert!(zeros > 1000, "{zeros}");
    }

    #[test]
    fn value_stability() {
        let mut out = Vec::new();
        for dist in JitterDist::ALL {
            let mut j = Jitter::new(&jitter(100.0, 20.0, dist).with_correlation(0.25).unwrap()).unwrap();
            let mut rng = StageRng::seed_from_u64(42);
            out.push((0..6).map(|i| delay_of(j.decide(i * 1_000_000, &mut rng))).collect::<Vec<u64>>());
        }
        assert_eq!(out, PINNED);
    }
    const PINNED: [[u64; 6]; 3] = [
        [116687951, 94199774, 125810471, 115446747, 122329366, 110890567],
        [104716573, 92528833, 115375905, 103616775, 110702987, 100127880],
        [107850198, 92469625, 118795370, 106649607, 114120290, 102693906],
    ];
}
