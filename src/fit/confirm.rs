//! Confirmation: an independent simulation of fitted parameters with the
//! model's own code, reporting what they realize with 95% intervals.
//!
//! Contract: pure and seeded. A confirmation is a fixed number of
//! [`REPLICAS`] independent replicas, each with its own Xoshiro256++ stream
//! derived from the confirmation seed and its index; it advances in rounds in
//! which every replica simulates the same number of batches. Replicas are
//! independent, so a caller may run a round's replicas on several threads:
//! the result depends only on the seed, never on the number of threads.
//! After each round [`Confirmation::done`] applies the stopping rule: at
//! least a minimum sample, then until every metric's 95% half-width is at
//! most [`HALF_WIDTH_GOAL_REL`] of its value, or a maximum sample.
//!
//! What is simulated:
//! - `ge_lomax` and `delay`: frame by frame through [`AnyModel::decide`], frames
//!   every `frame_interval_ns` (the model is the one the emulator runs).
//! - `outage` (`unit = "time"`, `p_start = 1`): window by window
//!   ([`OutageCycles`]). With `p_start = 1` and frames on a fixed grid, the
//!   frames from one window opening to the next are: the opening frame and
//!   every frame before the window ends (dropped, `max(1, ⌈L/Δ⌉)` of them),
//!   then those before the cooldown ends (delivered); the first frame after
//!   that opens the next window. The model draws exactly one uniform per
//!   window (for `L`), so stepping window by window gives the very same fates
//!   as `Outage::decide` frame by frame with the same stream (a test checks
//!   it), at a cost per window rather than per frame: the low-loss entries
//!   need ~10^10 frames for a 0.2% interval.
//!
//! Intervals: batches of each replica are merged into at most 16 groups, and
//! each metric is a ratio `Σ num / Σ den` over all groups (drops/frames,
//! drops/runs, delay sum/frames, window length sum/windows) with the ratio
//! estimator's batch-means variance and a Student-t quantile. Loss intervals
//! are never narrower than the binomial one. The p99 delay uses the
//! distribution-free order-statistic interval of i.i.d. delays on an HDR
//! histogram (3 significant digits).

use super::{FitError, Metric};
use crate::model::units::ms_to_ns;
use crate::model::{AnyModel, Millis, OutageParams, OutageUnit, StageRng, Verdict};
use crate::model::{stream_seed, ModelSpec};
use hdrhistogram::Histogram;
use rand::{RngExt, SeedableRng};

/// Independent replicas per confirmation (fixed: results never depend on the
/// number of threads).
pub const REPLICAS: usize = 8;
/// Stop once every metric's 95% half-width is at most this fraction of its
/// value (2.5 times inside the database's 0.5% tolerance).
pub const HALF_WIDTH_GOAL_REL: f64 = 0.002;
/// Batches each replica simulates per round.
const BATCHES_PER_ROUND: usize = 4;
/// Groups per replica the batches are merged into for the interval.
const GROUPS_PER_REPLICA: usize = 16;

/// Per-kind sample sizes: frames (or windows) per batch, and the least and
/// most batches per replica.
#[derive(Debug, Clone, Copy)]
struct Sizes {
    per_batch: u64,
    min_batches: usize,
    max_batches: usize,
}

const GE_LOMAX_SIZES: Sizes = Sizes { per_batch: 1 << 16, min_batches: 8, max_batches: 4096 };
const DELAY_SIZES: Sizes = Sizes { per_batch: 1 << 15, min_batches: 4, max_batches: 1024 };
const OUTAGE_SIZES: Sizes = Sizes { per_batch: 1 << 10, min_batches: 4, max_batches: 4096 };

/// One metric as realized, with its 95% interval.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Estimate {
    pub metric: Metric,
    pub value: f64,
    pub ci95: [f64; 2],
}

/// One window of an `outage` stage: frames dropped, frames from its opening
/// to the next opening, and its drawn length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cycle {
    pub dropped: u64,
    pub frames: u64,
    pub length_ns: u64,
}

/// Window-by-window simulation of an `outage` stage with `p_start = 1` in
/// time units, frames every `interval_ns` (module docs).
#[derive(Debug, Clone)]
pub struct OutageCycles {
    length_min_ns: u64,
    length_span_ns: u64,
    cooldown_ns: u64,
    interval_ns: u64,
}

impl OutageCycles {
    /// `None` unless the parameters are `unit = "time"` with `p_start = 1`
    /// and the interval is positive.
    pub fn new(p: &OutageParams, interval_ns: u64) -> Option<OutageCycles> {
        if p.unit != OutageUnit::Time || p.p_start.get() != 1.0 || interval_ns == 0 {
            return None;
        }
        // The same conversions as the model's.
        let min_ns = ms_to_ns(p.min_ms.map_or(0.0, Millis::get));
        let max_ns = ms_to_ns(p.max_ms?.get());
        Some(OutageCycles {
            length_min_ns: min_ns,
            length_span_ns: max_ns.checked_sub(min_ns)?,
            cooldown_ns: ms_to_ns(p.cooldown_ms?.get()),
            interval_ns,
        })
    }

    /// The next window, drawing what `Outage::decide` draws for it.
    #[inline]
    pub fn next(&self, rng: &mut StageRng) -> Cycle {
        let length_ns = if self.length_span_ns == 0 {
            self.length_min_ns
        } else {
            self.length_min_ns + (rng.random::<f64>() * self.length_span_ns as f64) as u64
        };
        let frames_before = |ns: u64| ns.div_ceil(self.interval_ns).max(1);
        Cycle {
            dropped: frames_before(length_ns),
            frames: frames_before(length_ns.saturating_add(self.cooldown_ns)),
            length_ns,
        }
    }
}

/// Sums over one batch.
#[derive(Debug, Clone, Copy, Default)]
struct Batch {
    frames: u64,
    drops: u64,
    /// Runs of drops that start in this batch.
    runs: u64,
    delay_ms_sum: f64,
    delay_ms_sq_sum: f64,
    windows: u64,
    window_ms_sum: f64,
}

impl Batch {
    fn add(&mut self, o: &Batch) {
        self.frames += o.frames;
        self.drops += o.drops;
        self.runs += o.runs;
        self.delay_ms_sum += o.delay_ms_sum;
        self.delay_ms_sq_sum += o.delay_ms_sq_sum;
        self.windows += o.windows;
        self.window_ms_sum += o.window_ms_sum;
    }
}

// `Frames` holds a model inline (a `ge_lomax` is ~0.9 KiB); there are eight
// replicas, so boxing would save nothing that matters.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
enum Sim {
    /// Frame by frame through the model: loss models and delay.
    Frames { model: AnyModel, prev_drop: bool, next_frame: u64, interval_ns: u64, delays: Option<Box<Histogram<u64>>> },
    /// Window by window: outage.
    Windows(OutageCycles),
}

/// One independent replica of a confirmation.
#[derive(Debug, Clone)]
pub struct Replica {
    sim: Sim,
    rng: StageRng,
    sizes: Sizes,
    batches: Vec<Batch>,
}

impl Replica {
    /// Simulates one round (a fixed number of batches).
    pub fn run_round(&mut self) {
        for _ in 0..BATCHES_PER_ROUND {
            let b = self.run_batch();
            self.batches.push(b);
        }
    }

    fn run_batch(&mut self) -> Batch {
        let mut b = Batch::default();
        match &mut self.sim {
            Sim::Frames { model, prev_drop, next_frame, interval_ns, delays } => {
                let rng = &mut self.rng;
                let mut prev = *prev_drop;
                for _ in 0..self.sizes.per_batch {
                    let t = *next_frame * *interval_ns;
                    *next_frame += 1;
                    match model.decide(t, rng) {
                        Verdict::Drop => {
                            b.drops += 1;
                            b.runs += u64::from(!prev);
                            prev = true;
                        }
                        // The fitted families (loss chains, delays) only
                        // pass or drop; any other verdict passes at once.
                        verdict => {
                            let delay_ns = if let Verdict::Pass { delay_ns } = verdict { delay_ns } else { 0 };
                            prev = false;
                            let ms = delay_ns as f64 / 1e6;
                            b.delay_ms_sum += ms;
                            b.delay_ms_sq_sum += ms * ms;
                            if let Some(h) = delays {
                                h.saturating_record(delay_ns.max(1));
                            }
                        }
                    }
                }
                *prev_drop = prev;
                b.frames = self.sizes.per_batch;
            }
            Sim::Windows(cycles) => {
                for _ in 0..self.sizes.per_batch {
                    let c = cycles.next(&mut self.rng);
                    b.frames += c.frames;
                    b.drops += c.dropped;
                    b.runs += 1;
                    b.windows += 1;
                    b.window_ms_sum += c.length_ns as f64 / 1e6;
                }
            }
        }
        b
    }

    fn groups(&self) -> Vec<Batch> {
        let per = self.batches.len().div_ceil(GROUPS_PER_REPLICA).max(1);
        self.batches
            .chunks(per)
            .map(|c| {
                let mut g = Batch::default();
                c.iter().for_each(|b| g.add(b));
                g
            })
            .collect()
    }
}

/// A confirmation in progress.
#[derive(Debug, Clone)]
pub struct Confirmation {
    replicas: Vec<Replica>,
    metrics: Vec<Metric>,
    seed: u64,
}

impl Confirmation {
    /// A confirmation of `spec` for `metrics`, seeded by `seed`, frames every
    /// `frame_interval_ns`.
    pub fn new(
        spec: &ModelSpec,
        metrics: &[Metric],
        seed: u64,
        frame_interval_ns: u64,
    ) -> Result<Confirmation, FitError> {
        let model =
            spec.build().map_err(|e| FitError::BadRequest { problem: format!("fitted parameters invalid: {e}") })?;
        let (sim, sizes) = match spec {
            ModelSpec::Outage(p) => match OutageCycles::new(p, frame_interval_ns) {
                Some(c) => (Sim::Windows(c), OUTAGE_SIZES),
                None => {
                    return Err(FitError::BadRequest {
                        problem: "only `unit = \"time\"` outages with `p_start = 1` are confirmed".into(),
                    })
                }
            },
            other => {
                let delays = metrics.contains(&Metric::DelayMsP99).then(|| {
                    Box::new(Histogram::<u64>::new_with_bounds(1, 3_600_000_000_000, 3).expect("static bounds"))
                });
                let sizes = if matches!(other, ModelSpec::Delay(_) | ModelSpec::Jitter(_)) { DELAY_SIZES } else { GE_LOMAX_SIZES };
                (Sim::Frames { model, prev_drop: false, next_frame: 0, interval_ns: frame_interval_ns, delays }, sizes)
            }
        };
        let replicas = (0..REPLICAS)
            .map(|r| Replica {
                sim: sim.clone(),
                rng: StageRng::seed_from_u64(stream_seed(seed, r, "fit/replica")),
                sizes,
                batches: Vec::new(),
            })
            .collect();
        Ok(Confirmation { replicas, metrics: metrics.to_vec(), seed })
    }

    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The replicas, to run a round on each (in any order, on any thread).
    pub fn replicas_mut(&mut self) -> &mut [Replica] {
        &mut self.replicas
    }

    /// Runs rounds on the calling thread until [`Confirmation::done`].
    pub fn run_serial(&mut self) {
        while !self.done() {
            self.replicas.iter_mut().for_each(Replica::run_round);
        }
    }

    /// Whether the stopping rule is met.
    pub fn done(&self) -> bool {
        let batches = self.replicas[0].batches.len();
        let sizes = self.replicas[0].sizes;
        if batches < sizes.min_batches {
            return false;
        }
        if batches >= sizes.max_batches {
            return true;
        }
        self.metrics.iter().all(|&m| {
            let e = self.estimate(m);
            let half = (e.ci95[1] - e.ci95[0]) / 2.0;
            half <= HALF_WIDTH_GOAL_REL * e.value.abs()
        })
    }

    /// Frames whose fate was decided.
    pub fn frames(&self) -> u64 {
        self.replicas.iter().flat_map(|r| &r.batches).map(|b| b.frames).sum()
    }

    /// Outage windows opened (0 for other models).
    pub fn windows(&self) -> u64 {
        self.replicas.iter().flat_map(|r| &r.batches).map(|b| b.windows).sum()
    }

    /// Progress towards the stopping rule's maximum, in `[0, 1]`.
    pub fn batches_done(&self) -> (usize, usize) {
        (self.replicas[0].batches.len(), self.replicas[0].sizes.max_batches)
    }

    /// Every requested metric as realized so far.
    pub fn estimates(&self) -> Vec<Estimate> {
        self.metrics.iter().map(|&m| self.estimate(m)).collect()
    }

    fn estimate(&self, metric: Metric) -> Estimate {
        let groups: Vec<Batch> = self.replicas.iter().flat_map(Replica::groups).collect();
        let ratio = |num: &dyn Fn(&Batch) -> f64, den: &dyn Fn(&Batch) -> f64| ratio_ci(&groups, num, den);
        let (value, ci95) = match metric {
            Metric::LossRate => {
                let (r, [lo, hi]) = ratio(&|b| b.drops as f64, &|b| b.frames as f64);
                let n = self.frames() as f64;
                let binomial = 1.96 * (r * (1.0 - r) / n).sqrt();
                let h = ((hi - lo) / 2.0).max(binomial);
                (r, [(r - h).max(0.0), (r + h).min(1.0)])
            }
            Metric::LossRunMean => ratio(&|b| b.drops as f64, &|b| b.runs as f64),
            Metric::DelayMsMean => ratio(&|b| b.delay_ms_sum, &|b| (b.frames - b.drops) as f64),
            Metric::DelayMsStd => {
                let variances: Vec<f64> = groups
                    .iter()
                    .filter(|b| b.frames > b.drops + 1)
                    .map(|b| {
                        let n = (b.frames - b.drops) as f64;
                        let mean = b.delay_ms_sum / n;
                        (b.delay_ms_sq_sum / n - mean * mean).max(0.0) * n / (n - 1.0)
                    })
                    .collect();
                let (v, [lo, hi]) = mean_ci(&variances);
                (v.sqrt(), [lo.max(0.0).sqrt(), hi.sqrt()])
            }
            Metric::DelayMsP99 => self.p99(),
            Metric::OutageMsMean => ratio(&|b| b.window_ms_sum, &|b| b.windows as f64),
        };
        Estimate { metric, value, ci95 }
    }

    fn p99(&self) -> (f64, [f64; 2]) {
        let mut all = Histogram::<u64>::new_with_bounds(1, 3_600_000_000_000, 3).expect("static bounds");
        for r in &self.replicas {
            if let Sim::Frames { delays: Some(h), .. } = &r.sim {
                all.add(h.as_ref()).expect("same bounds");
            }
        }
        let n = all.len() as f64;
        if n == 0.0 {
            return (f64::NAN, [f64::NAN, f64::NAN]);
        }
        let q = 0.99;
        let d = 1.96 * (q * (1.0 - q) / n).sqrt();
        let at = |q: f64| all.value_at_quantile(q.clamp(0.0, 1.0)) as f64 / 1e6;
        (at(q), [at(q - d), at(q + d)])
    }
}

/// Two-sided 97.5% Student-t quantiles.
fn t975(df: usize) -> f64 {
    match df {
        0 => f64::INFINITY,
        1..=7 => [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365][df - 1],
        8..=15 => 2.131,
        16..=31 => 2.040,
        32..=63 => 1.998,
        64..=127 => 1.979,
        _ => 1.96,
    }
}

/// `Σ num / Σ den` over groups with the ratio estimator's 95% interval.
fn ratio_ci(groups: &[Batch], num: &dyn Fn(&Batch) -> f64, den: &dyn Fn(&Batch) -> f64) -> (f64, [f64; 2]) {
    let g = groups.len();
    let (sn, sd): (f64, f64) = groups.iter().fold((0.0, 0.0), |(a, b), x| (a + num(x), b + den(x)));
    if sd == 0.0 {
        return (f64::NAN, [f64::NAN, f64::NAN]);
    }
    let r = sn / sd;
    if g < 2 {
        return (r, [f64::NEG_INFINITY, f64::INFINITY]);
    }
    let mean_den = sd / g as f64;
    let s2 = groups.iter().map(|x| (num(x) - r * den(x)).powi(2)).sum::<f64>() / (g - 1) as f64;
    let h = t975(g - 1) * (s2 / g as f64).sqrt() / mean_den;
    (r, [r - h, r + h])
}

fn mean_ci(xs: &[f64]) -> (f64, [f64; 2]) {
    let n = xs.len();
    if n < 2 {
        return (xs.first().copied().unwrap_or(f64::NAN), [f64::NEG_INFINITY, f64::INFINITY]);
    }
    let m = xs.iter().sum::<f64>() / n as f64;
    let s2 = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1) as f64;
    let h = t975(n - 1) * (s2 / n as f64).sqrt();
    (m, [m - h, m + h])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Model, Outage};

    fn outage(min_ms: f64, max_ms: f64, cooldown_ms: f64) -> OutageParams {
        OutageParams::time(1.0, min_ms, max_ms, cooldown_ms).unwrap()
    }

    /// Window by window gives the same fates as the model frame by frame,
    /// with the same stream, including windows shorter than a frame and an
    /// interval that does not divide the lengths.
    #[test]
    fn window_steps_match_the_model_frame_by_frame() {
        for (p, interval_ns) in [
            (outage(0.0, 2000.0, 1000.0), 1_000_000),
            (outage(0.0, 3.7, 0.4), 1_000_000),
            (outage(2.5, 2.5, 0.0), 1_000_000),
            (outage(0.0, 50.0, 13.3), 1_934_236),
        ] {
            let cycles = OutageCycles::new(&p, interval_ns).unwrap();
            let mut model = Outage::new(&p).unwrap();
            let mut rng_model = StageRng::seed_from_u64(4);
            let mut rng_cycles = rng_model.clone();
            let mut frame = 0u64;
            for _ in 0..2000 {
                let c = cycles.next(&mut rng_cycles);
                let fates: Vec<bool> = (0..c.frames)
                    .map(|j| model.decide((frame + j) * interval_ns, &mut rng_model) == Verdict::Drop)
                    .collect();
                frame += c.frames;
                let dropped = fates.iter().take_while(|d| **d).count() as u64;
                assert_eq!(dropped, c.dropped, "{p:?}");
                assert!(fates[dropped as usize..].iter().all(|d| !d), "{p:?}");
            }
            assert_eq!(model.windows().count, 2000);
            // The next frame opens window 2001.
            assert_eq!(model.decide(frame * interval_ns, &mut rng_model), Verdict::Drop);
            assert_eq!(model.windows().count, 2001);
        }
    }

    #[test]
    fn confirms_an_outage_exactly_enough() {
        let p = outage(0.0, 3000.0, 8500.0);
        let exact = Outage::new(&p).unwrap().loss_rate_approx(1_000_000).unwrap();
        let mut c =
            Confirmation::new(&ModelSpec::Outage(p), &[Metric::LossRate, Metric::OutageMsMean], 1, 1_000_000).unwrap();
        c.run_serial();
        let e = c.estimates();
        assert!(e[0].ci95[0] <= exact && exact <= e[0].ci95[1], "{e:?} vs {exact}");
        assert!((e[0].ci95[1] - e[0].ci95[0]) / 2.0 <= HALF_WIDTH_GOAL_REL * e[0].value);
        assert!((e[1].value - 1500.0).abs() < 4.0 * (e[1].ci95[1] - e[1].value), "{e:?}");
        assert_eq!(c.windows(), (REPLICAS * c.replicas[0].batches.len()) as u64 * OUTAGE_SIZES.per_batch);
    }

    #[test]
    fn same_seed_same_confirmation() {
        let spec = crate::model::presets::preset_models("PLM-2").unwrap().remove(0);
        let run = |seed| {
            let mut c = Confirmation::new(&spec, &[Metric::LossRate, Metric::LossRunMean], seed, 1_000_000).unwrap();
            c.replicas_mut().iter_mut().for_each(Replica::run_round);
            (c.estimates(), c.frames())
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3).0, run(4).0);
    }
}
