//! `jitter` (docs/spec.md §3.7) against its law: the marginal by
//! Kolmogorov–Smirnov, with and without correlation, the lag-1 correlation of
//! the normal scores, and the clamped mean.
//!
//! Every check has a fixed seed and level α = 0.001 (two-sided where it is a
//! difference). The reference distribution functions are written here from
//! the laws' definitions (netem's tables: Pareto of shape 3, and the
//! comonotone `Z/4 + P − 3/2`), not taken from the model.
//!
//! Honest KS under correlation: with `ρ = 0.9` successive delays are far from
//! independent, and KS's critical value assumes independence. The check keeps
//! every 100th delay: kept normal scores are correlated by `ρ^100 = 2.7·10^-5`,
//! so the kept sample is independent to that precision, and the critical value
//! is that of its size (40,000).

use super::{FRAME_NS, Z_TWO_SIDED_0_001, T99_TWO_SIDED_0_001, KS_C_0_001};
use crate::common::machine;
use netfi::model::jitter::{normal_cdf, normal_quantile, normal_sf, PARETONORMAL_SD};
use netfi::model::{Jitter, JitterDist, JitterParams, Model, StageRng, Verdict};
use rand::SeedableRng;

const MEAN_MS: f64 = 100.0;
const SD_MS: f64 = 20.0;

fn params(dist: JitterDist, mean_ms: f64, sd_ms: f64, rho: f64) -> JitterParams {
    JitterParams::new(mean_ms, sd_ms, dist).unwrap().with_correlation(rho).unwrap()
}

/// `n` delays in ms of one stage, frames 1 ms apart.
fn delays_ms(p: &JitterParams, seed: u64, n: usize) -> Vec<f64> {
    let mut j = Jitter::new(p).unwrap();
    let mut rng = StageRng::seed_from_u64(seed);
    (0..n as u64)
        .map(|i| match j.decide(i * FRAME_NS, &mut rng) {
            Verdict::Pass { delay_ns } => delay_ns as f64 / 1e6,
            other => panic!("a jitter stage only passes, got {other:?}"),
        })
        .collect()
}

/// The normal score `z` with `F(x) = Φ(z)` for the standardized variate `s`
/// of law `dist`, from the law's definition.
fn reference_score(dist: JitterDist, s: f64) -> f64 {
    match dist {
        JitterDist::Normal => s,
        JitterDist::Pareto => {
            // P = 3/2 + s·√(3/4) is Pareto(3, 1): F = 1 − P^−3.
            let p = 1.5 + s * 0.75f64.sqrt();
            if p <= 1.0 {
                return f64::NEG_INFINITY;
            }
            // 1 − F = P^−3 = Φ(−z).
            -normal_quantile(p.powi(-3))
        }
        JitterDist::Paretonormal => {
            // T = z/4 + Φ(−z)^(−1/3) − 3/2, increasing in z: bisection.
            let t = s * PARETONORMAL_SD;
            let g = |z: f64| 0.25 * z + normal_sf(z).powf(-1.0 / 3.0) - 1.5;
            let (mut lo, mut hi) = (-40.0f64, 12.0f64);
            for _ in 0..64 {
                let mid = 0.5 * (lo + hi);
                if g(mid) < t {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        }
    }
}

fn ks_distance(mut us: Vec<f64>) -> f64 {
    us.sort_by(f64::total_cmp);
    let n = us.len() as f64;
    us.iter().enumerate().fold(0.0f64, |d, (i, &u)| d.max(u - i as f64 / n).max((i + 1) as f64 / n - u))
}

/// The probability integral transform of delays: `F(D)` under the reference law.
fn pit(dist: JitterDist, xs: &[f64], mean_ms: f64, sd_ms: f64) -> Vec<f64> {
    xs.iter().map(|&x| normal_cdf(reference_score(dist, (x - mean_ms) / sd_ms))).collect()
}

/// KS at α = 0.001 against each law, uncorrelated: 10^6 delays per law
/// (critical distance 0.0019). At mean 100 ms and sd 20 ms the clamp moves
/// less than 3·10^-7 of the mass (normal: Φ(−5)), and whole-nanosecond
/// rounding about 10^-8: both far below the critical distance.
#[test]
fn jitter_marginal_matches_each_law() {
    let _machine = machine::not_beside_a_run();
    let n = 1_000_000;
    let critical = KS_C_0_001 / (n as f64).sqrt();
    for (seed, dist) in JitterDist::ALL.into_iter().enumerate() {
        let xs = delays_ms(&params(dist, MEAN_MS, SD_MS, 0.0), 300 + seed as u64, n);
        let d = ks_distance(pit(dist, &xs, MEAN_MS, SD_MS));
        eprintln!("{dist:?} ρ 0: KS distance {d:.5} (critical {critical:.5})");
        assert!(d < critical, "{dist:?}: KS distance {d} ≥ {critical} (α = 0.001)");
    }
}

/// The same with correlation 0.9, every 100th of 4·10^6 delays kept (see the
/// module docs): 40,000 nearly independent delays, critical distance 0.0097.
#[test]
fn jitter_marginal_stays_exact_under_correlation() {
    let _machine = machine::not_beside_a_run();
    let (n, keep_every) = (4_000_000, 100);
    let kept = n / keep_every;
    let critical = KS_C_0_001 / (kept as f64).sqrt();
    for (seed, dist) in JitterDist::ALL.into_iter().enumerate() {
        let xs = delays_ms(&params(dist, MEAN_MS, SD_MS, 0.9), 310 + seed as u64, n);
        let thinned: Vec<f64> = xs.iter().step_by(keep_every).copied().collect();
        assert_eq!(thinned.len(), kept);
        let d = ks_distance(pit(dist, &thinned, MEAN_MS, SD_MS));
        eprintln!("{dist:?} ρ 0.9 thinned: KS distance {d:.5} (critical {critical:.5})");
        assert!(d < critical, "{dist:?}: KS distance {d} ≥ {critical} (α = 0.001)");
    }
}

/// Pearson's lag-1 correlation of a series.
fn lag1(xs: &[f64]) -> f64 {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var: f64 = xs.iter().map(|x| (x - mean).powi(2)).sum();
    let cov: f64 = xs.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
    cov / var
}

/// The lag-1 correlation of the normal scores `Φ⁻¹(F(D_n))` is `ρ`, for every
/// law and ρ ∈ {0.25, 0.9}; for `normal` so is Pearson's of the delays
/// themselves. For a Gaussian AR(1) series of length n the estimator's
/// standard deviation is `√((1 − ρ²)/n)` (Bartlett); the tolerance is 3.29
/// of those (α = 0.001), with 10^6 frames: 0.0032 at ρ = 0.25, 0.0014 at 0.9.
#[test]
fn jitter_lag1_correlation_is_rho() {
    let _machine = machine::not_beside_a_run();
    let n = 1_000_000;
    for (seed, (dist, rho)) in JitterDist::ALL
        .into_iter()
        .flat_map(|d| [(d, 0.25), (d, 0.9)])
        .enumerate()
    {
        let xs = delays_ms(&params(dist, MEAN_MS, SD_MS, rho), 320 + seed as u64, n);
        let scores: Vec<f64> = xs.iter().map(|&x| reference_score(dist, (x - MEAN_MS) / SD_MS)).collect();
        let tolerance = Z_TWO_SIDED_0_001 * ((1.0 - rho * rho) / n as f64).sqrt();
        let r = lag1(&scores);
        eprintln!("{dist:?} ρ {rho}: normal scores' lag-1 {r:.5} (± {tolerance:.5})");
        assert!((r - rho).abs() < tolerance, "{dist:?} ρ {rho}: normal scores' lag-1 {r} (± {tolerance})");
        if dist == JitterDist::Normal {
            let r = lag1(&xs);
            assert!((r - rho).abs() < tolerance, "normal ρ {rho}: delays' lag-1 {r} (± {tolerance})");
        }
    }
}

/// Where the clamp bites, the sample mean matches the exact clamped mean
/// (normal: mean 10, sd 20, 31% of draws clamped; Pareto: mean 10, sd 40),
/// with correlation 0.5. Standard errors by batch means: 100 batches of 10^4
/// frames, each far longer than the memory of ρ = 0.5 (0.5^20 ≈ 10^-6);
/// Student's t with 99 degrees of freedom at α = 0.001.
#[test]
fn jitter_clamped_mean_matches_exact() {
    let _machine = machine::not_beside_a_run();
    for (seed, dist, sd_ms) in [(330, JitterDist::Normal, 20.0), (331, JitterDist::Pareto, 40.0)] {
        let p = params(dist, 10.0, sd_ms, 0.5);
        let exact = Jitter::new(&p).unwrap().mean_ms_exact();
        assert!(exact > 10.5, "{dist:?}: the clamp should raise the mean, {exact}");
        let xs = delays_ms(&p, seed, 1_000_000);
        let means: Vec<f64> = xs.chunks(10_000).map(|c| c.iter().sum::<f64>() / c.len() as f64).collect();
        let b = means.len() as f64;
        let mean = means.iter().sum::<f64>() / b;
        let se = (means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (b - 1.0) / b).sqrt();
        assert!(
            (mean - exact).abs() < T99_TWO_SIDED_0_001 * se,
            "{dist:?}: mean {mean} ms vs exact {exact} ms, standard error {se}"
        );
        eprintln!("{dist:?}: clamped mean {mean:.4} ms vs exact {exact:.4} ms (se {se:.4})");
        let zeros = xs.iter().filter(|&&x| x == 0.0).count() as f64 / xs.len() as f64;
        let mass = Jitter::new(&p).unwrap().clamped_fraction_exact();
        // A proportion under correlation: batch-means standard error again.
        let fracs: Vec<f64> =
            xs.chunks(10_000).map(|c| c.iter().filter(|&&x| x == 0.0).count() as f64 / c.len() as f64).collect();
        let fm = fracs.iter().sum::<f64>() / b;
        let fse = (fracs.iter().map(|f| (f - fm).powi(2)).sum::<f64>() / (b - 1.0) / b).sqrt();
        assert!((zeros - mass).abs() < T99_TWO_SIDED_0_001 * fse.max(1e-12), "{dist:?}: clamped {zeros} vs {mass} (se {fse})");
    }
}
