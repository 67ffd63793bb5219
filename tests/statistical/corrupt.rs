//! `corrupt` (docs/spec.md §3.9) against its law, through the checker, at
//! α = 0.001 with a fixed seed: the fraction of frames corrupted is `p`, each
//! flip's bit is uniform over the 992 bits (chi-square over the 124 bytes),
//! and the checksum catches exactly `44/124` of single flips.

use super::Z_TWO_SIDED_0_001;
use crate::common::machine;
use netfi::check::{self, Arrivals};
use netfi::frame::{checksum_covers, CHECKSUM_COVERED_BYTES};
use netfi::model::{Corrupt, CorruptParams, Model, StageRng, Verdict};
use netfi::scenario::{parse_str, Scenario};
use rand::SeedableRng;

/// The chi-square quantile at 1 − 0.001 for 123 degrees of freedom
/// (Wilson–Hilferty, within 0.1% here).
const CHI2_123_0_001: f64 = 177.26;

#[test]
fn corrupt_rate_bytes_and_checksum_catches() {
    let _machine = machine::not_beside_a_run();
    // The flipped bits themselves: uniform over the bytes.
    let mut c = Corrupt::new(&CorruptParams::new(1.0).unwrap()).unwrap();
    let mut rng = StageRng::seed_from_u64(400);
    let n = 1_240_000u64;
    let mut per_byte = [0u64; 124];
    for t in 0..n {
        if let Verdict::Corrupt(h) = c.decide(t, &mut rng) {
            per_byte[usize::from(h.bits()[0] / 8)] += 1;
        }
    }
    let expected = n as f64 / 124.0;
    let chi2: f64 = per_byte.iter().map(|&o| (o as f64 - expected).powi(2) / expected).sum();
    eprintln!("corrupt: chi-square over bytes {chi2:.1} (critical {CHI2_123_0_001}, 123 df)");
    assert!(chi2 < CHI2_123_0_001, "bytes not uniform: chi-square {chi2}");
    assert_eq!((0..124).filter(|&b| checksum_covers(b)).count(), CHECKSUM_COVERED_BYTES);

    // Through the checker: the rate and what the checksum catches.
    let (p, frames) = (0.02, 2_000_000u64);
    let text = format!("[[stage]]\nmodel = \"corrupt\"\np = {p}\n");
    let sc = Scenario::new(&parse_str(&text, "s.toml", "s").unwrap(), 401).unwrap();
    let r = check::run(sc, &Arrivals::Rate { frames, rate_hz: 1000.0 }, 1 << 16, |_| {});
    let c = r.corruption.expect("a corrupting scenario reports corruption");
    assert_eq!(c.caught + c.passed, c.corrupted);
    let rate = c.corrupted as f64 / frames as f64;
    let se = (p * (1.0 - p) / frames as f64).sqrt();
    eprintln!("corrupt: {rate:.6} of frames vs {p} (se {se:.6})");
    assert!((rate - p).abs() < Z_TWO_SIDED_0_001 * se);
    let q = 44.0 / 124.0;
    let caught = c.caught as f64 / c.corrupted as f64;
    let se = (q * (1.0 - q) / c.corrupted as f64).sqrt();
    eprintln!("corrupt: checksum caught {caught:.5} vs 44/124 = {q:.5} (se {se:.5})");
    assert!((caught - q).abs() < Z_TWO_SIDED_0_001 * se);
    assert_eq!(r.stages[0].caught_fraction_model, Some(q));
}

/// The chi-square quantile at 1 − 0.001 for 4 and 7 degrees of freedom.
const CHI2_4_0_001: f64 = 18.467;
const CHI2_7_0_001: f64 = 24.322;

/// `ber_per_byte = q`: the number of bytes in error per frame is
/// min(Binomial(124, q), 4) (chi-square over 0, 1, 2, 3, ≥ 4 against the
/// exact law), the flips per frame have the model's exact mean (z-test with
/// the binomial's variance, an upper bound for the truncated one), and the
/// bit within a byte is uniform (chi-square over 8).
#[test]
fn corrupt_per_byte_realizes_its_binomial_law() {
    let _machine = machine::not_beside_a_run();
    let q = 0.01f64;
    let mut c = Corrupt::new(&CorruptParams::per_byte(q).unwrap()).unwrap();
    let mut rng = StageRng::seed_from_u64(402);
    let n = 400_000u64;
    let (mut per_k, mut per_bit, mut flips) = ([0u64; 5], [0u64; 8], 0u64);
    for t in 0..n {
        let k = match c.decide(t, &mut rng) {
            Verdict::Corrupt(h) => {
                for &b in h.bits() {
                    per_bit[usize::from(b % 8)] += 1;
                }
                h.bits().len()
            }
            Verdict::PASS => 0,
            other => panic!("{other:?}"),
        };
        per_k[k] += 1;
        flips += k as u64;
    }
    // The exact law of min(K, 4), K ~ Binomial(124, q).
    let pmf = |k: i32| {
        let choose: f64 = (1..=k).map(|i| f64::from(124 - k + i) / f64::from(i)).product();
        choose * q.powi(k) * (1.0 - q).powi(124 - k)
    };
    let law = [pmf(0), pmf(1), pmf(2), pmf(3), 1.0 - (0..4).map(pmf).sum::<f64>()];
    let chi2: f64 = per_k.iter().zip(law).map(|(&o, p)| (o as f64 - n as f64 * p).powi(2) / (n as f64 * p)).sum();
    eprintln!("corrupt per byte: bytes in error {per_k:?}, chi-square {chi2:.2} (critical {CHI2_4_0_001}, 4 df)");
    assert!(chi2 < CHI2_4_0_001, "min(K, 4) off its law: chi-square {chi2}");
    assert!((1.0 - law[0] - c.corrupt_rate_exact()).abs() < 1e-12);
    let mean = c.flips_per_frame_exact();
    let se = (124.0 * q * (1.0 - q) / n as f64).sqrt();
    let realized = flips as f64 / n as f64;
    eprintln!("corrupt per byte: {realized:.5} flips per frame vs {mean:.5} (se ≤ {se:.5})");
    assert!((realized - mean).abs() < Z_TWO_SIDED_0_001 * se);
    let expected = flips as f64 / 8.0;
    let chi2: f64 = per_bit.iter().map(|&o| (o as f64 - expected).powi(2) / expected).sum();
    assert!(chi2 < CHI2_7_0_001, "bit within the byte not uniform: chi-square {chi2}");

    // Through the checker: the fraction of frames corrupted is
    // 1 − (1 − q)^124, and every corrupted frame is caught or passes.
    let (q, frames) = (0.0005f64, 1_000_000u64);
    let text = format!("[[stage]]\nmodel = \"corrupt\"\nber_per_byte = {q}\n");
    let sc = Scenario::new(&parse_str(&text, "s.toml", "s").unwrap(), 403).unwrap();
    let r = check::run(sc, &Arrivals::Rate { frames, rate_hz: 1000.0 }, 1 << 16, |_| {});
    let cs = r.corruption.expect("a corrupting scenario reports corruption");
    assert_eq!(cs.caught + cs.passed, cs.corrupted);
    let p = 1.0 - (1.0 - q).powi(124);
    let rate = cs.corrupted as f64 / frames as f64;
    let se = (p * (1.0 - p) / frames as f64).sqrt();
    eprintln!("corrupt per byte: {rate:.6} of frames vs {p:.6} (se {se:.6})");
    assert!((rate - p).abs() < Z_TWO_SIDED_0_001 * se);
    assert_eq!(r.stages[0].corrupt_rate_model, Some(p).map(|_| c_rate(q)));
    assert_eq!(r.stages[0].caught_fraction_model, None, "no closed form with several flips");
}

fn c_rate(q: f64) -> f64 {
    Corrupt::new(&CorruptParams::per_byte(q).unwrap()).unwrap().corrupt_rate_exact()
}
