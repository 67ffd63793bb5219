//! The loss interval over many seeds: a 95 % interval must hold the model's
//! long-run loss for at least 95 % of the runs, for every model the fitter
//! can produce — the study's presets, and two-state `ge_lomax` chains down
//! to the fitter's shape bound α = 1.5, whose burst lengths have infinite
//! variance (docs/spec.md §5).
//!
//! Seeds are fixed (1, 2, 3, …, not chosen). With `S` runs the number of
//! intervals holding the model's loss is binomial; with a true coverage of
//! at least 95 % it falls below the bound asserted here with probability
//! at most 0.001, and each end misses more often than asserted with
//! probability at most 0.001 (a true miss rate of at most 2.5 % a side).
//! Batch means alone (no allowance for what a run cannot see) held the
//! fitted α = 1.52 chain's loss in 157 of 200 runs of 50 000 frames, most
//! misses above the interval.

use crate::common::machine;
use netfi::check::{self, Arrivals};
use netfi::model::{GeLomaxParams, ModelSpec};
use netfi::scenario::{Scenario, ScenarioSpec, StageSpec};

/// Runs per model and length.
const SEEDS: u64 = 200;

/// `P(X ≤ k)` for `X` binomial with `n` trials of probability `p`.
fn binomial_cdf(k: u64, n: u64, p: f64) -> f64 {
    let mut pmf = (1.0 - p).powi(n as i32);
    let mut cdf = pmf;
    for i in 0..k {
        pmf *= (n - i) as f64 / (i + 1) as f64 * p / (1.0 - p);
        cdf += pmf;
    }
    cdf
}

/// The fewest of `n` intervals of coverage `p` that may hold the value:
/// fewer happens with probability at most 0.001.
fn fewest_covering(n: u64, p: f64) -> u64 {
    (0..=n).take_while(|&c| c == 0 || binomial_cdf(c - 1, n, p) <= 0.001).last().unwrap()
}

/// The most of `n` intervals missing on one side, at a miss rate of `p`
/// there: more happens with probability at most 0.001.
fn most_missing(n: u64, p: f64) -> u64 {
    (0..=n).find(|&m| 1.0 - binomial_cdf(m, n, p) <= 0.001).unwrap()
}

fn ge_lomax(alpha: f64, lambda: [f64; 2]) -> ModelSpec {
    ModelSpec::GeLomax(GeLomaxParams::two_state(netfi::model::presets::STUDY_TRANSITION, [alpha; 2], lambda))
}

#[test]
fn the_loss_interval_holds_the_models_loss_at_its_stated_level() {
    let _machine = machine::not_beside_a_run();
    let preset = |name: &str| netfi::load::resolve(name).unwrap().phases[0].stages[0].model.clone();
    let models = [
        ("PLM-2", preset("PLM-2")),
        ("PLM-3", preset("PLM-3")),
        // `netfi fit loss 30% --run-length 3.55` and `--run-length 3.0`.
        ("fit 30% run 3.55 (α 1.52)", ge_lomax(1.522309, [0.1922291, 0.7689164])),
        ("fit 30% run 3.0 (α 1.76)", ge_lomax(1.761268, [0.2968424, 1.187369])),
        // The fitter's shape bound, at a low loss.
        ("α 1.5, loss 2.3%", ge_lomax(1.5, [0.02, 0.08])),
    ];
    let (at_least, at_most_a_side) = (fewest_covering(SEEDS, 0.95), most_missing(SEEDS, 0.025));
    let mut failures = Vec::new();
    for frames in [10_000u64, 50_000] {
        for (name, model) in &models {
            let spec = ScenarioSpec::single(*name, vec![StageSpec { name: None, preset: None, model: model.clone() }]);
            // Runs whose interval lies above the model's loss, and below it.
            let (mut below, mut above) = (0, 0);
            let mut exact = 0.0;
            for seed in 1..=SEEDS {
                let r = check::run(Scenario::new(&spec, seed).unwrap(), &Arrivals::Rate { frames, rate_hz: 1000.0 }, 1 << 16, |_| {});
                exact = r.stages[0].loss_rate_model.unwrap();
                let [lo, hi] = r.loss_rate_ci95;
                below += u64::from(exact < lo);
                above += u64::from(exact > hi);
            }
            let covered = SEEDS - below - above;
            println!("{name}, {frames} frames: model {exact:.5} held by {covered} of {SEEDS} intervals ({below} lay above it, {above} below it)");
            if covered < at_least || below > at_most_a_side || above > at_most_a_side {
                failures.push(format!("{name}, {frames} frames: {covered} covered (at least {at_least}), {below} + {above} missed (at most {at_most_a_side} a side)"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn the_binomial_bounds_are_those_of_the_law() {
    // 200 runs at 95 %: 190 expected, sd 3.08 (P(X ≤ 178) = 0.00048,
    // P(X ≤ 179) = 0.0012); at 2.5 %: 5 expected (P(X > 13) = 0.00057).
    assert_eq!((fewest_covering(200, 0.95), most_missing(200, 0.025)), (179, 13));
    assert!((binomial_cdf(200, 200, 0.3) - 1.0).abs() < 1e-12);
}
