//! The study presets at 10^7 frames through the whole core (scenario, injector,
//! release queue, checker): realized values against each model's exact
//! long-run value.

use crate::common::machine;
use netfi::check::{self, Arrivals};
use netfi::scenario::Scenario;

const FRAMES: u64 = 10_000_000;

fn check_preset(name: &str, seed: u64) -> check::CheckReport {
    let spec = netfi::load::resolve(name).unwrap();
    check::run(Scenario::new(&spec, seed).unwrap(), &Arrivals::Rate { frames: FRAMES, rate_hz: 1000.0 }, 1 << 20, |_| {})
}

/// PLM and CLM: the exact long-run loss lies inside the reported 95% interval.
/// Seeds are fixed; with a correct interval each check fails for 5% of seeds,
/// so these seeds are simply the first ones (1, 2, 3, …), not chosen.
#[test]
fn loss_presets_realize_their_exact_long_run_loss() {
    let _machine = machine::not_beside_a_run();
    for (i, name) in ["PLM-1", "PLM-2", "PLM-3", "CLM-1", "CLM-2", "CLM-3"].iter().enumerate() {
        let r = check_preset(name, i as u64 + 1);
        let exact = r.stages[0].loss_rate_model.expect("loss models have an exact value");
        let [lo, hi] = r.loss_rate_ci95;
        println!("{name}: realized {:.5} [{lo:.5}, {hi:.5}], exact {exact:.5}", r.loss_rate);
        assert!(lo <= exact && exact <= hi, "{name}: exact {exact} outside [{lo}, {hi}] (realized {})", r.loss_rate);
        // The interval is informative: about a percent wide at most (the CLM
        // presets renew only every 1.5–10 s, so 10^7 frames hold ~5000 cycles).
        assert!(hi - lo < 0.02, "{name}: interval [{lo}, {hi}] too wide to be useful");
        assert_eq!(r.delivered + r.dropped.values().sum::<u64>(), FRAMES);
    }
}

/// The RFC 4737 reordered fraction of i.i.d. delays D at 1 frame per ms: frame
/// i arrives in order iff no later frame j overtakes it, i.e.
/// D_j + (j − i) > D_i for every j > i, so
/// P(in order) = ∫ Π_{k≥1} (1 − F(x − k)) dF(x), computed on a fine grid.
fn reordered_fraction_exact(d: &netfi::model::Delay) -> f64 {
    let (lo, hi) = (d.quantile_ms(1e-12), d.quantile_ms(1.0 - 1e-12));
    let steps = 200_000;
    let h = (hi - lo) / steps as f64;
    let mut in_order = 0.0;
    for m in 0..steps {
        let (a, b) = (lo + m as f64 * h, lo + (m + 1) as f64 * h);
        let x = 0.5 * (a + b);
        let mut prod = 1.0;
        let mut k = 1.0;
        while x - k > lo && prod > 0.0 {
            prod *= 1.0 - d.cdf_ms(x - k);
            k += 1.0;
        }
        in_order += (d.cdf_ms(b) - d.cdf_ms(a)) * prod;
    }
    1.0 - in_order
}

/// DLM: the mean injected delay within 0.5% of min + Σ w/λ, no loss, and the
/// reordered fraction as the law of the delays implies.
#[test]
fn delay_presets_realize_their_mean() {
    let _machine = machine::not_beside_a_run();
    for (i, name) in ["DLM-1", "DLM-2", "DLM-3"].iter().enumerate() {
        let r = check_preset(name, i as u64 + 11);
        let exact = r.stages[0].delay_ms_model.unwrap();
        let rel = (r.delay_ms.mean - exact).abs() / exact;
        println!("{name}: mean {:.3} ms, exact {exact:.3} ms, rel err {rel:.2e}", r.delay_ms.mean);
        assert!(rel < 0.005, "{name}: mean {} vs {exact}", r.delay_ms.mean);
        assert_eq!(r.delivered, FRAMES);
        let spec = netfi::load::resolve(name).unwrap();
        let netfi::model::AnyModel::Delay(d) = spec.phases[0].stages[0].model.build().unwrap() else { unreachable!() };
        let expected = reordered_fraction_exact(&d);
        println!("{name}: reordered {:.4}, expected {expected:.4}", r.reordered_fraction);
        // Indicators of neighbouring frames are correlated; 10^7 frames still
        // pin the fraction to well under 0.002 (observed spread across seeds
        // is ~1e-4).
        assert!((r.reordered_fraction - expected).abs() < 0.002, "{name}: reordered {} vs {expected}", r.reordered_fraction);
    }
}
