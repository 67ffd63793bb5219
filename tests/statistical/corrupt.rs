//! `corrupt` (docs/spec.md §3.9) against its law, through the checker, at
//! α = 0.001 with a fixed seed: the fraction of frames corrupted is `p`, each
//! flip's bit is uniform over the 992 bits (chi-square over the 124 bytes),
//! and the checksum catches exactly `44/124` of single flips.

use netfi::check::{self, Arrivals};
use netfi::frame::{checksum_covers, CHECKSUM_COVERED_BYTES};
use netfi::model::{Corrupt, CorruptParams, Model, StageRng, Verdict};
use netfi::scenario::{parse_str, Scenario};
use rand::SeedableRng;

/// `z` with `P(|Z| > z) = 0.001`.
const Z_TWO_SIDED_0_001: f64 = 3.290_527;
/// The chi-square quantile at 1 − 0.001 for 123 degrees of freedom
/// (Wilson–Hilferty, within 0.1% here).
const CHI2_123_0_001: f64 = 177.26;

#[test]
fn corrupt_rate_bytes_and_checksum_catches() {
    // The flipped bits themselves: uniform over the bytes.
    let mut c = Corrupt::new(&CorruptParams::new(1.0).unwrap()).unwrap();
    let mut rng = StageRng::seed_from_u64(400);
    let n = 1_240_000u64;
    let mut per_byte = [0u64; 124];
    for t in 0..n {
        if let Verdict::Corrupt { bit } = c.decide(t, &mut rng) {
            per_byte[usize::from(bit / 8)] += 1;
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
