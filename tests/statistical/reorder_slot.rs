//! `reorder` (docs/spec.md §3.10) and `slot` (§3.11) against their laws,
//! fixed seeds, α = 0.001.

use super::Z_TWO_SIDED_0_001;
use crate::common::machine;
use netfi::model::{Model, Reorder, ReorderParams, Slot, SlotParams, StageRng, Verdict};
use rand::SeedableRng;

fn delay_of(v: Verdict) -> u64 {
    match v {
        Verdict::Pass { delay_ns } => delay_ns,
        other => panic!("only passes, got {other:?}"),
    }
}

/// The frames between picks are `gap − 1 + G`, `G` geometric on {1, 2, …}
/// with mean `1/p`: the cycle lengths' mean matches `gap − 1 + 1/p` and no
/// cycle is shorter than `gap` (cycles are independent: the renewal
/// structure, so the standard error is the sample's).
#[test]
fn reorder_cycles_follow_the_gap_rule() {
    let _machine = machine::not_beside_a_run();
    for (seed, p, gap) in [(500, 0.25, 5u64), (501, 0.6, 1), (502, 0.05, 20)] {
        let mut m = Reorder::new(&ReorderParams::new(p, gap, 10.0).unwrap()).unwrap();
        let mut rng = StageRng::seed_from_u64(seed);
        let (mut cycles, mut since) = (Vec::new(), 0u64);
        for t in 0..2_000_000u64 {
            since += 1;
            if delay_of(m.decide(t, &mut rng)) == 0 {
                cycles.push(since as f64);
                since = 0;
            }
        }
        assert!(cycles.iter().all(|&c| c >= gap as f64), "a cycle shorter than the gap");
        let n = cycles.len() as f64;
        let mean = cycles.iter().sum::<f64>() / n;
        let sd = (cycles.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let exact = (gap - 1) as f64 + 1.0 / p;
        eprintln!("reorder p {p} gap {gap}: cycle mean {mean:.4} vs {exact:.4} (se {:.4})", sd / n.sqrt());
        assert!((mean - exact).abs() < Z_TWO_SIDED_0_001 * sd / n.sqrt(), "p {p} gap {gap}: {mean} vs {exact}");
        // Geometric excess: sd = √(1 − p)/p. The sample sd's relative
        // standard error is about √((κ − 1)/4n) ≤ 0.007 here (κ ≈ 9, n ≥
        // 51,000 cycles): 5% is more than 7 of them.
        let sd_exact = (1.0 - p).sqrt() / p;
        assert!((sd / sd_exact - 1.0).abs() < 0.05, "p {p}: cycle sd {sd} vs {sd_exact}");
    }
}

/// Saturated slots (frames arrive far faster than slots release them):
/// every slot releases exactly `packets` frames, and the spacings of
/// successive release instants are `U[min, max)` (mean within 3.29 standard
/// errors, `(max − min)/√12` each, and within the bounds).
#[test]
fn saturated_slots_release_packets_per_uniform_spacing() {
    let _machine = machine::not_beside_a_run();
    let (min_ms, max_ms, packets) = (2.0, 6.0, 4u64);
    let mut s = Slot::new(&SlotParams::new(min_ms, max_ms, Some(packets), None).unwrap()).unwrap();
    let mut rng = StageRng::seed_from_u64(510);
    // A frame every 10 µs: 400 per mean slot, 100 times what a slot takes.
    let mut releases = Vec::new();
    for i in 0..400_000u64 {
        let t = i * 10_000;
        releases.push(t + delay_of(s.decide(t, &mut rng)));
    }
    let mut bursts: Vec<(u64, u64)> = Vec::new();
    for r in releases {
        match bursts.last_mut() {
            Some((at, n)) if *at == r => *n += 1,
            _ => bursts.push((r, 1)),
        }
    }
    bursts.pop(); // the last may be partial
    assert!(bursts.iter().skip(1).all(|&(_, n)| n == packets), "a saturated slot takes exactly `packets`");
    let gaps: Vec<f64> = bursts.windows(2).skip(1).map(|w| (w[1].0 - w[0].0) as f64 / 1e6).collect();
    assert!(gaps.iter().all(|&g| (min_ms..=max_ms).contains(&g)));
    let n = gaps.len() as f64;
    let mean = gaps.iter().sum::<f64>() / n;
    let se = (max_ms - min_ms) / 12f64.sqrt() / n.sqrt();
    eprintln!("slot: spacing mean {mean:.4} ms vs {} (se {se:.4}, {n} slots)", (min_ms + max_ms) / 2.0);
    assert!((mean - (min_ms + max_ms) / 2.0).abs() < Z_TWO_SIDED_0_001 * se);
}
