//! Differential evolution (Storn & Price 1997), strategy `best/1/bin` with a
//! dithered mutation factor, over a box.
//!
//! Contract: pure and seeded. The search never evaluates the objective
//! itself; it hands each generation's candidates to the caller's `evaluate`
//! and reads back one value per candidate, in order. A caller may evaluate a
//! generation in parallel; as long as the objective is a deterministic
//! function of the candidate (common random numbers, or a closed form), the
//! result is the same for any evaluation order and any number of threads.
//!
//! Per generation, for each member `i`: a mutant `best + F·(x_r1 − x_r2)`
//! with `r1 ≠ r2 ≠ i` drawn at random and `F ~ U[0.5, 1)` drawn once per
//! generation (dither, as SciPy's default); binomial crossover with rate
//! `CR`, one coordinate always from the mutant; coordinates outside the box
//! are reflected back into it. The trial replaces member `i` if it is no
//! worse. The search stops when the best value is at or below `tolerance`,
//! when the population has collapsed (every value within `1e-15` of the best
//! and every coordinate within `1e-12` of the box width), or after
//! `max_generations`.

use crate::model::StageRng;
use rand::{RngExt, SeedableRng};

/// Settings of one search.
#[derive(Debug, Clone, PartialEq)]
pub struct DeConfig {
    /// Candidates per generation; 0 picks `max(10, 10 · dims)`.
    pub population: usize,
    /// The most generations after the initial one.
    pub max_generations: usize,
    /// Crossover rate `CR` in `[0, 1]`.
    pub crossover: f64,
    /// Stop as soon as the best objective value is at or below this.
    pub tolerance: f64,
}

impl Default for DeConfig {
    fn default() -> Self {
        DeConfig { population: 0, max_generations: 400, crossover: 0.7, tolerance: 0.0 }
    }
}

/// The outcome of a search.
#[derive(Debug, Clone, PartialEq)]
pub struct DeResult {
    /// The best candidate found.
    pub best: Vec<f64>,
    /// Its objective value.
    pub value: f64,
    /// Generations run after the initial one.
    pub generations: usize,
    /// Objective evaluations in all.
    pub evaluations: usize,
}

/// Minimizes over the box `bounds` (`(low, high)` per coordinate, `low ≤
/// high`). `evaluate` receives a generation's candidates and returns their
/// values (NaN counts as +∞); `on_generation(generation, best_value)` is
/// called after each generation.
///
/// # Panics
/// If `bounds` is empty or has a coordinate with `low > high` or a bound that
/// is not finite, or if `evaluate` returns the wrong number of values: those
/// are programming errors of the caller, not bad input.
pub fn minimize(
    bounds: &[(f64, f64)],
    config: &DeConfig,
    seed: u64,
    evaluate: &mut dyn FnMut(&[Vec<f64>]) -> Vec<f64>,
    on_generation: &mut dyn FnMut(usize, f64),
) -> DeResult {
    let dims = bounds.len();
    assert!(dims > 0, "a search needs at least one coordinate");
    for &(lo, hi) in bounds {
        assert!(lo.is_finite() && hi.is_finite() && lo <= hi, "bad bounds ({lo}, {hi})");
    }
    let np = if config.population == 0 { (10 * dims).max(10) } else { config.population.max(4) };
    let mut rng = StageRng::seed_from_u64(seed);

    let mut population: Vec<Vec<f64>> =
        (0..np).map(|_| bounds.iter().map(|&(lo, hi)| lo + rng.random::<f64>() * (hi - lo)).collect()).collect();
    let mut values = checked(evaluate(&population), np);
    let mut evaluations = np;
    let mut best = argmin(&values);
    let mut generations = 0;

    while generations < config.max_generations
        && values[best] > config.tolerance
        && !collapsed(&population, &values, best, bounds)
    {
        let f: f64 = 0.5 + 0.5 * rng.random::<f64>();
        let trials: Vec<Vec<f64>> = (0..np)
            .map(|i| {
                let (r1, r2) = two_others(&mut rng, np, i);
                let forced = rng.random_range(0..dims);
                (0..dims)
                    .map(|j| {
                        let take = j == forced || rng.random::<f64>() < config.crossover;
                        if !take {
                            return population[i][j];
                        }
                        let v = population[best][j] + f * (population[r1][j] - population[r2][j]);
                        reflect(v, bounds[j], &mut rng)
                    })
                    .collect()
            })
            .collect();
        let trial_values = checked(evaluate(&trials), np);
        evaluations += np;
        for (i, (t, v)) in trials.into_iter().zip(trial_values).enumerate() {
            if v <= values[i] {
                population[i] = t;
                values[i] = v;
            }
        }
        best = argmin(&values);
        generations += 1;
        on_generation(generations, values[best]);
    }
    DeResult { best: population[best].clone(), value: values[best], generations, evaluations }
}

/// Polishes a point by Nelder–Mead (reflection 1, expansion 2, contraction
/// 1/2, shrink 1/2), as SciPy polishes its differential evolution: the
/// search finds the basin, the simplex walks to the bottom of it even where
/// the population stagnated. The initial simplex steps 5% of the box width
/// from `start` along each coordinate (inwards); points are clamped to the
/// box. Stops at `tolerance`, when the simplex has shrunk to `1e-14` of the
/// box, or after `max_evaluations`. Returns the best point, its value and the
/// evaluations used. Pure: one candidate per call of `evaluate`.
pub fn polish(
    bounds: &[(f64, f64)],
    start: &[f64],
    start_value: f64,
    tolerance: f64,
    max_evaluations: usize,
    evaluate: &mut dyn FnMut(&[Vec<f64>]) -> Vec<f64>,
) -> (Vec<f64>, f64, usize) {
    let dims = bounds.len();
    let clamp = |x: &mut Vec<f64>| {
        for (v, &(lo, hi)) in x.iter_mut().zip(bounds) {
            *v = v.clamp(lo, hi);
        }
    };
    let mut evaluations = 0;
    let mut eval = |x: &Vec<f64>, evaluations: &mut usize| {
        *evaluations += 1;
        let v = checked(evaluate(std::slice::from_ref(x)), 1)[0];
        v
    };
    let mut simplex: Vec<(Vec<f64>, f64)> = vec![(start.to_vec(), start_value)];
    for (j, &(lo, hi)) in bounds.iter().enumerate() {
        let step = 0.05 * (hi - lo);
        let mut x = start.to_vec();
        x[j] = if x[j] + step <= hi { x[j] + step } else { x[j] - step };
        clamp(&mut x);
        let v = eval(&x, &mut evaluations);
        simplex.push((x, v));
    }
    let centroid = |s: &[(Vec<f64>, f64)]| -> Vec<f64> {
        let n = s.len() - 1;
        (0..dims).map(|j| s[..n].iter().map(|p| p.0[j]).sum::<f64>() / n as f64).collect()
    };
    let along = |c: &[f64], w: &[f64], t: f64| -> Vec<f64> { c.iter().zip(w).map(|(c, w)| c + t * (w - c)).collect() };
    while evaluations < max_evaluations {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        if simplex[0].1 <= tolerance {
            break;
        }
        let small = bounds.iter().enumerate().all(|(j, &(lo, hi))| {
            let width = (hi - lo).max(f64::MIN_POSITIVE);
            simplex.iter().all(|p| (p.0[j] - simplex[0].0[j]).abs() <= 1e-14 * width)
        });
        if small {
            break;
        }
        let c = centroid(&simplex);
        let worst = simplex[dims].clone();
        let mut r = along(&c, &worst.0, -1.0);
        clamp(&mut r);
        let fr = eval(&r, &mut evaluations);
        if fr < simplex[0].1 {
            let mut e = along(&c, &worst.0, -2.0);
            clamp(&mut e);
            let fe = eval(&e, &mut evaluations);
            simplex[dims] = if fe < fr { (e, fe) } else { (r, fr) };
        } else if fr < simplex[dims - 1].1 {
            simplex[dims] = (r, fr);
        } else {
            // Contract towards the better of the worst point and its reflection.
            let (toward, f_toward) = if fr < worst.1 { (r, fr) } else { (worst.0.clone(), worst.1) };
            let k = along(&c, &toward, 0.5);
            let fk = eval(&k, &mut evaluations);
            if fk < f_toward {
                simplex[dims] = (k, fk);
            } else {
                let best = simplex[0].0.clone();
                for p in simplex.iter_mut().skip(1) {
                    p.0 = along(&best, &p.0, 0.5);
                    p.1 = eval(&p.0, &mut evaluations);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (x, v) = simplex.swap_remove(0);
    (x, v, evaluations)
}

fn checked(values: Vec<f64>, n: usize) -> Vec<f64> {
    assert_eq!(values.len(), n, "the evaluator must return one value per candidate");
    values.into_iter().map(|v| if v.is_nan() { f64::INFINITY } else { v }).collect()
}

fn argmin(values: &[f64]) -> usize {
    let mut best = 0;
    for (i, v) in values.iter().enumerate() {
        if *v < values[best] {
            best = i;
        }
    }
    best
}

/// Two distinct indices, both different from `i`.
fn two_others(rng: &mut StageRng, n: usize, i: usize) -> (usize, usize) {
    let r1 = loop {
        let r = rng.random_range(0..n);
        if r != i {
            break r;
        }
    };
    let r2 = loop {
        let r = rng.random_range(0..n);
        if r != i && r != r1 {
            break r;
        }
    };
    (r1, r2)
}

/// A coordinate outside `[lo, hi]` is placed uniformly between the bound it
/// crossed and the middle of the box: it stays inside without piling up on
/// the bound.
fn reflect(v: f64, (lo, hi): (f64, f64), rng: &mut StageRng) -> f64 {
    if v < lo {
        lo + rng.random::<f64>() * (hi - lo) * 0.5
    } else if v > hi {
        hi - rng.random::<f64>() * (hi - lo) * 0.5
    } else {
        v
    }
}

fn collapsed(population: &[Vec<f64>], values: &[f64], best: usize, bounds: &[(f64, f64)]) -> bool {
    let vb = values[best];
    if !values.iter().all(|v| (v - vb).abs() <= 1e-15 * vb.abs().max(1e-300) + 1e-300) {
        return false;
    }
    bounds.iter().enumerate().all(|(j, &(lo, hi))| {
        let width = (hi - lo).max(f64::MIN_POSITIVE);
        population.iter().all(|x| (x[j] - population[best][j]).abs() <= 1e-12 * width)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serial(f: impl Fn(&[f64]) -> f64) -> impl FnMut(&[Vec<f64>]) -> Vec<f64> {
        move |xs: &[Vec<f64>]| xs.iter().map(|x| f(x)).collect()
    }

    #[test]
    fn finds_the_minimum_of_a_shifted_sphere() {
        let mut eval = serial(|x| (x[0] - 1.5).powi(2) + (x[1] + 2.0).powi(2));
        let r = minimize(
            &[(-5.0, 5.0), (-5.0, 5.0)],
            &DeConfig { tolerance: 1e-20, ..DeConfig::default() },
            1,
            &mut eval,
            &mut |_, _| {},
        );
        assert!((r.best[0] - 1.5).abs() < 1e-9 && (r.best[1] + 2.0).abs() < 1e-9, "{r:?}");
        assert!(r.value <= 1e-18);
    }

    #[test]
    fn solves_rosenbrock() {
        let mut eval = serial(|x| 100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2));
        let r = minimize(
            &[(-2.0, 2.0), (-2.0, 2.0)],
            &DeConfig { max_generations: 2000, tolerance: 1e-16, ..DeConfig::default() },
            3,
            &mut eval,
            &mut |_, _| {},
        );
        assert!((r.best[0] - 1.0).abs() < 1e-6 && (r.best[1] - 1.0).abs() < 1e-6, "{r:?}");
    }

    #[test]
    fn same_seed_same_search_and_bounds_hold() {
        let run = |seed| {
            let mut seen = Vec::new();
            let mut eval = |xs: &[Vec<f64>]| {
                for x in xs {
                    assert!((0.0..=1.0).contains(&x[0]), "{x:?} left the box");
                }
                seen.extend(xs.iter().map(|x| x[0]));
                xs.iter().map(|x| (x[0] - 2.0).abs()).collect()
            };
            let r = minimize(
                &[(0.0, 1.0)],
                &DeConfig { max_generations: 30, ..DeConfig::default() },
                seed,
                &mut eval,
                &mut |_, _| {},
            );
            (r, seen)
        };
        let (a, sa) = run(7);
        let (b, sb) = run(7);
        assert_eq!(a, b);
        assert_eq!(sa, sb);
        // The minimum on the box is its upper bound.
        assert!(a.best[0] > 0.999, "{a:?}");
        assert_ne!(run(8).1, sa);
    }

    #[test]
    fn polish_walks_to_the_bottom() {
        let mut eval = serial(|x| (x[0] - 0.123456789).powi(2));
        let (x, v, n) = polish(&[(0.0, 1.0)], &[0.9], 0.776, 1e-24, 500, &mut eval);
        assert!((x[0] - 0.123456789).abs() < 1e-11 && v < 1e-22, "{x:?} {v} after {n}");
        let mut eval = serial(|x| 100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2));
        let (x, _, _) = polish(&[(-2.0, 2.0), (-2.0, 2.0)], &[-1.0, 1.5], 4.25 + 6.25, 1e-20, 5000, &mut eval);
        assert!((x[0] - 1.0).abs() < 1e-6 && (x[1] - 1.0).abs() < 1e-6, "{x:?}");
    }

    #[test]
    fn nan_is_never_preferred() {
        let mut eval = serial(|x| if x[0] < 0.5 { f64::NAN } else { x[0] });
        let r = minimize(
            &[(0.0, 1.0)],
            &DeConfig { max_generations: 100, ..DeConfig::default() },
            2,
            &mut eval,
            &mut |_, _| {},
        );
        assert!(r.value.is_finite() && r.best[0] >= 0.5 && r.best[0] < 0.51, "{r:?}");
    }
}
