//! `duplicate` (docs/spec.md §3.8) against its law, through the injector, at
//! α = 0.001 with fixed seeds.

use super::{FRAME_NS, Z_TWO_SIDED_0_001};
use crate::common::machine;

/// `duplicate` (docs/spec.md §3.8) in a pipeline, through the injector:
/// copies per frame match `p`, and the copies meet the later loss stage as
/// fresh frames (their loss fraction matches its `p`). Both are proportions
/// of independent trials: binomial standard errors, α = 0.001 two-sided.
#[test]
fn duplicate_rate_and_copies_meet_later_stages() {
    use netfi::injector::Injector;
    use netfi::scenario::{parse_str, Scenario};
    let _machine = machine::not_beside_a_run();
    let (p_dup, p_loss, n) = (0.05, 0.2, 2_000_000u64);
    let text = format!(
        "[[stage]]\nmodel = \"duplicate\"\np = {p_dup}\n[[stage]]\nmodel = \"bernoulli\"\np = {p_loss}\n"
    );
    let sc = Scenario::new(&parse_str(&text, "s.toml", "s").unwrap(), 77).unwrap();
    let mut inj: Injector<()> = Injector::new(sc, 1 << 16);
    let mut copies_passed = 0u64;
    for i in 0..n {
        let t = i * FRAME_NS;
        while inj.pop_due(t).is_some() {}
        copies_passed += u64::from(inj.ingress(t, ()).copies);
    }
    while inj.pop_due(u64::MAX).is_some() {}
    let c = inj.counts();
    assert!(c.balanced() && c.held == 0, "{c:?}");
    let rate = c.duplicated as f64 / n as f64;
    let se = (p_dup * (1.0 - p_dup) / n as f64).sqrt();
    eprintln!("duplicate: {rate:.6} copies per frame vs {p_dup} (se {se:.6})");
    assert!((rate - p_dup).abs() < Z_TWO_SIDED_0_001 * se, "copies per frame {rate} vs {p_dup}");
    let copy_loss = 1.0 - copies_passed as f64 / c.duplicated as f64;
    let se = (p_loss * (1.0 - p_loss) / c.duplicated as f64).sqrt();
    eprintln!("duplicate: copies lost {copy_loss:.5} vs {p_loss} (se {se:.5})");
    assert!((copy_loss - p_loss).abs() < Z_TWO_SIDED_0_001 * se, "copies lost {copy_loss} vs {p_loss}");
    assert_eq!(c.released, c.entered + c.duplicated - c.dropped());
}
