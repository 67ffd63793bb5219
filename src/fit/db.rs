//! The fault parameter database (docs/spec.md §5): fitted parameters for a grid of
//! targets, from ideal to worst case, and the lookup that target-based
//! scenario stages use.
//!
//! The database is `config/faultdb.toml` (format in `docs/faultdb.md`). It is
//! compiled into the library ([`embedded`]), so a scenario's `loss = "30%"`
//! resolves the same way from any directory and without reading a file; it
//! is regenerated with `netfi fit db --out config/faultdb.toml` and checked
//! with `netfi fit db --verify`.
//!
//! Coverage ([`GRIDS`]): loss 1–95% in 1% steps, mean delay 5–1300 ms in 5 ms
//! steps, outage 1–95% in 1% steps. Every entry is a one-target fit with the
//! default rules of [`super::family`], seeded by [`entry_seed`]; its realized
//! value is within [`super::TOLERANCE_REL`] of its target.

use super::{FitError, FitRequest, FitResult, Kind, TOOL_VERSION};
use crate::model::{DelayParams, GeLomaxParams, Order, OutageParams, Probability};
use crate::model::{stream_seed, ModelSpec};
use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

/// The database as shipped, compiled in.
pub const EMBEDDED_TEXT: &str = include_str!("../../config/faultdb.toml");

/// The version of the file format this code reads and writes.
pub const FORMAT: u32 = 1;

/// The master seed of the shipped database.
pub const DEFAULT_SEED: u64 = 2026;

/// A grid of targets: `first, first + step, …, last`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub kind: Kind,
    /// The number of steps from 0 to the first target (targets are
    /// `i · step` for `i` in `first_index..=last_index`, so every target is
    /// the same decimal however it is computed).
    pub first_index: u32,
    pub last_index: u32,
    pub step: f64,
}

/// What the database covers.
pub const GRIDS: [Grid; 3] = [
    Grid { kind: Kind::Loss, first_index: 1, last_index: 95, step: 0.01 },
    Grid { kind: Kind::Delay, first_index: 1, last_index: 260, step: 5.0 },
    Grid { kind: Kind::Outage, first_index: 1, last_index: 95, step: 0.01 },
];

impl Grid {
    pub fn of(kind: Kind) -> Grid {
        GRIDS.into_iter().find(|g| g.kind == kind).expect("every kind has a grid")
    }

    /// Target number `i` (from `first_index`).
    pub fn target(&self, i: u32) -> f64 {
        // `i / 100` rather than `i · 0.01`: the nearest double to the decimal.
        if self.step == 0.01 {
            f64::from(i) / 100.0
        } else {
            f64::from(i) * self.step
        }
    }

    pub fn targets(&self) -> Vec<f64> {
        (self.first_index..=self.last_index).map(|i| self.target(i)).collect()
    }

    /// The grid index of `value`, if it is on the grid.
    pub fn index_of(&self, value: f64) -> Option<u32> {
        let i = (value / self.step).round();
        if i < f64::from(self.first_index) || i > f64::from(self.last_index) {
            return None;
        }
        let i = i as u32;
        ((value - self.target(i)).abs() <= 1e-9 * self.step).then_some(i)
    }

    /// A target as people write it: `30%` or `250 ms`.
    pub fn show(&self, value: f64) -> String {
        match self.kind {
            Kind::Loss | Kind::Outage => format!("{}%", super::fmt_sig(value * 100.0)),
            Kind::Delay | Kind::Jitter => format!("{} ms", super::fmt_sig(value)),
        }
    }

    /// `loss 1% to 95% in steps of 1%`.
    pub fn describe(&self) -> String {
        let step = match self.kind {
            Kind::Loss | Kind::Outage => format!("{}%", super::fmt_sig(self.step * 100.0)),
            Kind::Delay | Kind::Jitter => format!("{} ms", self.step),
        };
        format!(
            "{} {} to {} in steps of {step}",
            self.kind.name(),
            self.show(self.target(self.first_index)),
            self.show(self.target(self.last_index))
        )
    }
}

/// One database entry: a target and the parameters fitted to it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Entry<P> {
    /// The target: a loss rate or lost fraction in `[0, 1]`, or a mean delay
    /// in ms.
    pub target: f64,
    /// The model the parameters are for.
    pub model: String,
    /// The long-run value of `params` by closed form.
    pub exact: f64,
    /// The value realized by the confirmation simulation.
    pub realized: f64,
    pub realized_ci95: [f64; 2],
    /// The fit's seed (`netfi fit <kind> <target> --seed <seed>` reproduces
    /// this entry exactly).
    pub seed: u64,
    /// The confirmation's seed, derived from `seed`.
    pub confirm_seed: u64,
    /// Frames the confirmation decided.
    pub frames: u64,
    /// Outage windows the confirmation opened (outage entries).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub windows: Option<u64>,
    pub tool_version: String,
    /// The model's parameters, as in a scenario stage.
    pub params: P,
}

impl<P> Entry<P> {
    /// The same entry with its parameters mapped by `f`.
    pub fn map<Q>(self, f: impl FnOnce(P) -> Q) -> Entry<Q> {
        let Entry { target, model, exact, realized, realized_ci95, seed, confirm_seed, frames, windows, tool_version, params } = self;
        Entry { target, model, exact, realized, realized_ci95, seed, confirm_seed, frames, windows, tool_version, params: f(params) }
    }
}

/// The whole database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Database {
    pub format: u32,
    pub tool_version: String,
    /// The master seed the entries' seeds derive from.
    pub seed: u64,
    /// The frame rate the fits assume.
    pub frame_rate_hz: f64,
    /// Every realized value is within this fraction of its target.
    pub tolerance_rel: f64,
    #[serde(default)]
    pub loss: Vec<Entry<GeLomaxParams>>,
    #[serde(default)]
    pub delay: Vec<Entry<DelayParams>>,
    #[serde(default)]
    pub outage: Vec<Entry<OutageParams>>,
}

/// A database file that could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("fault parameter database: {problem}")]
pub struct DatabaseError {
    pub problem: String,
}

/// A target a scenario asked for that the database does not have.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{field}`: {problem}")]
pub struct LookupError {
    /// The scenario key: `loss`, `delay_ms_mean`, `outage` (or another key of
    /// a target stage that is wrong).
    pub field: String,
    pub problem: String,
}

/// The seed of the entry for target index `i` of `kind`, from the master seed.
pub fn entry_seed(master: u64, kind: Kind, i: u32) -> u64 {
    stream_seed(master, kind as usize, &format!("faultdb/{}/{i}", kind.name()))
}

/// The fit requests that make up a database with master seed `master`, in
/// grid order (loss, delay, outage).
pub fn plan(master: u64) -> Vec<FitRequest> {
    GRIDS
        .iter()
        .flat_map(|g| {
            (g.first_index..=g.last_index)
                .map(move |i| FitRequest::new(g.kind, g.target(i), entry_seed(master, g.kind, i)))
        })
        .collect()
}

impl Database {
    /// Parses database TOML.
    pub fn parse(text: &str) -> Result<Database, DatabaseError> {
        let db: Database = toml::from_str(text).map_err(|e| DatabaseError { problem: e.to_string() })?;
        if db.format != FORMAT {
            return Err(DatabaseError { problem: format!("format {}: this netfi reads format {FORMAT}", db.format) });
        }
        Ok(db)
    }

    /// Builds the database from fits of [`plan`] requests (in any order).
    pub fn from_results(master: u64, results: &[FitResult]) -> Result<Database, DatabaseError> {
        let mut db = Database {
            format: FORMAT,
            tool_version: TOOL_VERSION.to_string(),
            seed: master,
            frame_rate_hz: super::DEFAULT_FRAME_RATE_HZ,
            tolerance_rel: super::TOLERANCE_REL,
            loss: Vec::new(),
            delay: Vec::new(),
            outage: Vec::new(),
        };
        for r in results {
            if !r.within_tolerance {
                return Err(DatabaseError {
                    problem: format!(
                        "{} target {:?} realized {:?}: outside the {}% tolerance",
                        r.model,
                        r.target,
                        r.realized,
                        super::TOLERANCE_REL * 100.0
                    ),
                });
            }
            let e = r.primary();
            macro_rules! entry {
                ($params:expr) => {
                    Entry {
                        target: r.target.values().next().copied().expect("a fit has a target"),
                        model: r.model.to_string(),
                        exact: r.exact.values().next().copied().expect("a fit has a target"),
                        realized: e.value,
                        realized_ci95: e.ci95,
                        seed: r.seed,
                        confirm_seed: r.confirm_seed,
                        frames: r.frames,
                        windows: r.windows,
                        tool_version: r.tool_version.to_string(),
                        params: $params.clone(),
                    }
                };
            }
            match &r.spec {
                ModelSpec::GeLomax(p) => db.loss.push(entry!(p)),
                ModelSpec::Delay(p) => db.delay.push(entry!(p)),
                ModelSpec::Outage(p) => db.outage.push(entry!(p)),
                other => unreachable!("fits produce no {:?}", other.kind()),
            }
        }
        db.loss.sort_by(|a, b| a.target.total_cmp(&b.target));
        db.delay.sort_by(|a, b| a.target.total_cmp(&b.target));
        db.outage.sort_by(|a, b| a.target.total_cmp(&b.target));
        Ok(db)
    }

    /// The file text: a commented header, then the entries.
    pub fn to_toml(&self) -> String {
        let mut s = String::from(HEADER);
        s.push_str(&toml::to_string(self).expect("the database serializes"));
        s
    }

    /// The entry of `kind` for `target`, as a model: an error names the
    /// covered range, or the nearest entries for an off-grid target.
    pub fn lookup(&self, kind: Kind, target: f64, field: &str) -> Result<ModelSpec, LookupError> {
        let err = |problem: String| LookupError { field: field.to_string(), problem };
        if kind == Kind::Jitter {
            return Err(err("jitter targets are solved in closed form, not stored (see `target_stage`)".into()));
        }
        let grid = Grid::of(kind);
        let Some(i) = grid.index_of(target) else {
            let lo = grid.target(grid.first_index);
            let hi = grid.target(grid.last_index);
            if !(target >= lo - 1e-12 && target <= hi + 1e-12) {
                return Err(err(format!(
                    "{} is outside the fault parameter database, which covers {}; for other targets run `netfi fit {}`",
                    grid.show(target),
                    grid.describe(),
                    kind.name()
                )));
            }
            let below = (target / grid.step).floor() as u32;
            return Err(err(format!(
                "{} is not in the fault parameter database, which covers {} (nearest: {} and {}); for other targets run `netfi fit {} {}`",
                grid.show(target),
                grid.describe(),
                grid.show(grid.target(below)),
                grid.show(grid.target(below + 1)),
                kind.name(),
                grid.show(target).replace(' ', "")
            )));
        };
        let target = grid.target(i);
        let missing = || {
            err(format!(
                "{} is missing from the fault parameter database (it should cover {})",
                grid.show(target),
                grid.describe()
            ))
        };
        let found = |t: f64| (t - target).abs() <= 1e-9 * grid.step;
        Ok(match kind {
            Kind::Loss => {
                ModelSpec::GeLomax(self.loss.iter().find(|e| found(e.target)).ok_or_else(missing)?.params.clone())
            }
            Kind::Delay => {
                ModelSpec::Delay(self.delay.iter().find(|e| found(e.target)).ok_or_else(missing)?.params.clone())
            }
            Kind::Outage => {
                ModelSpec::Outage(self.outage.iter().find(|e| found(e.target)).ok_or_else(missing)?.params.clone())
            }
            Kind::Jitter => unreachable!("refused above"),
        })
    }

    /// Every entry, for checks that treat all kinds alike.
    pub fn entries(&self) -> Vec<EntryView> {
        let mut out = Vec::new();
        out.extend(self.loss.iter().map(|e| EntryView { kind: Kind::Loss, entry: e.clone().map(ModelSpec::GeLomax) }));
        out.extend(self.delay.iter().map(|e| EntryView { kind: Kind::Delay, entry: e.clone().map(ModelSpec::Delay) }));
        out.extend(self.outage.iter().map(|e| EntryView { kind: Kind::Outage, entry: e.clone().map(ModelSpec::Outage) }));
        out
    }
}

/// One entry of any kind, its parameters as a model.
#[derive(Debug, Clone, PartialEq)]
pub struct EntryView {
    pub kind: Kind,
    pub entry: Entry<ModelSpec>,
}

/// How many combined standard errors an independent re-simulation may be
/// from the stored value: 4.5 keeps the chance of a false alarm anywhere in
/// the 450 entries under 0.5% (Bonferroni).
pub const CONSISTENCY_Z: f64 = 4.5;

impl EntryView {
    fn name(&self) -> String {
        format!("{} {}", self.kind.name(), Grid::of(self.kind).show(self.entry.target))
    }

    /// Without simulating: the parameters are valid, their closed-form value
    /// is the stored one and within a fifth of the tolerance of the target,
    /// and the stored realized value is within the tolerance.
    pub fn check_stored(&self) -> Result<(), String> {
        let interval = (1e9 / super::DEFAULT_FRAME_RATE_HZ).round() as u64;
        let exact = super::family::metrics_exact(&self.entry.params, &[self.kind.primary()], interval)
            .ok_or_else(|| format!("{}: parameters invalid", self.name()))?[0];
        if (exact - self.entry.exact).abs() > 1e-9 * self.entry.exact.abs() {
            return Err(format!("{}: closed form gives {exact}, the entry says {}", self.name(), self.entry.exact));
        }
        let rel = |v: f64| ((v - self.entry.target) / self.entry.target).abs();
        if rel(exact) > super::TOLERANCE_REL / 5.0 {
            return Err(format!("{}: closed form {exact} is {:.3}% off", self.name(), rel(exact) * 100.0));
        }
        if rel(self.entry.realized) > super::TOLERANCE_REL {
            return Err(format!(
                "{}: realized {} is {:.3}% off",
                self.name(),
                self.entry.realized,
                rel(self.entry.realized) * 100.0
            ));
        }
        let [lo, hi] = self.entry.realized_ci95;
        if !(lo <= self.entry.realized && self.entry.realized <= hi) {
            return Err(format!("{}: realized {} outside its own interval [{lo}, {hi}]", self.name(), self.entry.realized));
        }
        Ok(())
    }

    /// Re-simulating with the stored confirmation seed gives the stored
    /// value, interval and frame count exactly.
    pub fn check_reproduces(&self) -> Result<(), String> {
        let (e, frames) = self.confirm(self.entry.confirm_seed).map_err(|e| format!("{}: {e}", self.name()))?;
        if e.value != self.entry.realized || e.ci95 != self.entry.realized_ci95 || frames != self.entry.frames {
            return Err(format!(
                "{}: seed {} re-simulates to {} {:?} over {frames} frames, the entry says {} {:?} over {}",
                self.name(),
                self.entry.confirm_seed,
                e.value,
                e.ci95,
                self.entry.realized,
                self.entry.realized_ci95,
                self.entry.frames
            ));
        }
        Ok(())
    }

    /// An independent re-simulation (another seed) lands within the
    /// tolerance of the target and agrees with the stored value within
    /// [`CONSISTENCY_Z`] combined standard errors.
    pub fn check_independent(&self) -> Result<(), String> {
        let seed = stream_seed(self.entry.confirm_seed, 1, "faultdb/verify");
        let (e, _) = self.confirm(seed).map_err(|e| format!("{}: {e}", self.name()))?;
        let rel = ((e.value - self.entry.target) / self.entry.target).abs();
        if rel > super::TOLERANCE_REL {
            return Err(format!("{}: seed {seed} realizes {} ({:.3}% off)", self.name(), e.value, rel * 100.0));
        }
        let se = |ci: [f64; 2]| (ci[1] - ci[0]) / 2.0 / 1.96;
        let combined = se(e.ci95).hypot(se(self.entry.realized_ci95));
        if (e.value - self.entry.realized).abs() > CONSISTENCY_Z * combined {
            return Err(format!(
                "{}: seed {seed} realizes {} {:?}, inconsistent with the stored {} {:?}",
                self.name(),
                e.value,
                e.ci95,
                self.entry.realized,
                self.entry.realized_ci95
            ));
        }
        Ok(())
    }

    /// All three checks.
    pub fn check(&self) -> Result<(), String> {
        self.check_stored()?;
        self.check_reproduces()?;
        self.check_independent()
    }

    fn confirm(&self, seed: u64) -> Result<(super::Estimate, u64), FitError> {
        let interval = (1e9 / super::DEFAULT_FRAME_RATE_HZ).round() as u64;
        let mut c = super::Confirmation::new(&self.entry.params, &[self.kind.primary()], seed, interval)?;
        c.run_serial();
        Ok((c.estimates()[0], c.frames()))
    }
}

const HEADER: &str = "\
# netfi fault parameter database (format described in docs/faultdb.md).
#
# Fitted parameters for a grid of targets: packet loss (`ge_lomax`) 1-95% in
# 1% steps, mean delay (`delay`) 5-1300 ms in 5 ms steps, communication loss
# (`outage`) 1-95% in 1% steps, at 1 kHz. Each entry gives its target, the
# model and its parameters (as a scenario stage writes them), the exact
# long-run value of those parameters, the value an independent confirmation
# simulation realized with its 95% interval, the fit's seed and the
# confirmation's, the frames simulated and the tool version.
#
# A scenario stage `loss = \"30%\"`, `delay_ms_mean = 250` or `outage = \"10%\"`
# takes the entry. Regenerate with `netfi fit db --out config/faultdb.toml`;
# check with `netfi fit db --verify`.

";

static EMBEDDED: OnceLock<Result<Database, DatabaseError>> = OnceLock::new();

/// The database compiled into this build.
pub fn embedded() -> Result<&'static Database, DatabaseError> {
    EMBEDDED.get_or_init(|| Database::parse(EMBEDDED_TEXT)).as_ref().map_err(Clone::clone)
}

/// The keys of a target stage.
pub const TARGET_KEYS: [&str; 3] = ["loss", "delay_ms_mean", "outage"];

/// A scenario stage that names a target (`loss = "30%"`, `delay_ms_mean =
/// 250`, `outage = "10%"`) instead of a model: `None` if `table` has no
/// target key; otherwise the database's model and a label for reports
/// (`faultdb loss 30%`), or what is wrong. A `delay_ms_mean` stage may also
/// give `order`. A `delay_ms_mean` stage with `delay_ms_p99` is a jitter
/// (docs/spec.md §3.7) of that mean and p99, solved in closed form
/// ([`crate::model::jitter::fit_mean_p99`], nothing stored), with optional
/// `dist` (default `normal`), `correlation` and `order`.
pub fn target_stage(table: &toml::Table) -> Option<Result<(String, ModelSpec), LookupError>> {
    let given: Vec<&str> = TARGET_KEYS.iter().copied().filter(|k| table.contains_key(*k)).collect();
    let key = *given.first()?;
    Some(resolve_target(table, key, &given))
}

fn resolve_target(table: &toml::Table, key: &str, given: &[&str]) -> Result<(String, ModelSpec), LookupError> {
    let err = |field: &str, problem: String| LookupError { field: field.to_string(), problem };
    if given.len() > 1 {
        return Err(err(
            given[1],
            format!("a stage takes one target: `{}` or `{}`, not both (use two stages)", given[0], given[1]),
        ));
    }
    if key == "delay_ms_mean" && table.contains_key("delay_ms_p99") {
        return jitter_target(table);
    }
    for k in table.keys() {
        if k != key && !(key == "delay_ms_mean" && k == "order") {
            let accepted =
                if key == "delay_ms_mean" { "`delay_ms_mean`, `order` and `name`" } else { "the target and `name`" };
            return Err(err(k, format!("does not apply to a target stage: it takes only {accepted}")));
        }
    }
    let value = &table[key];
    let (kind, target) = match key {
        "loss" | "outage" => {
            let p = match value {
                toml::Value::String(s) => Probability::parse(s),
                toml::Value::Float(f) => Probability::new(*f),
                toml::Value::Integer(i) => Probability::new(*i as f64),
                other => Err(format!("expected a fraction or a percentage like \"30%\", found {}", other.type_str())),
            }
            .map_err(|p| err(key, p))?;
            (if key == "loss" { Kind::Loss } else { Kind::Outage }, p.get())
        }
        _ => {
            let ms = match value {
                toml::Value::Float(f) => *f,
                toml::Value::Integer(i) => *i as f64,
                other => return Err(err(key, format!("expected a mean delay in ms, found {}", other.type_str()))),
            };
            (Kind::Delay, ms)
        }
    };
    let db = embedded().map_err(|e| err(key, e.to_string()))?;
    let mut spec = db.lookup(kind, target, key)?;
    if let (ModelSpec::Delay(p), Some(order)) = (&mut spec, table.get("order")) {
        p.order = match order.as_str() {
            Some("reorder") => Order::Reorder,
            Some("fifo") => Order::Fifo,
            _ => return Err(err("order", format!("{order}: expected \"reorder\" or \"fifo\""))),
        };
    }
    Ok((format!("faultdb {} {}", kind.name(), Grid::of(kind).show(target)), spec))
}

/// Keys a jitter target stage takes.
const JITTER_TARGET_KEYS: [&str; 5] = ["delay_ms_mean", "delay_ms_p99", "dist", "correlation", "order"];

/// `delay_ms_mean` with `delay_ms_p99`: the jitter of that mean and p99.
fn jitter_target(table: &toml::Table) -> Result<(String, ModelSpec), LookupError> {
    use crate::model::jitter::{fit_mean_p99, JitterDist};
    let err = |field: &str, problem: String| LookupError { field: field.to_string(), problem };
    if let Some(k) = table.keys().find(|k| !JITTER_TARGET_KEYS.contains(&k.as_str())) {
        return Err(err(k, format!("does not apply to a jitter target stage: it takes only {}", JITTER_TARGET_KEYS.join(", "))));
    }
    let ms = |key: &str| match &table[key] {
        toml::Value::Float(f) => Ok(*f),
        toml::Value::Integer(i) => Ok(*i as f64),
        other => Err(err(key, format!("expected a delay in ms, found {}", other.type_str()))),
    };
    let (mean_ms, p99_ms) = (ms("delay_ms_mean")?, ms("delay_ms_p99")?);
    let dist = match table.get("dist").map(|v| v.as_str()) {
        None => JitterDist::Normal,
        Some(name) => JitterDist::ALL.into_iter().find(|d| Some(d.name()) == name).ok_or_else(|| {
            let names: Vec<_> = JitterDist::ALL.iter().map(|d| d.name()).collect();
            err("dist", format!("expected one of {}", names.join(", ")))
        })?,
    };
    let from_param = |e: crate::model::ParamError| {
        let field = match e.field.as_str() {
            "mean_ms" => "delay_ms_mean",
            "p99_ms" => "delay_ms_p99",
            other => other,
        };
        err(field, e.problem)
    };
    let mut params = fit_mean_p99(dist, mean_ms, p99_ms).map_err(from_param)?;
    if let Some(c) = table.get("correlation") {
        let rho = match c {
            toml::Value::Float(f) => Probability::new(*f),
            toml::Value::Integer(i) => Probability::new(*i as f64),
            toml::Value::String(s) => Probability::parse(s),
            other => Err(format!("expected a correlation in [0, 1), found {}", other.type_str())),
        }
        .map_err(|p| err("correlation", p))?;
        params = params.with_correlation(rho.get()).map_err(from_param)?;
    }
    if let Some(order) = table.get("order") {
        params = params.with_order(match order.as_str() {
            Some("reorder") => Order::Reorder,
            Some("fifo") => Order::Fifo,
            _ => return Err(err("order", format!("{order}: expected \"reorder\" or \"fifo\""))),
        });
    }
    let spec = ModelSpec::Jitter(params);
    spec.build().map_err(from_param)?;
    let label = format!("fit jitter {} ms p99 {} ms {}", super::fmt_sig(mean_ms), super::fmt_sig(p99_ms), dist.name());
    Ok((label, spec))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_cover_what_the_issue_asks() {
        let loss = Grid::of(Kind::Loss).targets();
        assert_eq!((loss.len(), loss[0], loss[29], loss[94]), (95, 0.01, 0.3, 0.95));
        let delay = Grid::of(Kind::Delay).targets();
        assert_eq!((delay.len(), delay[0], delay[49], delay[259]), (260, 5.0, 250.0, 1300.0));
        assert_eq!(Grid::of(Kind::Outage).targets().len(), 95);
        assert_eq!(plan(1).len(), 450);
        assert_eq!(Grid::of(Kind::Loss).index_of(0.3), Some(30));
        assert_eq!(Grid::of(Kind::Loss).index_of(0.305), None);
        assert_eq!(Grid::of(Kind::Delay).index_of(250.0), Some(50));
        assert_eq!(Grid::of(Kind::Delay).index_of(1305.0), None);
        assert_eq!(Grid::of(Kind::Loss).describe(), "loss 1% to 95% in steps of 1%");
        assert_eq!(Grid::of(Kind::Delay).describe(), "delay 5 ms to 1300 ms in steps of 5 ms");
    }

    #[test]
    fn entry_seeds_differ() {
        let seeds: std::collections::BTreeSet<u64> = plan(1).iter().map(|r| r.seed).collect();
        assert_eq!(seeds.len(), 450);
        assert_eq!(plan(1), plan(1));
    }
}
