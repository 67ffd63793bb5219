//! `netfi fit …`: fit a model to a target, and build or verify the fault
//! parameter database.

use crate::cli::{FitCmd, FitCommon, FitDbArgs, ObjectiveArg};
use anyhow::{bail, Context, Result};
use netfi::fit::db::{self, Database, Grid};
use netfi::fit::run::{self, Progress};
use netfi::fit::{FitRequest, FitResult, Kind, Metric, Objective, TOLERANCE_REL};
use netfi::host::StealTimer;
use netfi::model::jitter::JitterDist;
use netfi::model::Probability;
use netfi::service::run::fresh_seed;
use std::path::Path;
use std::time::Instant;

pub fn run(cmd: FitCmd) -> Result<()> {
    match cmd {
        FitCmd::Loss { target, run_length, common } => {
            let p = parse_fraction(&target, "loss")?;
            let mut req = request(Kind::Loss, p, &common)?;
            if let Some(r) = run_length {
                req = req.with_goal(Metric::LossRunMean, r);
            }
            fit_one(req, &common)
        }
        FitCmd::Delay { target, p99_ms, std_ms, min_ms, common } => {
            let ms = parse_ms(&target)?;
            let mut req = request(Kind::Delay, ms, &common)?;
            if let Some(v) = p99_ms {
                req = req.with_goal(Metric::DelayMsP99, v);
            }
            if let Some(v) = std_ms {
                req = req.with_goal(Metric::DelayMsStd, v);
            }
            req.delay_min_ms = min_ms;
            fit_one(req, &common)
        }
        FitCmd::Outage { target, outage_ms, rate_hz, common } => {
            let p = parse_fraction(&target, "outage")?;
            let mut req = request(Kind::Outage, p, &common)?;
            if let Some(v) = outage_ms {
                req = req.with_goal(Metric::OutageMsMean, v);
            }
            req.frame_rate_hz = rate_hz;
            fit_one(req, &common)
        }
        FitCmd::Jitter { target, p99_ms, dist, correlation, common } => {
            let mut req = request(Kind::Jitter, parse_ms(&target)?, &common)?.with_goal(Metric::DelayMsP99, p99_ms);
            req.jitter_dist = JitterDist::ALL.into_iter().find(|d| d.name() == dist).ok_or_else(|| {
                let names: Vec<_> = JitterDist::ALL.iter().map(|d| d.name()).collect();
                anyhow::anyhow!("--dist {dist}: expected one of {}", names.join(", "))
            })?;
            req.jitter_correlation = parse_fraction(&correlation, "correlation")?;
            fit_one(req, &common)
        }
        FitCmd::Db(args) => {
            if let Some(path) = &args.verify {
                verify(path, &args)
            } else {
                generate(&args)
            }
        }
    }
}

fn parse_fraction(s: &str, what: &str) -> Result<f64> {
    Probability::parse(s).map(Probability::get).map_err(|e| anyhow::anyhow!("{what} target: {e}"))
}

fn parse_ms(s: &str) -> Result<f64> {
    let t = s.trim();
    let t = t.strip_suffix("ms").unwrap_or(t).trim();
    t.parse::<f64>().with_context(|| format!("delay target \"{s}\": expected a mean delay in ms, e.g. 250 or 250ms"))
}

fn threads(n: Option<usize>) -> usize {
    n.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())).max(1)
}

fn request(kind: Kind, target: f64, common: &FitCommon) -> Result<FitRequest> {
    let mut req = FitRequest::new(kind, target, common.seed.unwrap_or_else(fresh_seed));
    req.objective = match common.objective {
        ObjectiveArg::Exact => Objective::Exact,
        ObjectiveArg::MonteCarlo => Objective::MonteCarlo,
    };
    req.like = common.like.clone();
    Ok(req)
}

fn fit_one(req: FitRequest, common: &FitCommon) -> Result<()> {
    req.validate()?;
    let threads = threads(common.threads);
    eprintln!("fit {} {} seed {} ({} threads)", req.kind.name(), req.goals[0].value, req.seed, threads);
    let bar = indicatif::ProgressBar::new(1);
    bar.set_style(indicatif::ProgressStyle::with_template("{msg:24} {bar:40} {pos}/{len}").expect("static template"));
    let started = Instant::now();
    let result = run::fit(&req, threads, &|p| match p {
        Progress::Search { generation, max_generations, .. } => {
            if generation == 1 {
                bar.set_message("search (generations)");
                bar.set_length(max_generations as u64);
            }
            bar.set_position(generation as u64);
        }
        Progress::Confirm { batches, max_batches, .. } => {
            bar.set_message("confirm (batches)");
            bar.set_length(max_batches as u64);
            bar.set_position(batches as u64);
        }
    });
    bar.finish_and_clear();
    let result = result?;
    let secs = started.elapsed().as_secs_f64();
    if common.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
    } else {
        print_result(&result, secs);
    }
    if !result.within_tolerance {
        bail!("a realized value is outside the {}% tolerance of its target (see above)", TOLERANCE_REL * 100.0);
    }
    Ok(())
}

fn print_result(r: &FitResult, secs: f64) {
    println!("model         {}", r.model);
    println!("family        {}", r.family);
    println!("seed          {} (confirmation seed {})", r.seed, r.confirm_seed);
    println!(
        "search        {} generations, {} evaluations, objective {:.3e} ({})",
        r.search.generations,
        r.search.evaluations,
        r.search.objective,
        r.objective.name()
    );
    print!("confirmation  {} frames at {} Hz", r.frames, r.frame_rate_hz);
    if let Some(w) = r.windows {
        print!(", {w} windows");
    }
    println!("; {secs:.2} s");
    println!("  {:<16} {:>14} {:>14} {:>14}   95% interval", "metric", "target", "exact", "realized");
    for (name, target) in &r.target {
        let ci = r.realized_ci95[name];
        println!(
            "  {:<16} {:>14} {:>14.7} {:>14.7}   [{:.7}, {:.7}]",
            name, target, r.exact[name], r.realized[name], ci[0], ci[1]
        );
    }
    println!("within {}%     {}", TOLERANCE_REL * 100.0, if r.within_tolerance { "yes" } else { "NO" });
    println!("\nas a scenario stage:\n{}", r.stage_toml());
}

fn generate(args: &FitDbArgs) -> Result<()> {
    let threads = threads(args.threads);
    let seed = args.seed.unwrap_or(db::DEFAULT_SEED);
    let plan = db::plan(seed);
    eprintln!("fault parameter database: {} entries, master seed {seed}, {threads} threads", plan.len());
    let bar = indicatif::ProgressBar::new(plan.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} entries ({elapsed}, eta {eta})")
            .expect("static template"),
    );
    let steal_timer = StealTimer::start();
    let started = Instant::now();
    let results = run::fit_many(&plan, threads, &|_, _| bar.inc(1));
    bar.finish_and_clear();
    let secs = started.elapsed().as_secs_f64();
    let mut fits = Vec::with_capacity(results.len());
    for (req, r) in plan.iter().zip(results) {
        fits.push(r.with_context(|| format!("fitting {} {}", req.kind.name(), req.goals[0].value))?);
    }
    let database = Database::from_results(seed, &fits)?;
    let frames: u64 = fits.iter().map(|f| f.frames).sum();
    let steal = format!("{:.1}%", steal_timer.stop().fraction * 100.0);
    eprintln!("{} entries in {secs:.1} s on {threads} threads ({frames} frames confirmed); steal {steal}", fits.len());
    match &args.out {
        Some(path) => {
            netfi::durable::write_whole(path, database.to_toml().as_bytes())?;
            eprintln!("wrote {}", path.display());
        }
        None => print!("{}", database.to_toml()),
    }
    Ok(())
}

fn verify(path: &Path, args: &FitDbArgs) -> Result<()> {
    let text = netfi::load::open_regular(path)
        .and_then(std::io::read_to_string)
        .with_context(|| format!("reading {}", path.display()))?;
    let database = Database::parse(&text)?;
    let entries = database.entries();
    let threads = threads(args.threads);
    eprintln!("verifying {} entries of {} on {threads} threads", entries.len(), path.display());
    let missing: Vec<String> = db::GRIDS
        .iter()
        .flat_map(|g| g.targets().into_iter().map(move |t| (g, t)))
        .filter(|(g, t)| !entries.iter().any(|e| e.kind == g.kind && g.index_of(e.entry.target) == g.index_of(*t)))
        .map(|(g, t)| format!("{} {}", g.kind.name(), Grid::of(g.kind).show(t)))
        .collect();
    let bar = indicatif::ProgressBar::new(entries.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} entries ({eta})").expect("static template"),
    );
    let started = Instant::now();
    let problems: Vec<Option<String>> = run::par_map(&entries, threads, |e| {
        let p = e.check().err();
        bar.inc(1);
        p
    });
    bar.finish_and_clear();
    let problems: Vec<String> =
        missing.into_iter().map(|m| format!("{m}: missing")).chain(problems.into_iter().flatten()).collect();
    eprintln!("checked in {:.1} s", started.elapsed().as_secs_f64());
    if problems.is_empty() {
        println!(
            "{}: {} entries, all reproduce and re-simulate within {}% of their targets",
            path.display(),
            entries.len(),
            TOLERANCE_REL * 100.0
        );
        Ok(())
    } else {
        for p in &problems {
            println!("{p}");
        }
        bail!("{} of {} entries failed verification", problems.len(), entries.len())
    }
}
