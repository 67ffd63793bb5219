//! Target-based scenario stages and the calibrated study presets.

use crate::common::machine;
use netfi::check::{self, Arrivals};
use netfi::fit::db;
use netfi::fit::family::metrics_exact;
use netfi::fit::{FitRequest, Kind};
use netfi::model::Order;
use netfi::scenario::{self, parse_str, ModelSpec, Scenario, ScenarioError};

fn parse(text: &str) -> Result<netfi::scenario::ScenarioSpec, ScenarioError> {
    parse_str(text, "t.toml", "t")
}

#[test]
fn targets_take_the_database_entry() {
    let _machine = machine::not_beside_a_run();
    let spec = parse(
        "[[stage]]\nloss = \"30%\"\n[[stage]]\nname = \"lag\"\ndelay_ms_mean = 250\norder = \"fifo\"\n[[stage]]\noutage = 0.1\n",
    )
    .unwrap();
    let db = db::embedded().unwrap();
    let stages = &spec.phases[0].stages;
    assert_eq!(stages[0].model, db.lookup(Kind::Loss, 0.3, "loss").unwrap());
    assert_eq!(stages[0].preset.as_deref(), Some("faultdb loss 30%"));
    let ModelSpec::Delay(d) = &stages[1].model else { panic!("{:?}", stages[1].model) };
    assert_eq!(d.order, Order::Fifo);
    assert_eq!(stages[1].name.as_deref(), Some("lag"));
    let ModelSpec::Delay(mut reorder) = db.lookup(Kind::Delay, 250.0, "delay_ms_mean").unwrap() else { panic!() };
    reorder.order = Order::Fifo;
    assert_eq!(d, &reorder);
    assert_eq!(stages[2].model, db.lookup(Kind::Outage, 0.1, "outage").unwrap());
    // Printed back, the scenario names the models themselves.
    let again = parse(&spec.to_toml()).unwrap();
    let models =
        |s: &netfi::scenario::ScenarioSpec| s.phases[0].stages.iter().map(|s| s.model.clone()).collect::<Vec<_>>();
    assert_eq!(models(&again), models(&spec));
}

/// A scenario asking for 30% loss realizes it (10^6 frames: a 95% interval
/// of about ±0.2%).
#[test]
fn a_target_scenario_realizes_its_target() {
    let _machine = machine::not_beside_a_run();
    let spec = parse("[[stage]]\nloss = \"30%\"\n").unwrap();
    let r = check::run(
        Scenario::new(&spec, 4).unwrap(),
        &Arrivals::Rate { frames: 1_000_000, rate_hz: 1000.0 },
        1 << 16,
        |_| {},
    );
    let [lo, hi] = r.loss_rate_ci95;
    assert!(lo <= 0.3 && 0.3 <= hi, "{} [{lo}, {hi}]", r.loss_rate);
    assert_eq!(r.stages[0].preset.as_deref(), Some("faultdb loss 30%"));
}

#[test]
fn targets_outside_the_database_are_clear_errors() {
    let _machine = machine::not_beside_a_run();
    for (text, line, field, says) in [
        ("name = \"x\"\n[[stage]]\nloss = \"0.5%\"\n", 3, "loss", "covers loss 1% to 95% in steps of 1%"),
        ("[[stage]]\nloss = \"30.5%\"\n", 2, "loss", "nearest: 30% and 31%"),
        ("[[stage]]\ndelay_ms_mean = 1400\n", 2, "delay_ms_mean", "covers delay 5 ms to 1300 ms in steps of 5 ms"),
        ("[[stage]]\noutage = \"96%\"\n", 2, "outage", "1% to 95%"),
        ("[[stage]]\nloss = \"30%\"\noutage = \"10%\"\n", 3, "outage", "one target"),
        ("[[stage]]\nloss = \"30%\"\norder = \"fifo\"\n", 3, "order", "does not apply"),
        ("[[stage]]\ndelay_ms_mean = \"fast\"\n", 2, "delay_ms_mean", "expected a mean delay in ms"),
        ("[[stage]]\nloss = 3\n", 2, "loss", "not a probability"),
    ] {
        let e = parse(text).expect_err(text);
        assert_eq!((e.line, e.field.as_deref()), (Some(line), Some(field)), "{text}: {e}");
        assert!(e.problem.contains(says), "{text}: {e}");
        assert_eq!(e.location.as_deref(), Some("stage 1"), "{e}");
    }
}

/// Each calibrated preset keeps its study preset's shape and realizes the
/// label exactly (its closed form within 1e-6), and is what `netfi fit …
/// --like` finds.
#[test]
fn calibrated_presets_hit_their_labels() {
    let _machine = machine::not_beside_a_run();
    for (name, kind, label) in [
        ("PLM-1", Kind::Loss, 0.1),
        ("PLM-2", Kind::Loss, 0.3),
        ("PLM-3", Kind::Loss, 0.5),
        ("DLM-1", Kind::Delay, 100.0),
        ("DLM-2", Kind::Delay, 300.0),
        ("DLM-3", Kind::Delay, 500.0),
        ("CLM-1", Kind::Outage, 0.1),
        ("CLM-2", Kind::Outage, 0.3),
        ("CLM-3", Kind::Outage, 0.5),
    ] {
        let cal = format!("{name}-cal");
        let model = scenario::preset_stages(&cal).unwrap().remove(0).model;
        let verbatim = scenario::preset_stages(name).unwrap().remove(0).model;
        let metric = kind.primary();
        let exact = metrics_exact(&model, &[metric], 1_000_000).unwrap()[0];
        assert!(((exact - label) / label).abs() < 1e-6, "{cal}: {exact} vs {label}");
        assert!(scenario::preset_label(&cal).unwrap().ends_with("calibrated"));
        match (&model, &verbatim) {
            (ModelSpec::GeLomax(c), ModelSpec::GeLomax(v)) => {
                assert_eq!((&c.transition, &c.alpha), (&v.transition, &v.alpha), "{cal}");
                assert!((c.lambda[1] / c.lambda[0] - v.lambda[1] / v.lambda[0]).abs() < 1e-6, "{cal}");
            }
            (ModelSpec::Delay(c), ModelSpec::Delay(v)) => {
                assert_eq!((c.min_ms, &c.weights), (v.min_ms, &v.weights), "{cal}");
                let ratio = |p: &netfi::model::DelayParams| p.rates_per_ms.as_ref().map(|r| r[1] / r[0]).unwrap();
                assert!((ratio(c) / ratio(v) - 1.0).abs() < 1e-6, "{cal}");
            }
            (ModelSpec::Outage(c), ModelSpec::Outage(v)) => {
                assert_eq!((c.min_ms, c.max_ms, c.p_start), (v.min_ms, v.max_ms, v.p_start), "{cal}");
            }
            other => panic!("{cal}: {other:?}"),
        }
        let mut req = FitRequest::new(kind, label, 1);
        req.like = Some(name.into());
        let family = netfi::fit::family_of(&req).unwrap();
        let found = netfi::fit::search(
            &req,
            &family,
            &mut |xs| xs.iter().map(|x| family.objective(x, &req.goals, req.objective, 0)).collect(),
            &mut |_, _| {},
        );
        assert_eq!(family.spec(&found.best, true), model, "{cal}");
    }
}

#[test]
fn calibrated_presets_resolve_by_name() {
    let _machine = machine::not_beside_a_run();
    for name in ["PLM-1-cal", "plm1cal", "clm_3_cal", "DLM-2-CAL"] {
        let s = netfi::load::resolve(name).unwrap();
        assert_eq!(s.phases[0].stages.len(), 1, "{name}");
    }
    let s = parse("[[stage]]\npreset = \"CLM-1-cal\"\n").unwrap();
    assert_eq!(s.phases[0].stages[0].preset.as_deref(), Some("CLM-1-cal"));
}
