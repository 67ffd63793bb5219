//! Jitter fits (docs/faultdb.md): a mean and a p99 of the delay, solved in
//! closed form and confirmed by simulation; the same targets in a scenario
//! stage; and their errors.

use crate::common::machine;
use netfi::check::{self, Arrivals};
use netfi::fit::run;
use netfi::fit::{FitError, FitRequest, Kind, Metric, TOLERANCE_REL};
use netfi::model::jitter::JitterDist;
use netfi::scenario::{parse_str, ModelSpec, Scenario};

fn rel(a: f64, b: f64) -> f64 {
    ((a - b) / b).abs()
}

fn request(mean_ms: f64, p99_ms: f64, dist: JitterDist, rho: f64, seed: u64) -> FitRequest {
    let mut req = FitRequest::new(Kind::Jitter, mean_ms, seed).with_goal(Metric::DelayMsP99, p99_ms);
    req.jitter_dist = dist;
    req.jitter_correlation = rho;
    req
}

/// Each law, with and without correlation: the rounded parameters' exact
/// mean and p99 are on target (to a fifth of the tolerance), and the
/// independent confirmation realizes both within the tolerance or, where
/// the p99's interval is wider, within 4 of its standard errors.
#[test]
fn jitter_fits_reach_mean_and_p99() {
    let _machine = machine::not_beside_a_run();
    for (mean, p99, dist, rho) in [
        (100.0, 180.0, JitterDist::Normal, 0.0),
        (100.0, 180.0, JitterDist::Pareto, 0.0),
        (20.0, 60.0, JitterDist::Paretonormal, 0.25),
        (250.0, 900.0, JitterDist::Normal, 0.0),
    ] {
        let req = request(mean, p99, dist, rho, 13);
        let r = run::fit(&req, 2, &|_| {}).unwrap_or_else(|e| panic!("{req:?}: {e}"));
        assert_eq!(r.model, "jitter");
        let ModelSpec::Jitter(p) = &r.spec else { panic!("{:?}", r.spec) };
        assert_eq!((p.dist, p.correlation.get()), (dist, rho));
        for (goal, e) in req.goals.iter().zip(&r.estimates) {
            assert!(rel(r.exact[goal.metric.name()], goal.value) < TOLERANCE_REL / 5.0, "{req:?}: exact {:?}", r.exact);
            let se = (e.ci95[1] - e.ci95[0]) / 2.0 / 1.96;
            let allowed = (TOLERANCE_REL * goal.value).max(4.0 * se);
            assert!((e.value - goal.value).abs() <= allowed, "{req:?} {:?}: {e:?}", goal);
        }
        // Reproducible from the seed.
        assert_eq!(run::fit(&req, 1, &|_| {}).unwrap().params, r.params);
    }
}

#[test]
fn jitter_fits_refuse_what_cannot_be() {
    let _machine = machine::not_beside_a_run();
    // No p99.
    let e = run::fit(&FitRequest::new(Kind::Jitter, 100.0, 1), 1, &|_| {}).unwrap_err();
    assert!(matches!(&e, FitError::BadRequest { problem } if problem.contains("--p99-ms")), "{e}");
    // A p99 not above the mean.
    let e = run::fit(&request(100.0, 90.0, JitterDist::Normal, 0.0, 1), 1, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("above the mean"), "{e}");
    // A correlation outside [0, 1).
    let e = run::fit(&request(100.0, 180.0, JitterDist::Normal, 1.0, 1), 1, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("[0, 1)"), "{e}");
    // A p99 so far above a small mean that even the widest law cannot
    // (clamped at 0, its mean stays above the target): says the least mean.
    let e = run::fit(&request(1.0, 1000.0, JitterDist::Normal, 0.0, 1), 1, &|_| {}).unwrap_err();
    assert!(matches!(e, FitError::Unreachable { .. }) && e.to_string().contains("at least"), "{e}");
}

/// `delay_ms_mean` with `delay_ms_p99` in a scenario: the closed-form
/// jitter, with its law, correlation and order; `scenario check` realizes
/// the mean within 5 standard errors.
#[test]
fn a_jitter_target_stage_resolves_in_closed_form() {
    let _machine = machine::not_beside_a_run();
    let text = "[[stage]]\nname = \"j\"\ndelay_ms_mean = 100\ndelay_ms_p99 = 180\ndist = \"pareto\"\ncorrelation = \"20%\"\norder = \"fifo\"\n";
    let spec = parse_str(text, "t.toml", "t").unwrap();
    let st = &spec.phases[0].stages[0];
    let ModelSpec::Jitter(p) = &st.model else { panic!("{:?}", st.model) };
    assert_eq!((p.dist, p.correlation.get(), p.order), (JitterDist::Pareto, 0.2, netfi::model::Order::Fifo));
    assert_eq!(st.preset.as_deref(), Some("fit jitter 100 ms p99 180 ms pareto"));
    let m = netfi::model::Jitter::new(p).unwrap();
    assert!(rel(m.mean_ms_exact(), 100.0) < 1e-6 && rel(m.quantile_ms(0.99), 180.0) < 1e-6);
    // Uncorrelated, reordering: the realized mean of 10^5 delays.
    let spec = parse_str("[[stage]]\ndelay_ms_mean = 100\ndelay_ms_p99 = 180\n", "t.toml", "t").unwrap();
    let ModelSpec::Jitter(p) = &spec.phases[0].stages[0].model else { panic!() };
    let sd = p.sd_ms;
    let n = 100_000u64;
    let r = check::run(Scenario::new(&spec, 3).unwrap(), &Arrivals::Rate { frames: n, rate_hz: 1000.0 }, 1 << 18, |_| {});
    let mean = r.delay_ms.mean;
    assert!((mean - 100.0).abs() < 5.0 * sd / (n as f64).sqrt(), "mean {mean}");
}

#[test]
fn jitter_target_stages_name_file_line_and_field() {
    let _machine = machine::not_beside_a_run();
    for (text, line, field, says) in [
        ("[[stage]]\ndelay_ms_mean = 100\ndelay_ms_p99 = 50\n", 3, "delay_ms_p99", "above the mean"),
        ("[[stage]]\ndelay_ms_mean = 100\ndelay_ms_p99 = 180\ndist = \"cauchy\"\n", 4, "dist", "normal, pareto, paretonormal"),
        ("[[stage]]\ndelay_ms_mean = 100\ndelay_ms_p99 = 180\ncorrelation = 1.5\n", 4, "correlation", "[0, 1]"),
        ("[[stage]]\ndelay_ms_mean = 100\ndelay_ms_p99 = 180\nsd_ms = 3\n", 4, "sd_ms", "jitter target"),
    ] {
        let e = parse_str(text, "t.toml", "t").unwrap_err();
        assert_eq!((e.line, e.field.as_deref()), (Some(line), Some(field)), "{e}\n{text}");
        assert!(e.to_string().contains(says), "{e}");
    }
}
