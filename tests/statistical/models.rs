//! Degradation models against their analytic laws (docs/spec.md §3, §4).
//!
//! Every check has a fixed seed and a stated significance level. Unless said
//! otherwise the level is α = 0.001 (two-sided where it is a difference), so a
//! correct model fails a given check for a given seed with probability 0.001.
//! Loss rates of correlated models are checked with batch means (100 batches
//! of 10^5 frames, far longer than any of these chains' memory) or, for
//! outages, with the renewal-cycle ratio estimator; standard errors come from
//! those, never from an assumed independence of frames.

use super::{FRAME_NS, Z_TWO_SIDED_0_001, Z_ONE_SIDED_0_001, T99_TWO_SIDED_0_001, T99_TWO_SIDED_0_05, KS_C_0_001};
use crate::common::machine;
use netfi::model::{
    Bernoulli, BernoulliParams, Delay, DelayParams, GeLomax, GeLomaxParams, GilbertElliott, GilbertElliottParams,
    Markov4, Markov4Params, Model, Order, Outage, OutageParams, Probability, StageRng, Verdict,
};
use rand::SeedableRng;

fn prob(p: f64) -> Probability {
    Probability::new(p).unwrap()
}

// ---------------------------------------------------------------- statistics

/// Mean and standard error of the per-batch drop fractions over `batches`
/// batches of `batch_frames` frames at 1 kHz.
fn batch_means(model: &mut impl Model, rng: &mut StageRng, batches: u64, batch_frames: u64) -> (f64, f64) {
    let mut fractions = Vec::with_capacity(batches as usize);
    let mut t = 0u64;
    for _ in 0..batches {
        let mut drops = 0u64;
        for _ in 0..batch_frames {
            drops += (model.decide(t, rng) == Verdict::Drop) as u64;
            t += FRAME_NS;
        }
        fractions.push(drops as f64 / batch_frames as f64);
    }
    mean_and_standard_error(&fractions)
}

fn mean_and_standard_error(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let variance = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (variance / n).sqrt())
}

/// The Kolmogorov–Smirnov distance between the sample and `cdf`.
fn ks_distance(mut xs: Vec<f64>, cdf: impl Fn(f64) -> f64) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len() as f64;
    let mut d = 0.0f64;
    for (i, &x) in xs.iter().enumerate() {
        let f = cdf(x);
        d = d.max(f - i as f64 / n).max((i + 1) as f64 / n - f);
    }
    d
}

/// The chi-square quantile at `1 − 0.001` for `df` degrees of freedom: exact
/// for 1 and 2, Wilson–Hilferty beyond (within 1% for `df ≥ 3`).
fn chi_square_critical_0_001(df: usize) -> f64 {
    match df {
        0 => panic!("no degrees of freedom"),
        1 => Z_TWO_SIDED_0_001 * Z_TWO_SIDED_0_001,
        2 => -2.0 * 0.001f64.ln(),
        _ => {
            let k = df as f64;
            let h = 2.0 / (9.0 * k);
            k * (1.0 - h + Z_ONE_SIDED_0_001 * h.sqrt()).powi(3)
        }
    }
}

/// Pearson's statistic of integer `counts` against `pmf`, with bins
/// `0, 1, …, K − 1` and a pooled tail `≥ K`, `K` the first value whose bin or
/// remaining tail would expect fewer than 5. Returns the statistic and the
/// degrees of freedom.
fn chi_square(counts: &[u64], n: u64, pmf: impl Fn(u64) -> f64) -> (f64, usize) {
    let n_f = n as f64;
    let mut tail = 1.0;
    let mut k = 0u64;
    let mut statistic = 0.0;
    let mut observed_below = 0u64;
    loop {
        let p = pmf(k);
        if n_f * p < 5.0 || n_f * (tail - p) < 5.0 {
            break;
        }
        let observed = counts.get(k as usize).copied().unwrap_or(0);
        statistic += (observed as f64 - n_f * p).powi(2) / (n_f * p);
        observed_below += observed;
        tail -= p;
        k += 1;
    }
    let observed_tail = n - observed_below;
    statistic += (observed_tail as f64 - n_f * tail).powi(2) / (n_f * tail);
    (statistic, k as usize)
}

// --------------------------------------------------------------------- delay

fn hyperexp(min_ms: f64, weights: [f64; 2], rates: [f64; 2]) -> DelayParams {
    DelayParams::hyperexp(min_ms, &weights, &rates).unwrap()
}

/// docs/spec.md §4's delay presets.
fn dlm_presets() -> [(&'static str, f64, [f64; 2], [f64; 2]); 3] {
    [
        ("DLM-1", 70.0, [0.72645, 0.27355], [0.02711, 0.08529]),
        ("DLM-2", 210.0, [0.89258, 0.10742], [0.01081, 0.01624]),
        ("DLM-3", 406.0, [0.89574, 0.10426], [0.01025, 0.01551]),
    ]
}

fn delays_ms(params: &DelayParams, seed: u64, n: usize) -> Vec<f64> {
    let mut d = Delay::new(params).unwrap();
    let mut rng = StageRng::seed_from_u64(seed);
    (0..n as u64)
        .map(|i| match d.decide(i * FRAME_NS, &mut rng) {
            Verdict::Pass { delay_ns } => delay_ns as f64 / 1e6,
            other => panic!("a delay stage only passes, got {other:?}"),
        })
        .collect()
}

/// KS at α = 0.001 with 10^6 delays per preset against
/// `F(d) = Σ w_i (1 − e^(−λ_i (d − min)))`. Delays are whole nanoseconds; the
/// rounding moves the CDF by at most `λ·0.5 ns ≈ 10^-8`, far below the
/// critical distance `1.95/√n ≈ 0.002`.
#[test]
fn delay_hyperexp_matches_its_cdf() {
    let _machine = machine::not_beside_a_run();
    let n = 1_000_000;
    let critical = KS_C_0_001 / (n as f64).sqrt();
    for (seed, (name, min_ms, w, rates)) in dlm_presets().into_iter().enumerate() {
        let xs = delays_ms(&hyperexp(min_ms, w, rates), 100 + seed as u64, n);
        let cdf = |d: f64| {
            let x = (d - min_ms).max(0.0);
            w[0] * (-(-rates[0] * x).exp_m1()) + w[1] * (-(-rates[1] * x).exp_m1())
        };
        let distance = ks_distance(xs, cdf);
        assert!(distance < critical, "{name}: KS distance {distance} ≥ {critical} (α = 0.001)");
    }
}

/// KS at α = 0.001 with 10^6 delays against `U[min, min + jitter)`, in
/// `fifo` order at a frame interval far above the jitter so the hold never
/// applies (checked), and in `reorder` order.
#[test]
fn delay_uniform_matches_its_cdf() {
    let _machine = machine::not_beside_a_run();
    let n = 1_000_000;
    let critical = KS_C_0_001 / (n as f64).sqrt();
    for (seed, order) in [(7, Order::Reorder), (8, Order::Fifo)] {
        let params = DelayParams::uniform(2.5, 0.75).unwrap().with_order(order);
        let xs = delays_ms(&params, seed, n);
        assert!(xs.iter().all(|&d| (2.5..=3.25).contains(&d)));
        let distance = ks_distance(xs, |d| ((d - 2.5) / 0.75).clamp(0.0, 1.0));
        assert!(distance < critical, "{order:?}: KS distance {distance} ≥ {critical} (α = 0.001)");
    }
}

/// docs/spec.md §4: DLM sample means within 0.5% of `min + Σ w/λ` (10^6 frames), and
/// within 3.29 standard errors (α = 0.001), the stronger of the two here.
#[test]
fn dlm_means_match_the_presets() {
    let _machine = machine::not_beside_a_run();
    let n = 1_000_000;
    for (seed, (name, min_ms, w, rates)) in dlm_presets().into_iter().enumerate() {
        let params = hyperexp(min_ms, w, rates);
        let exact = Delay::new(&params).unwrap().mean_ms_exact();
        assert!((exact - (min_ms + w[0] / rates[0] + w[1] / rates[1])).abs() < 1e-12);
        let xs = delays_ms(&params, 200 + seed as u64, n);
        let (mean, se) = mean_and_standard_error(&xs);
        assert!((mean - exact).abs() < 0.005 * exact, "{name}: mean {mean} ms vs {exact} ms (0.5%)");
        assert!(
            (mean - exact).abs() < Z_TWO_SIDED_0_001 * se,
            "{name}: mean {mean} ms vs {exact} ms, standard error {se} (α = 0.001)"
        );
    }
}

// ------------------------------------------------------------------ ge_lomax

fn plm(alpha: [f64; 2], lambda: [f64; 2]) -> GeLomaxParams {
    GeLomaxParams::two_state(netfi::model::presets::STUDY_TRANSITION, alpha, lambda)
}

/// docs/spec.md §4's packet-loss presets.
fn plm_presets() -> [(&'static str, GeLomaxParams, f64); 3] {
    [
        ("PLM-1", plm([4.428, 4.966], [1.638, 0.271]), 0.10),
        ("PLM-2", plm([4.604, 3.901], [3.552, 1.466]), 0.30),
        ("PLM-3", plm([3.859, 3.797], [3.324, 6.049]), 0.50),
    ]
}

/// Burst lengths from the sampler, per state, against the floored-Lomax pmf
/// `(1 + k/λ)^(−α) − (1 + (k+1)/λ)^(−α)`: chi-square at α = 0.001, 10^6
/// bursts per state, bins expecting at least 5, tail pooled.
#[test]
fn ge_lomax_bursts_follow_the_floored_lomax() {
    let _machine = machine::not_beside_a_run();
    let n = 1_000_000u64;
    let mut cases: Vec<(String, GeLomaxParams)> =
        plm_presets().into_iter().map(|(name, p, _)| (name.to_string(), p)).collect();
    cases.push(("heavy".into(), plm([1.3, 0.8], [2.0, 25.0])));
    let mut seed = 300;
    for (name, params) in cases {
        let m = GeLomax::new(&params).unwrap();
        for state in 0..m.states() {
            seed += 1;
            let mut rng = StageRng::seed_from_u64(seed);
            let mut counts = vec![0u64; 1 << 16];
            for _ in 0..n {
                let b = m.sample_burst(state, &mut rng) as usize;
                counts[b.min((1 << 16) - 1)] += 1;
            }
            let (statistic, df) = chi_square(&counts, n, |k| m.burst_pmf(state, k));
            let critical = chi_square_critical_0_001(df);
            assert!(
                statistic < critical,
                "{name} state {state}: χ² = {statistic} with {df} df ≥ {critical} (α = 0.001)"
            );
        }
    }
}

/// A one-state chain's fates are its bursts laid end to end (each closed by
/// one delivery), so the runs of drops between deliveries are independent
/// draws of the floored Lomax: chi-square at α = 0.001 over 10^6 runs.
#[test]
fn ge_lomax_drop_runs_follow_the_floored_lomax() {
    let _machine = machine::not_beside_a_run();
    let params = GeLomaxParams { transition: vec![vec![1.0]], alpha: vec![2.2], lambda: vec![3.0] };
    let mut m = GeLomax::new(&params).unwrap();
    let mut rng = StageRng::seed_from_u64(400);
    let n = 1_000_000u64;
    let mut counts = vec![0u64; 1 << 16];
    let mut run = 0usize;
    let mut t = 0;
    for _ in 0..n {
        loop {
            t += FRAME_NS;
            if m.decide(t, &mut rng) == Verdict::Drop {
                run += 1;
            } else {
                break;
            }
        }
        counts[run.min((1 << 16) - 1)] += 1;
        run = 0;
    }
    let (statistic, df) = chi_square(&counts, n, |k| m.burst_pmf(0, k));
    let critical = chi_square_critical_0_001(df);
    assert!(statistic < critical, "χ² = {statistic} with {df} df ≥ {critical} (α = 0.001)");
}

/// docs/spec.md §4: the PLM presets' simulated loss (10^7 frames, 100 batches) has
/// `loss_rate_exact` inside its 95% batch-means interval. The labels are
/// targets that the presets miss by design; the exact values are printed.
#[test]
fn ge_lomax_plm_loss_matches_exact() {
    let _machine = machine::not_beside_a_run();
    for (seed, (name, params, label)) in plm_presets().into_iter().enumerate() {
        let mut m = GeLomax::new(&params).unwrap();
        let exact = m.loss_rate_exact();
        let mut rng = StageRng::seed_from_u64(500 + seed as u64);
        let (mean, se) = batch_means(&mut m, &mut rng, 100, 100_000);
        println!("{name}: exact long-run loss {exact:.9} (label {label}), simulated {mean:.6} ± {se:.6}");
        assert!(
            (mean - exact).abs() < T99_TWO_SIDED_0_05 * se,
            "{name}: simulated {mean} ± {se}, exact {exact} (95% interval)"
        );
        // "A little under or over" the label.
        assert!((exact - label).abs() < 0.05, "{name}: {exact} vs label {label}");
    }
}

/// Chains that exercise the other branches of `loss_rate_exact`: a periodic
/// chain (the draw kernel's tail split by residue class), three and four
/// states. α = 0.001, 10^7 frames, 100 batches. Shapes stay above 2 so burst
/// lengths have a variance and batch means a normal limit.
#[test]
fn ge_lomax_other_chains_match_exact() {
    let _machine = machine::not_beside_a_run();
    let cases = [
        GeLomaxParams {
            transition: vec![vec![0.0, 1.0], vec![1.0, 0.0]],
            alpha: vec![2.5, 6.0],
            lambda: vec![4.0, 0.5],
        },
        GeLomaxParams {
            transition: vec![vec![0.0, 1.0, 0.0], vec![0.0, 0.0, 1.0], vec![0.5, 0.0, 0.5]],
            alpha: vec![3.0, 5.0, 2.8],
            lambda: vec![6.0, 0.3, 2.0],
        },
        GeLomaxParams {
            transition: vec![
                vec![0.90, 0.05, 0.03, 0.02],
                vec![0.20, 0.70, 0.10, 0.00],
                vec![0.10, 0.10, 0.60, 0.20],
                vec![0.05, 0.00, 0.15, 0.80],
            ],
            alpha: vec![6.0, 4.0, 3.0, 2.6],
            lambda: vec![0.5, 2.0, 5.0, 12.0],
        },
    ];
    for (seed, params) in cases.into_iter().enumerate() {
        let mut m = GeLomax::new(&params).unwrap();
        let exact = m.loss_rate_exact();
        let mut rng = StageRng::seed_from_u64(600 + seed as u64);
        let (mean, se) = batch_means(&mut m, &mut rng, 100, 100_000);
        println!("{} states: exact long-run loss {exact:.6}, simulated {mean:.6} ± {se:.6}", m.states());
        assert!(
            (mean - exact).abs() < T99_TWO_SIDED_0_001 * se,
            "{params:?}: simulated {mean} ± {se}, exact {exact} (α = 0.001)"
        );
    }
}

// ----------------------------------------------------- netem models, bernoulli

#[test]
fn markov4_loss_matches_closed_form() {
    let _machine = machine::not_beside_a_run();
    let cases = [
        Markov4Params {
            p13: prob(0.05),
            p31: Some(prob(0.4)),
            p32: Some(prob(0.1)),
            p23: Some(prob(0.2)),
            p14: Some(prob(0.01)),
        },
        Markov4Params {
            p13: prob(0.01),
            p31: Some(prob(0.3)),
            p32: Some(prob(0.5)),
            p23: Some(prob(0.05)),
            p14: Some(prob(0.02)),
        },
        Markov4Params { p13: prob(0.25), p31: None, p32: None, p23: None, p14: None },
    ];
    for (seed, params) in cases.into_iter().enumerate() {
        let mut m = Markov4::new(&params).unwrap();
        let exact = m.loss_rate_exact();
        let mut rng = StageRng::seed_from_u64(700 + seed as u64);
        let (mean, se) = batch_means(&mut m, &mut rng, 100, 100_000);
        assert!(
            (mean - exact).abs() < T99_TWO_SIDED_0_001 * se,
            "{params:?}: simulated {mean} ± {se}, exact {exact} (α = 0.001)"
        );
    }
}

#[test]
fn gilbert_elliott_loss_matches_closed_form() {
    let _machine = machine::not_beside_a_run();
    let cases = [
        GilbertElliottParams {
            p: prob(0.01),
            r: Some(prob(0.3)),
            loss_good: Some(prob(0.02)),
            loss_bad: Some(prob(0.6)),
        },
        GilbertElliottParams { p: prob(0.1), r: None, loss_good: None, loss_bad: None },
        GilbertElliottParams { p: prob(0.002), r: Some(prob(0.05)), loss_good: None, loss_bad: Some(prob(0.9)) },
    ];
    for (seed, params) in cases.into_iter().enumerate() {
        let mut m = GilbertElliott::new(&params).unwrap();
        let exact = m.loss_rate_exact();
        let mut rng = StageRng::seed_from_u64(800 + seed as u64);
        let (mean, se) = batch_means(&mut m, &mut rng, 100, 100_000);
        assert!(
            (mean - exact).abs() < T99_TWO_SIDED_0_001 * se,
            "{params:?}: simulated {mean} ± {se}, exact {exact} (α = 0.001)"
        );
    }
}

/// Independent losses: binomial standard error over 10^7 frames, α = 0.001.
#[test]
fn bernoulli_loss_matches_p() {
    let _machine = machine::not_beside_a_run();
    let p = 0.137;
    let mut m = Bernoulli::new(&BernoulliParams { p: prob(p) }).unwrap();
    let mut rng = StageRng::seed_from_u64(900);
    let n = 10_000_000u64;
    let drops = (0..n).filter(|&i| m.decide(i * FRAME_NS, &mut rng) == Verdict::Drop).count();
    let se = (p * (1.0 - p) / n as f64).sqrt();
    let rate = drops as f64 / n as f64;
    assert!((rate - p).abs() < Z_TWO_SIDED_0_001 * se, "{rate} vs {p} ± {se}");
}

// -------------------------------------------------------------------- outage

fn outage_time(p_start: f64, min_ms: f64, max_ms: f64, cooldown_ms: f64) -> OutageParams {
    OutageParams::time(p_start, min_ms, max_ms, cooldown_ms).unwrap()
}

/// The lost fraction over renewal cycles (window opening to window opening,
/// frames before the first opening left out), with the ratio estimator's
/// delta-method standard error `s(D − r̂N) / (N̄ √cycles)`.
fn outage_cycles(params: &OutageParams, seed: u64, frames: u64, interval_ns: u64) -> (f64, f64, usize) {
    let mut m = Outage::new(params).unwrap();
    let mut rng = StageRng::seed_from_u64(seed);
    let mut cycles: Vec<(f64, f64)> = Vec::new();
    let (mut dropped, mut length) = (0u64, 0u64);
    let mut opened = 0u64;
    for i in 0..frames {
        let v = m.decide(i * interval_ns, &mut rng);
        let count = m.windows().count;
        if count > opened {
            if opened > 0 {
                cycles.push((dropped as f64, length as f64));
            }
            opened = count;
            (dropped, length) = (0, 0);
        }
        if opened > 0 {
            dropped += (v == Verdict::Drop) as u64;
            length += 1;
        }
    }
    let n = cycles.len() as f64;
    let ratio = cycles.iter().map(|c| c.0).sum::<f64>() / cycles.iter().map(|c| c.1).sum::<f64>();
    let mean_length = cycles.iter().map(|c| c.1).sum::<f64>() / n;
    let s2 = cycles.iter().map(|&(d, l)| (d - ratio * l).powi(2)).sum::<f64>() / (n - 1.0);
    (ratio, s2.sqrt() / (mean_length * n.sqrt()), cycles.len())
}

/// The CLM presets at 1 kHz (10^8 frames, 10^4–10^5 cycles each) and two
/// fine-grained cases where the frame grid matters (window lengths of a few
/// frames, `p_start < 1`; 10^7 frames): lost fraction against
/// `loss_rate_approx` at α = 0.001.
#[test]
fn outage_lost_fraction_matches_formula() {
    let _machine = machine::not_beside_a_run();
    let cases = [
        ("CLM-1", outage_time(1.0, 0.0, 3000.0, 8500.0), FRAME_NS, 100_000_000),
        ("CLM-2", outage_time(1.0, 0.0, 1000.0, 1000.0), FRAME_NS, 100_000_000),
        ("CLM-3", outage_time(1.0, 0.0, 2000.0, 1000.0), FRAME_NS, 100_000_000),
        ("short windows", outage_time(0.3, 0.3, 7.3, 2.1), FRAME_NS, 10_000_000),
        ("517 Hz", outage_time(0.05, 1.0, 12.0, 4.0), 1_934_236, 10_000_000),
    ];
    for (seed, (name, params, interval_ns, frames)) in cases.into_iter().enumerate() {
        let exact = Outage::new(&params).unwrap().loss_rate_approx(interval_ns).unwrap();
        let (ratio, se, cycles) = outage_cycles(&params, 1000 + seed as u64, frames, interval_ns);
        println!("{name}: exact lost fraction {exact:.6}, simulated {ratio:.6} ± {se:.6} over {cycles} cycles");
        assert!(
            (ratio - exact).abs() < Z_TWO_SIDED_0_001 * se,
            "{name}: simulated {ratio} ± {se} over {cycles} cycles, exact {exact} (α = 0.001)"
        );
    }
}

#[test]
fn outage_frames_lost_fraction_matches_formula() {
    let _machine = machine::not_beside_a_run();
    let params = OutageParams::frames(0.02, 1, 30, 50).unwrap();
    let exact = Outage::new(&params).unwrap().loss_rate_approx(FRAME_NS).unwrap();
    assert!((exact - 15.5 / (15.5 + 50.0 + 49.0)).abs() < 1e-15);
    let (ratio, se, cycles) = outage_cycles(&params, 1100, 10_000_000, FRAME_NS);
    assert!(
        (ratio - exact).abs() < Z_TWO_SIDED_0_001 * se,
        "simulated {ratio} ± {se} over {cycles} cycles, exact {exact} (α = 0.001)"
    );
}
