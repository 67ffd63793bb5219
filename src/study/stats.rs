//! The statistics of a study's report: mean and standard deviation, the
//! paired t-test, the Wilcoxon signed-rank test, and Holm's correction for
//! multiple comparisons.
//!
//! Pure. The t and normal distributions are `statrs`'s (the regularized
//! incomplete beta and the complementary error function, accurate to about
//! 1e-14 in the range a study's tests reach); the Wilcoxon statistic's exact
//! null distribution is counted here. Tests are two-sided. The conventions
//! are R's (`t.test(paired = TRUE)`, `wilcox.test(paired = TRUE)`,
//! `p.adjust(method = "holm")`), so a lab can check every figure there.

use statrs::distribution::{ContinuousCDF, Normal, StudentsT};

/// The mean of `xs` (`None` when empty).
pub fn mean(xs: &[f64]) -> Option<f64> {
    (!xs.is_empty()).then(|| xs.iter().sum::<f64>() / xs.len() as f64)
}

/// The sample standard deviation (n − 1 in the denominator; `None` below
/// two values).
pub fn sd(xs: &[f64]) -> Option<f64> {
    let m = mean(xs)?;
    (xs.len() >= 2).then(|| (xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (xs.len() - 1) as f64).sqrt())
}

/// A paired t-test of differences `d` (condition − baseline) against 0.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TTest {
    pub n: usize,
    pub mean_difference: f64,
    pub sd_difference: f64,
    pub t: f64,
    pub df: f64,
    /// Two-sided.
    pub p: f64,
}

/// The paired t-test of the differences `d`; `None` below two pairs or
/// when every difference is the same (the statistic is then undefined:
/// R says "data are essentially constant").
pub fn paired_t(d: &[f64]) -> Option<TTest> {
    let n = d.len();
    let m = mean(d)?;
    let s = sd(d)?;
    if s == 0.0 || !s.is_finite() {
        return None;
    }
    let t = m / (s / (n as f64).sqrt());
    let df = (n - 1) as f64;
    let law = StudentsT::new(0.0, 1.0, df).ok()?;
    let p = (2.0 * law.sf(t.abs())).min(1.0);
    Some(TTest { n, mean_difference: m, sd_difference: s, t, df, p })
}

/// How a Wilcoxon p-value was computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WilcoxonMethod {
    /// The exact null distribution (no ties, no zero differences, fewer
    /// than 50 pairs).
    Exact,
    /// The normal approximation with the tie correction of the variance
    /// and a continuity correction of 0.5.
    Normal,
}

/// A Wilcoxon signed-rank test of differences against 0.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Wilcoxon {
    /// Pairs with a difference other than 0 (the others are left out).
    pub n: usize,
    /// The sum of the ranks of the positive differences (R's `V`).
    pub v: f64,
    /// Two-sided.
    pub p: f64,
    pub method: WilcoxonMethod,
}

/// The Wilcoxon signed-rank test of `d`; `None` when no difference is
/// other than 0.
pub fn wilcoxon(d: &[f64]) -> Option<Wilcoxon> {
    let mut nz: Vec<f64> = d.iter().copied().filter(|x| *x != 0.0).collect();
    let n = nz.len();
    if n == 0 {
        return None;
    }
    nz.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Mid-ranks of the absolute differences, and the ties' sizes.
    let mut ranks = vec![0.0; n];
    let mut ties: Vec<usize> = Vec::new();
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j + 1 < n && nz[j + 1].abs() == nz[i].abs() {
            j += 1;
        }
        let mid = (i + j) as f64 / 2.0 + 1.0;
        ranks[i..=j].iter_mut().for_each(|r| *r = mid);
        if j > i {
            ties.push(j - i + 1);
        }
        i = j + 1;
    }
    let v: f64 = nz.iter().zip(&ranks).filter(|(x, _)| **x > 0.0).map(|(_, r)| r).sum();
    let zeros = d.len() - n;
    let nf = n as f64;
    if ties.is_empty() && zeros == 0 && n < 50 {
        let p = exact_signed_rank_p(n, v as u64);
        return Some(Wilcoxon { n, v, p, method: WilcoxonMethod::Exact });
    }
    let expected = nf * (nf + 1.0) / 4.0;
    let tie_term: f64 = ties.iter().map(|&t| (t * t * t - t) as f64).sum::<f64>() / 48.0;
    let var = nf * (nf + 1.0) * (2.0 * nf + 1.0) / 24.0 - tie_term;
    let diff = v - expected;
    let z = (diff - 0.5 * diff.signum()) / var.sqrt();
    let normal = Normal::new(0.0, 1.0).ok()?;
    let p = (2.0 * normal.sf(z.abs())).min(1.0);
    Some(Wilcoxon { n, v, p, method: WilcoxonMethod::Normal })
}

/// The two-sided exact p-value of the signed-rank statistic `v` with `n`
/// pairs: `min(1, 2·P(V ≤ v))` below the mean, `min(1, 2·P(V ≥ v))` above,
/// from the counts of the 2^n sign patterns (R's `psignrank` rule).
fn exact_signed_rank_p(n: usize, v: u64) -> f64 {
    let max = n * (n + 1) / 2;
    // counts[s]: sign patterns of ranks 1..=k whose positive ranks sum to s.
    let mut counts = vec![0f64; max + 1];
    counts[0] = 1.0;
    for k in 1..=n {
        for s in (k..=max).rev() {
            counts[s] += counts[s - k];
        }
    }
    let total = 2f64.powi(n as i32);
    let v = v as usize;
    let below: f64 = counts[..=v.min(max)].iter().sum();
    let above: f64 = counts[v.min(max)..].iter().sum();
    let half = max as f64 / 2.0;
    let tail = if (v as f64) <= half { below } else { above };
    (2.0 * tail / total).min(1.0)
}

/// Holm's step-down adjustment of `p` (R's `p.adjust(p, "holm")`): the
/// k-th smallest of m is multiplied by m − k + 1, the results made
/// non-decreasing in that order, and capped at 1.
pub fn holm(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]));
    let mut adjusted = vec![0.0; m];
    let mut running: f64 = 0.0;
    for (k, &i) in order.iter().enumerate() {
        running = running.max(((m - k) as f64 * p[i]).min(1.0));
        adjusted[i] = running;
    }
    adjusted
}

/// A Pearson correlation of paired values.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Pearson {
    pub n: usize,
    pub r: f64,
    /// Two-sided, from t = r √(n − 2) / √(1 − r²) with n − 2 degrees of
    /// freedom (R's `cor.test`).
    pub p: f64,
}

/// The Pearson correlation of the pairs `(x, y)`; `None` below three
/// pairs or when either side is constant (r is then undefined).
pub fn pearson(pairs: &[(f64, f64)]) -> Option<Pearson> {
    let n = pairs.len();
    if n < 3 {
        return None;
    }
    let mx = pairs.iter().map(|p| p.0).sum::<f64>() / n as f64;
    let my = pairs.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for &(x, y) in pairs {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    if sxx == 0.0 || syy == 0.0 || !(sxx * syy).is_finite() {
        return None;
    }
    // Rounding can take |r| an ulp past 1; the quotient is otherwise exact to it.
    let r = (sxy / (sxx.sqrt() * syy.sqrt())).clamp(-1.0, 1.0);
    let df = (n - 2) as f64;
    let p = if r.abs() == 1.0 {
        0.0
    } else {
        let t = r * df.sqrt() / (1.0 - r * r).sqrt();
        (2.0 * StudentsT::new(0.0, 1.0, df).ok()?.sf(t.abs())).min(1.0)
    };
    Some(Pearson { n, r, p })
}
