//! Small statistics used to report what a scenario realizes.

/// Fine batches kept while simulating; merged into fewer, longer batches for
/// the interval.
pub const FINE_BATCHES: usize = 1024;

/// The 97.5% quantile of Student's t with `df` degrees of freedom (for
/// two-sided 95% intervals): exact to 3 decimals up to 15, then the value at
/// the low end of each range, so an interval is never too narrow.
pub fn t975(df: usize) -> f64 {
    const SMALL: [f64; 15] =
        [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131];
    match df {
        0 => f64::INFINITY,
        1..=15 => SMALL[df - 1],
        16..=31 => 2.120,
        32..=63 => 2.037,
        64..=127 => 1.998,
        _ => 1.979,
    }
}

/// The exact 95 % upper bound on a rate of which `n` independent trials saw
/// no event (one-sided Clopper–Pearson): `1 − 0.05^(1/n)`, about `3/n`.
pub fn none_seen_upper_ci95(n: u64) -> f64 {
    -((0.05f64).ln() / n as f64).exp_m1()
}

/// Counts of events (e.g. drops) over consecutive batches of trials (frames),
/// for a confidence interval on the event rate that accounts for correlation
/// between neighbouring trials (bursts): the method of batch means.
#[derive(Debug, Clone)]
pub struct BatchMeans {
    trials_per_batch: u64,
    trials: Vec<u64>,
    events: Vec<u64>,
    n: u64,
    /// The fine batch trial `n` goes into, `min(n / trials_per_batch,
    /// FINE_BATCHES − 1)`, kept as a count rather than divided out per
    /// trial; and the trials that batch takes before the next one starts.
    batch: usize,
    left: u64,
}

impl BatchMeans {
    /// For a run of `total_trials` trials, known in advance.
    pub fn new(total_trials: u64) -> Self {
        let trials_per_batch = total_trials.div_ceil(FINE_BATCHES as u64).max(1);
        BatchMeans {
            trials_per_batch,
            trials: vec![0; FINE_BATCHES],
            events: vec![0; FINE_BATCHES],
            n: 0,
            batch: 0,
            left: trials_per_batch,
        }
    }

    #[inline]
    pub fn record(&mut self, event: bool) {
        let b = self.batch;
        self.trials[b] += 1;
        self.events[b] += u64::from(event);
        self.n += 1;
        self.left -= 1;
        if self.left == 0 {
            // The last fine batch takes every trial beyond the expected.
            self.batch = (b + 1).min(FINE_BATCHES - 1);
            self.left = self.trials_per_batch;
        }
    }

    pub fn trials(&self) -> u64 {
        self.n
    }

    pub fn events(&self) -> u64 {
        self.events.iter().sum()
    }

    /// The rate and its 95% interval. Batch means over 64 batches, halved
    /// (merging neighbours) while the batch means' lag-1 autocorrelation is
    /// significant, down to 8 batches. With no event (or only events) the
    /// interval is the exact (Clopper–Pearson) one-sided bound
    /// `[0, 1 − 0.05^(1/n)]`, about `3/n` (the "rule of three"; resp.
    /// `[0.05^(1/n), 1]`).
    pub fn rate_ci95(&self) -> (f64, [f64; 2]) {
        self.rate_ci95_with(0.0)
    }

    /// [`BatchMeans::rate_ci95`] with `unseen_rate` added to the upper end:
    /// the long-run rate of events a run of this length is unlikely to have
    /// sampled (a heavy-tailed model's longest bursts,
    /// [`crate::model::AnyModel::unseen_loss_rate`]), which no spread of the
    /// run's own can show.
    pub fn rate_ci95_with(&self, unseen_rate: f64) -> (f64, [f64; 2]) {
        let (rate, [lo, hi]) = self.rate_ci95_seen();
        (rate, [lo, (hi + unseen_rate).min(1.0)])
    }

    fn rate_ci95_seen(&self) -> (f64, [f64; 2]) {
        let n = self.n;
        if n == 0 {
            return (0.0, [0.0, 1.0]);
        }
        let events = self.events();
        let rate = events as f64 / n as f64;
        if events == 0 {
            return (0.0, [0.0, none_seen_upper_ci95(n)]);
        }
        if events == n {
            return (1.0, [1.0 - none_seen_upper_ci95(n), 1.0]);
        }
        let used = self.trials.iter().rposition(|t| *t > 0).map_or(0, |i| i + 1);
        let mut batches = 64usize.min(used);
        let mut half_width;
        loop {
            let (means, r1) = self.merged(used, batches);
            let b = means.len() as f64;
            let mean = means.iter().sum::<f64>() / b;
            let var = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (b - 1.0).max(1.0);
            half_width = t975(means.len() - 1) * (var / b).sqrt();
            if batches <= 8 || r1.abs() <= 2.0 / b.sqrt() {
                break;
            }
            batches /= 2;
        }
        // Never narrower than the independent-trials (binomial) interval.
        let binomial = 1.96 * (rate * (1.0 - rate) / n as f64).sqrt();
        let h = half_width.max(binomial);
        (rate, [(rate - h).max(0.0), (rate + h).min(1.0)])
    }

    /// Batch rates over `batches` merged batches of the first `used` fine
    /// ones, and their lag-1 autocorrelation.
    fn merged(&self, used: usize, batches: usize) -> (Vec<f64>, f64) {
        let per = used.div_ceil(batches.max(1));
        let means: Vec<f64> = (0..used)
            .step_by(per)
            .filter_map(|s| {
                let e = (s + per).min(used);
                let t: u64 = self.trials[s..e].iter().sum();
                (t > 0).then(|| self.events[s..e].iter().sum::<u64>() as f64 / t as f64)
            })
            .collect();
        let b = means.len();
        if b < 3 {
            return (means, 0.0);
        }
        let mean = means.iter().sum::<f64>() / b as f64;
        let var: f64 = means.iter().map(|m| (m - mean).powi(2)).sum();
        let cov: f64 = means.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
        let r1 = if var > 0.0 { cov / var } else { 0.0 };
        (means, r1)
    }
}

/// The most a percentile or maximum read from an HDR histogram of 3
/// significant digits lies above the exact value, as a fraction of it:
/// its buckets are at most 2^-10 of their values wide, and it reports a
/// bucket's top.
pub const HDR_ERROR_FRACTION_MAX: f64 = 1.0 / 1024.0;

/// The most values [`Quantiles`] keeps to give exact quantiles: 2^25
/// (256 MiB); beyond them it goes on in an HDR histogram.
pub const EXACT_VALUES_MAX: usize = 1 << 25;

/// Quantiles of a sample of `u64` values (delays in ns): exact while the
/// values fit in [`EXACT_VALUES_MAX`], then from an HDR histogram over every
/// `u64` (3 significant digits), which says so. The quantile `q` of `n`
/// values is the value of rank `max(1, ⌈q·n⌉)` in increasing order, the
/// rank HdrHistogram reads too.
#[derive(Debug, Clone)]
pub struct Quantiles {
    values: Vec<u64>,
    /// The most values kept ([`EXACT_VALUES_MAX`] but in tests).
    cap: usize,
    histogram: Option<Box<hdrhistogram::Histogram<u64>>>,
}

impl Quantiles {
    /// For about `expected` values (room for them is reserved, up to
    /// [`EXACT_VALUES_MAX`]).
    pub fn new(expected: u64) -> Quantiles {
        Quantiles::with_cap(expected, EXACT_VALUES_MAX)
    }

    fn with_cap(expected: u64, cap: usize) -> Quantiles {
        Quantiles { values: Vec::with_capacity(expected.min(cap as u64) as usize), cap, histogram: None }
    }

    #[inline]
    pub fn record(&mut self, v: u64) {
        match &mut self.histogram {
            Some(h) => h.saturating_record(v),
            None if self.values.len() < self.cap => self.values.push(v),
            None => self.spill(v),
        }
    }

    /// The values no longer fit: they go into a histogram, and so does
    /// every value from here on.
    #[cold]
    fn spill(&mut self, v: u64) {
        let mut h = hdrhistogram::Histogram::new_with_bounds(1, u64::MAX, 3).expect("static bounds are valid");
        for &x in self.values.iter().chain([&v]) {
            h.saturating_record(x);
        }
        self.values = Vec::new();
        self.histogram = Some(Box::new(h));
    }

    /// The values recorded.
    pub fn len(&self) -> u64 {
        self.histogram.as_ref().map_or(self.values.len() as u64, |h| h.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether the quantiles are exact (the values all fitted).
    pub fn is_exact(&self) -> bool {
        self.histogram.is_none()
    }

    /// The quantiles `qs` (each in [0, 1], in increasing order), 0 for no
    /// values. Reorders the values kept (a selection, not a sort).
    pub fn quantiles(&mut self, qs: &[f64]) -> Vec<u64> {
        let n = self.len();
        if n == 0 {
            return vec![0; qs.len()];
        }
        if let Some(h) = &self.histogram {
            return qs.iter().map(|&q| h.value_at_quantile(q)).collect();
        }
        let mut out = Vec::with_capacity(qs.len());
        // Each selection leaves the values at or above its rank to its
        // right: the next (higher) rank is selected there.
        let mut from = 0usize;
        for &q in qs {
            let rank = ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).clamp(1, n) as usize - 1;
            let rank = rank.max(from);
            let (_, v, _) = self.values[from..].select_nth_unstable(rank - from);
            out.push(*v);
            from = rank;
        }
        out
    }

    /// The precision of [`Quantiles::quantiles`]: `None` when exact, else
    /// the most each lies above the exact value, as a fraction of it.
    pub fn error_fraction_max(&self) -> Option<f64> {
        (!self.is_exact()).then_some(HDR_ERROR_FRACTION_MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_quantiles_are_the_values_at_their_ranks() {
        let mut q = Quantiles::new(1000);
        // 1..=1000 in a scrambled order: the p50 is the 500th, the p99 the
        // 990th, as HdrHistogram ranks them.
        for i in 0..1000u64 {
            q.record((i * 7919) % 1000 + 1);
        }
        assert!(q.is_exact() && q.error_fraction_max().is_none());
        assert_eq!(q.quantiles(&[0.0, 0.5, 0.99, 1.0]), [1, 500, 990, 1000]);
        let mut one = Quantiles::new(0);
        one.record(u64::MAX);
        assert_eq!(one.quantiles(&[0.5, 0.99]), [u64::MAX, u64::MAX]);
        assert_eq!(Quantiles::new(0).quantiles(&[0.5]), [0]);
    }

    #[test]
    fn beyond_the_values_kept_the_quantiles_say_their_precision() {
        let cap = 100_000usize;
        let mut q = Quantiles::with_cap(0, cap);
        for v in 1..=cap as u64 {
            q.record(v * 1_000_000);
        }
        assert!(q.is_exact());
        q.record(3 * 31_557_600_000_000_000);
        assert!(!q.is_exact());
        assert_eq!(q.error_fraction_max(), Some(HDR_ERROR_FRACTION_MAX));
        assert_eq!(q.len(), cap as u64 + 1);
        let p50 = q.quantiles(&[0.5])[0];
        let exact = (cap as u64 + 1).div_ceil(2) * 1_000_000;
        assert!(p50 >= exact && (p50 - exact) as f64 <= exact as f64 * HDR_ERROR_FRACTION_MAX, "{p50} vs {exact}");
    }
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    #[test]
    fn a_trial_goes_into_the_batch_of_its_index() {
        // Fewer, exactly and more trials than expected: trial n is in fine
        // batch min(n / trials_per_batch, FINE_BATCHES - 1).
        for (expected, run) in [(1u64, 3u64), (1000, 999), (5000, 5000), (4096, 9000), (10_000_000, 10_000_001)] {
            let mut bm = BatchMeans::new(expected);
            let mut trials = vec![0u64; FINE_BATCHES];
            let mut events = vec![0u64; FINE_BATCHES];
            for n in 0..run {
                let event = n % 3 == 0 || n % 7 == 0;
                bm.record(event);
                let b = ((n / bm.trials_per_batch) as usize).min(FINE_BATCHES - 1);
                trials[b] += 1;
                events[b] += u64::from(event);
            }
            assert_eq!((bm.trials(), &bm.trials, &bm.events), (run, &trials, &events), "{expected} expected, {run} run");
        }
    }

    #[test]
    fn independent_trials_give_about_the_binomial_interval() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        let n = 1_000_000;
        let mut bm = BatchMeans::new(n);
        for _ in 0..n {
            bm.record(rng.random::<f64>() < 0.3);
        }
        let (rate, [lo, hi]) = bm.rate_ci95();
        let binomial = 1.96 * (0.3f64 * 0.7 / n as f64).sqrt();
        assert!((rate - 0.3).abs() < 4.0 * binomial / 1.96, "rate {rate}");
        // The half-width estimate from 64 batches is within ~±35% of the
        // truth at 99% confidence (chi-square with 63 df), and never below
        // the binomial one.
        let h = (hi - lo) / 2.0;
        assert!(h >= binomial * 0.999 && h < binomial * 1.35, "half width {h} vs binomial {binomial}");
    }

    #[test]
    fn correlated_trials_widen_the_interval() {
        // Runs of 1000 identical outcomes: the effective sample is 1000×
        // smaller, so the interval must be ~sqrt(1000) ≈ 32× the binomial one.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
        let n = 1_000_000u64;
        let mut bm = BatchMeans::new(n);
        let mut state = false;
        for i in 0..n {
            if i % 1000 == 0 {
                state = rng.random::<f64>() < 0.5;
            }
            bm.record(state);
        }
        let (rate, [lo, hi]) = bm.rate_ci95();
        let binomial = 1.96 * (rate * (1.0 - rate) / n as f64).sqrt();
        assert!((hi - lo) / 2.0 > 15.0 * binomial, "half width {} vs binomial {binomial}", (hi - lo) / 2.0);
    }

    #[test]
    fn degenerate_rates_use_the_rule_of_three() {
        let mut bm = BatchMeans::new(1000);
        for _ in 0..1000 {
            bm.record(false);
        }
        let (rate, [lo, hi]) = bm.rate_ci95();
        assert_eq!((rate, lo), (0.0, 0.0));
        // (1 − hi)^1000 = 0.05: the exact bound, about 3/1000.
        assert!(((1.0 - hi).powi(1000) - 0.05).abs() < 1e-12 && (hi - 0.003).abs() < 1e-5, "{hi}");
        // Far beyond 4 decimals, the bound is still about 3/n.
        let n = 10_000_000u64;
        assert!((none_seen_upper_ci95(n) * n as f64 - 2.995_732).abs() < 1e-5);
        let mut all = BatchMeans::new(10);
        (0..10).for_each(|_| all.record(true));
        let (rate_all, [lo_all, hi_all]) = all.rate_ci95();
        assert_eq!((rate_all, hi_all), (1.0, 1.0));
        assert!((lo_all.powi(10) - 0.05).abs() < 1e-12, "{lo_all}");
        // What a run could not have seen widens the upper end only.
        assert_eq!(bm.rate_ci95_with(0.01).1, [0.0, hi + 0.01]);
        assert_eq!(all.rate_ci95_with(0.01).1, [lo_all, 1.0]);
    }
}
