//! The shipped fault parameter database (`config/faultdb.toml`).

use crate::common::machine;
use netfi::fit::db::{self, Database, EntryView, Grid, GRIDS};
use netfi::fit::{run, Kind, TOLERANCE_REL, TOOL_VERSION};

fn shipped() -> Database {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/faultdb.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let db = Database::parse(&text).unwrap_or_else(|e| panic!("{e}"));
    // The copy compiled into the library is this file.
    assert_eq!(db::embedded().unwrap(), &db);
    db
}

/// 20 entries spread over the three grids, including both ends of each.
fn sample(entries: &[EntryView]) -> Vec<EntryView> {
    let mut picked = Vec::new();
    for g in GRIDS {
        let of_kind: Vec<&EntryView> = entries.iter().filter(|e| e.kind == g.kind).collect();
        let n = match g.kind {
            Kind::Delay => 8,
            _ => 6,
        };
        for i in 0..n {
            picked.push(of_kind[i * (of_kind.len() - 1) / (n - 1)].clone());
        }
    }
    picked
}

#[test]
fn the_database_parses_and_covers_its_grid() {
    let _machine = machine::not_beside_a_run();
    let db = shipped();
    assert_eq!(db.format, db::FORMAT);
    assert_eq!(db.tolerance_rel, TOLERANCE_REL);
    assert_eq!(db.frame_rate_hz, 1000.0);
    assert_eq!((db.loss.len(), db.delay.len(), db.outage.len()), (95, 260, 95));
    let entries = db.entries();
    for g in GRIDS {
        let targets: Vec<f64> = entries.iter().filter(|e| e.kind == g.kind).map(|e| e.entry.target).collect();
        assert_eq!(targets, g.targets(), "{:?}", g.kind);
    }
    for e in &db.loss {
        assert_eq!(e.model, "ge_lomax");
        assert_eq!(e.tool_version, TOOL_VERSION);
        assert_eq!(e.params.transition, vec![vec![0.95, 0.05], vec![0.1, 0.9]]);
    }
    assert!(db.delay.iter().all(|e| e.model == "delay" && e.windows.is_none()));
    assert!(db.outage.iter().all(|e| e.model == "outage" && e.windows.unwrap_or(0) > 0));
}

/// Every entry without simulating: valid parameters whose closed form is the
/// stored one and on target, a realized value within the tolerance and
/// inside its own interval.
#[test]
fn every_entry_is_on_target_by_closed_form() {
    let _machine = machine::not_beside_a_run();
    let problems: Vec<String> = shipped().entries().iter().filter_map(|e| e.check_stored().err()).collect();
    assert!(problems.is_empty(), "{problems:#?}");
}

/// Fast tier: 20 entries re-simulate, with their stored seed, to exactly
/// their stored value, interval and frame count; and with another seed to
/// within the tolerance of their target and consistent with the stored
/// value.
#[test]
fn sampled_entries_reproduce_and_resimulate() {
    let _machine = machine::not_beside_a_run();
    let entries = sample(&shipped().entries());
    assert_eq!(entries.len(), 20);
    let problems: Vec<String> =
        run::par_map(&entries, 2, |e| e.check_reproduces().and_then(|_| e.check_independent()).err())
            .into_iter()
            .flatten()
            .collect();
    assert!(problems.is_empty(), "{problems:#?}");
}

/// Slow tier: all 450 entries, both re-simulations.
#[test]
fn every_entry_reproduces_and_resimulates() {
    let _machine = machine::not_beside_a_run();
    let entries = shipped().entries();
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let problems: Vec<String> =
        run::par_map(&entries, threads, |e| e.check_reproduces().and_then(|_| e.check_independent()).err())
            .into_iter()
            .flatten()
            .collect();
    assert!(problems.is_empty(), "{problems:#?}");
}

/// The database is what this code produces: regenerating sampled entries
/// from their seeds gives the stored parameters and realized values exactly.
#[test]
fn sampled_entries_regenerate_from_their_seeds() {
    let _machine = machine::not_beside_a_run();
    let db = shipped();
    let plan = db::plan(db.seed);
    let picks: Vec<usize> = vec![0, 17, 94, 95, 150, 354, 355, 400, 449];
    let reqs: Vec<_> = picks.iter().map(|&i| plan[i].clone()).collect();
    let fits: Vec<_> = run::fit_many(&reqs, 2, &|_, _| {}).into_iter().map(Result::unwrap).collect();
    let again = Database::from_results(db.seed, &fits).unwrap();
    for e in again.entries() {
        let stored = db.entries().into_iter().find(|s| s.kind == e.kind && s.entry.target == e.entry.target).unwrap();
        assert_eq!(e, stored, "{:?} {}", e.kind, e.entry.target);
    }
}

#[test]
fn lookups_name_the_covered_range() {
    let _machine = machine::not_beside_a_run();
    let db = shipped();
    let e = db.lookup(Kind::Loss, 0.005, "loss").unwrap_err();
    assert!(e.problem.contains("outside") && e.problem.contains("1% to 95%"), "{e}");
    let e = db.lookup(Kind::Loss, 0.305, "loss").unwrap_err();
    assert!(e.problem.contains("nearest: 30% and 31%"), "{e}");
    let e = db.lookup(Kind::Delay, 1400.0, "delay_ms_mean").unwrap_err();
    assert!(e.problem.contains("5 ms to 1300 ms"), "{e}");
    assert_eq!(Grid::of(Kind::Outage).describe(), "outage 1% to 95% in steps of 1%");
    db.lookup(Kind::Outage, 0.95, "outage").unwrap();
    db.lookup(Kind::Delay, 5.0, "delay_ms_mean").unwrap();
}
