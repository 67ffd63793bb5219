//! The sans-IO core end to end in simulated time: determinism, stream
//! independence, conservation, and the shipped scenario files.

use crate::common::machine;
use netfi::check::{self, Arrivals};
use netfi::injector::{DropCause, Fate, Injector};
use netfi::scenario::{self, parse_str, Decision, Scenario, ScenarioSpec};

fn spec(text: &str) -> ScenarioSpec {
    parse_str(text, "test.toml", "test").unwrap_or_else(|e| panic!("{e}"))
}

const PIPELINE: &str = r#"
[[stage]]
preset = "PLM-2"
[[stage]]
preset = "DLM-2"
[[stage]]
preset = "CLM-2"
"#;

/// Fates of `n` frames at 1 kHz.
fn fates(spec: &ScenarioSpec, seed: u64, n: u64) -> Vec<Fate> {
    let mut inj: Injector<()> = Injector::new(Scenario::new(spec, seed).unwrap(), 1 << 16);
    (0..n).map(|i| inj.ingress(i * 1_000_000, ()).fate).collect()
}

#[test]
fn same_seed_and_arrivals_give_the_same_fates() {
    let _machine = machine::not_beside_a_run();
    let s = spec(PIPELINE);
    let a = fates(&s, 42, 200_000);
    assert_eq!(a, fates(&s, 42, 200_000));
    let b = fates(&s, 43, 200_000);
    let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    // Another seed must change most delays: it would be a stream bug if not.
    assert!(differ > 100_000, "seeds 42 and 43 differ in only {differ} of 200000 fates");
}

/// The k-th decisions of each stage, identified by label.
fn per_stage_decisions(spec: &ScenarioSpec, seed: u64, n: u64) -> std::collections::BTreeMap<String, Vec<Option<u64>>> {
    // Decide frames one stage at a time by running the pipeline and reading
    // back which stage dropped each frame and the delay it got.
    let mut sc = Scenario::new(spec, seed).unwrap();
    let labels: Vec<String> = sc.phases()[0].stages().iter().map(|s| s.label().to_string()).collect();
    let kinds: Vec<_> = sc.phases()[0].stages().iter().map(|s| s.kind()).collect();
    let mut out: std::collections::BTreeMap<String, Vec<Option<u64>>> = labels.iter().map(|l| (l.clone(), Vec::new())).collect();
    for i in 0..n {
        let t = i * 1_000_000;
        match sc.decide(t, t) {
            Decision::Drop { stage, .. } => {
                for (j, l) in labels.iter().enumerate().take(usize::from(stage)) {
                    if kinds[j] != netfi::model::ModelKind::Delay {
                        out.get_mut(l).unwrap().push(Some(0));
                    }
                }
                out.get_mut(&labels[usize::from(stage)]).unwrap().push(None);
            }
            Decision::Pass { delay_ns } => {
                for (j, l) in labels.iter().enumerate() {
                    // Only one delay stage in these pipelines: it gets the whole delay.
                    let v = if kinds[j] == netfi::model::ModelKind::Delay { delay_ns } else { 0 };
                    out.get_mut(l).unwrap().push(Some(v));
                }
            }
        }
    }
    out
}

#[test]
fn inserting_a_stage_leaves_the_other_stages_decisions_unchanged() {
    let _machine = machine::not_beside_a_run();
    let before = spec("[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n");
    let after = spec(
        "[[stage]]\npreset = \"PLM-2\"\n[[stage]]\nmodel = \"bernoulli\"\np = 0.25\n[[stage]]\npreset = \"DLM-2\"\n",
    );
    let a = per_stage_decisions(&before, 9, 100_000);
    let b = per_stage_decisions(&after, 9, 100_000);
    // The loss stage sees the same frames and decides them identically.
    assert_eq!(a["ge_lomax#0"], b["ge_lomax#0"]);
    // The delay stage sees fewer frames (the new stage drops some), but its
    // k-th decision is the same: its stream is its own.
    let da: Vec<_> = a["delay#0"].iter().flatten().collect();
    let db: Vec<_> = b["delay#0"].iter().flatten().collect();
    assert!(db.len() < da.len() * 8 / 10, "the inserted stage should drop ~25%: {} vs {}", db.len(), da.len());
    assert_eq!(&da[..db.len()], &db[..]);
    // And the inserted stage really did decide something.
    assert!(b["bernoulli#0"].iter().any(|d| d.is_none()));
}

#[test]
fn every_frame_is_accounted_for_at_every_step() {
    let _machine = machine::not_beside_a_run();
    // A small queue so that queue_full happens too.
    let s = spec(PIPELINE);
    let mut inj: Injector<u64> = Injector::new(Scenario::new(&s, 5).unwrap(), 64);
    let mut released = std::collections::HashSet::new();
    let mut scheduled = std::collections::HashSet::new();
    let mut full = 0u64;
    for i in 0..100_000u64 {
        let now = i * 1_000_000;
        while let Some(r) = inj.pop_due(now) {
            assert!(r.release_ns <= now);
            assert_eq!(r.item, r.ingress_index, "the queue returned another frame's item");
            assert!(scheduled.remove(&r.ingress_index), "released a frame never scheduled");
            assert!(released.insert(r.ingress_index));
        }
        let e = inj.ingress(now, i);
        assert_eq!(e.ingress_index, i);
        match e.fate {
            Fate::Scheduled { release_ns, delay_ns } => {
                assert_eq!(release_ns, now + delay_ns);
                scheduled.insert(i);
            }
            Fate::Dropped(DropCause::QueueFull) => full += 1,
            Fate::Dropped(_) => {}
        }
        let c = inj.counts();
        assert!(c.balanced(), "unbalanced at frame {i}: {c:?}");
        assert_eq!(c.held as usize, scheduled.len());
    }
    let c = inj.counts();
    assert!(full > 0 && c.dropped_queue_full == full, "a 64-frame queue under 300 ms of delay at 1 kHz must overflow");
    assert_eq!(c.released as usize, released.len());
}

#[test]
fn malformed_frames_enter_and_are_counted() {
    let _machine = machine::not_beside_a_run();
    let mut inj: Injector<()> = Injector::new(scenario::Scenario::new(&spec(""), 1).unwrap(), 8);
    let e = inj.reject(10, netfi::injector::Invalid::WrongSize);
    assert_eq!(e.ingress_index, 0);
    inj.ingress(20, ());
    inj.reject(30, netfi::injector::Invalid::BadChecksum);
    let c = inj.counts();
    assert_eq!((c.entered, c.dropped(), c.held), (3, 2, 1));
    assert!(c.balanced());
    assert_eq!(inj.drops_by_reason(), vec![("wrong_size", 1), ("bad_checksum", 1)]);
}

#[test]
fn phases_switch_at_their_start_offsets() {
    let _machine = machine::not_beside_a_run();
    let s = spec(
        "[[phase]]\npreset = \"Normal\"\n[[phase]]\nstart_ms = 1000\n[[phase.stage]]\nmodel = \"bernoulli\"\np = 1\n[[phase]]\nstart_ms = 2000\npreset = \"Normal\"\n",
    );
    let mut inj: Injector<()> = Injector::new(Scenario::new(&s, 1).unwrap(), 16);
    // Start the run at an arbitrary clock value: phases count from the first frame.
    let t0 = 5_000_000_000u64;
    let dropped: Vec<bool> = (0..3000u64)
        .map(|ms| {
            let f = inj.ingress(t0 + ms * 1_000_000, ()).fate;
            while inj.pop_due(u64::MAX).is_some() {}
            matches!(f, Fate::Dropped(_))
        })
        .collect();
    assert!(dropped[..1000].iter().all(|d| !d));
    assert!(dropped[1000..2000].iter().all(|d| *d));
    assert!(dropped[2000..].iter().all(|d| !d));
}

#[test]
fn fifo_delay_never_reorders_and_reorder_does() {
    let _machine = machine::not_beside_a_run();
    let fifo = spec("[[stage]]\nmodel = \"delay\"\nmin_ms = 5\ndist = \"uniform\"\njitter_ms = 50\norder = \"fifo\"\n");
    let reorder = spec("[[stage]]\nmodel = \"delay\"\nmin_ms = 5\ndist = \"uniform\"\njitter_ms = 50\n");
    let arrivals = Arrivals::Rate { frames: 100_000, rate_hz: 1000.0 };
    let f = check::run(Scenario::new(&fifo, 1).unwrap(), &arrivals, 1 << 12, |_| {});
    let r = check::run(Scenario::new(&reorder, 1).unwrap(), &arrivals, 1 << 12, |_| {});
    assert_eq!(f.reordered_fraction, 0.0);
    assert_eq!(f.delivered, 100_000);
    // Two frames 1 ms apart with independent U[0,50) jitter: the later one is
    // released first with probability (49/50)²/2 ≈ 0.48 for neighbours; with
    // ~50 frames in flight the RFC 4737 fraction is well above 0.8.
    assert!(r.reordered_fraction > 0.8, "reordered fraction {}", r.reordered_fraction);
    // fifo only ever adds delay: its mean is above the model's 30 ms.
    assert!(f.delay_ms.mean > 30.0 && r.delay_ms.mean > 29.5 && r.delay_ms.mean < 30.5, "{} {}", f.delay_ms.mean, r.delay_ms.mean);
}

#[test]
fn shipped_scenarios_parse_build_and_run() {
    let _machine = machine::not_beside_a_run();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenarios");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let s = netfi::load::parse_file(&path).unwrap_or_else(|e| panic!("{e}"));
            let sc = Scenario::new(&s, s.seed.unwrap_or(1)).unwrap_or_else(|e| panic!("{e}"));
            let r = check::run(sc, &Arrivals::Rate { frames: 50_000, rate_hz: 1000.0 }, 1 << 16, |_| {});
            // Copies (`duplicate`) are counted apart: frames + copies = delivered + dropped.
            assert_eq!(r.frames + r.duplicated, r.delivered + r.dropped.values().sum::<u64>(), "{}", path.display());
            // Printing back and parsing again gives the same scenario.
            let again = parse_str(&s.to_toml(), "again", "again").unwrap_or_else(|e| panic!("{}: {e}\n{}", path.display(), s.to_toml()));
            // (Printing keeps the parameters, not which preset they came from.)
            let models = |x: &ScenarioSpec| -> Vec<_> {
                x.phases.iter().map(|p| (p.start_ms, p.stages.iter().map(|st| (st.name.clone(), st.model.clone())).collect::<Vec<_>>())).collect()
            };
            assert_eq!(models(&again), models(&s), "{}", path.display());
            n += 1;
        }
    }
    assert!(n >= 5, "found only {n} scenario files");
}

#[test]
fn every_preset_resolves_by_name() {
    let _machine = machine::not_beside_a_run();
    for name in scenario::PRESET_NAMES {
        let s = netfi::load::resolve(name).unwrap();
        assert_eq!(s.phases[0].stages.len(), usize::from(name != "Normal"));
        assert_eq!(netfi::load::resolve(&name.to_lowercase().replace('-', "")).unwrap(), s);
    }
    let e = netfi::load::resolve("PLM-7").unwrap_err();
    assert!(e.problem.contains("neither a scenario file nor a preset"), "{e}");
}
