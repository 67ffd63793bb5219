//! The `rate` link under Poisson arrivals against queueing theory: an M/D/1
//! queue (docs/spec.md §3.12). With arrivals at rate λ and a fixed service
//! time S (a frame's bits over the link's rate), ρ = λS < 1, the mean time
//! at the link is S + ρS / (2(1 − ρ)) (Pollaczek–Khinchine), and a frame
//! finds the link idle (waits 0) with probability 1 − ρ.
//!
//! Successive delays are strongly correlated, so the confidence intervals
//! are batch means: 200 batches of 10^4 frames, each batch far longer than
//! a busy period (mean S/(1 − ρ) = 3.3 S here); the bound is 4.5 standard
//! errors of the batch means (two-sided α ≈ 7·10^-6 under normality).

use crate::common::machine;
use netfi::model::{Model, Rate, RateParams, StageRng, Verdict};
use rand::SeedableRng;
use rand_distr::{Distribution, Exp};

const BATCHES: usize = 200;
const PER_BATCH: usize = 10_000;

/// Mean and standard error of batch means.
fn batch_mean(values: &[f64]) -> (f64, f64) {
    let means: Vec<f64> = values.chunks(PER_BATCH).map(|c| c.iter().sum::<f64>() / c.len() as f64).collect();
    let m = means.iter().sum::<f64>() / means.len() as f64;
    let var = means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (means.len() - 1) as f64;
    (m, (var / means.len() as f64).sqrt())
}

#[test]
fn a_rate_link_under_poisson_arrivals_is_an_md1_queue() {
    let _machine = machine::not_beside_a_run();
    // 1 Mbit/s, 124-byte frames: S = 992 µs.
    let service_ns = 992_000.0;
    for (rho, seed) in [(0.5, 71u64), (0.7, 72)] {
        let mut link = Rate::new(&RateParams { queue_packets: Some(1 << 20), ..RateParams::new(1e6) }).unwrap();
        let mut rng = StageRng::seed_from_u64(seed);
        let gaps = Exp::new(rho / service_ns).unwrap();
        let mut t = 0f64;
        let mut delays = Vec::with_capacity(BATCHES * PER_BATCH);
        let mut idle = Vec::with_capacity(BATCHES * PER_BATCH);
        for _ in 0..BATCHES * PER_BATCH {
            t += gaps.sample(&mut rng);
            match link.decide(t as u64, &mut rng) {
                Verdict::Pass { delay_ns } => {
                    delays.push(delay_ns as f64);
                    idle.push(if delay_ns == 992_000 { 1.0 } else { 0.0 });
                }
                v => panic!("{v:?}"),
            }
        }
        let want = service_ns + rho * service_ns / (2.0 * (1.0 - rho));
        let (mean, se) = batch_mean(&delays);
        // Rounding each departure up to the ns adds under 1 ns.
        assert!((mean - want).abs() < 4.5 * se + 1.0, "ρ {rho}: mean {mean} ns, M/D/1 {want} ns, se {se}");
        let (p_idle, se_idle) = batch_mean(&idle);
        assert!((p_idle - (1.0 - rho)).abs() < 4.5 * se_idle, "ρ {rho}: idle {p_idle}, M/D/1 {}, se {se_idle}", 1.0 - rho);
        assert!(se < 0.01 * want, "ρ {rho}: the test is too weak to fail: se {se}");
    }
}
