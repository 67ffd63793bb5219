//! The pure parts, without processes: Latin squares, schedules, the study
//! file's errors, and the statistics against published examples.

use netfi::study::file::BlockOrder;
use netfi::study::parse_study;
use netfi::study::schedule::{balance, position_counts, schedule};
use netfi::study::square::balanced_latin_square;
use netfi::study::stats::{holm, paired_t, wilcoxon, WilcoxonMethod};

/// Every balanced Latin square from 2 to 10 blocks: each row an order of
/// every block; each block in each position equally often; each ordered
/// pair of blocks neighbours equally often (once for even n, twice for odd
/// n, whose design is the square and its mirror).
#[test]
fn balanced_latin_squares_of_2_to_10_blocks_are_balanced_in_position_and_carry_over() {
    for n in 2..=10usize {
        let rows = balanced_latin_square(n);
        let expected_rows = if n % 2 == 0 { n } else { 2 * n };
        assert_eq!(rows.len(), expected_rows, "n = {n}");
        for row in &rows {
            let mut sorted = row.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..n).collect::<Vec<_>>(), "n = {n}: {row:?} is not an order of every block");
        }
        let per_position = rows.len() / n;
        for pos in 0..n {
            for b in 0..n {
                let count = rows.iter().filter(|r| r[pos] == b).count();
                assert_eq!(count, per_position, "n = {n}: block {b} stands {count} times in position {pos}");
            }
        }
        let per_pair = rows.len() / n;
        for a in 0..n {
            for b in (0..n).filter(|&b| b != a) {
                let count = rows.iter().flat_map(|r| r.windows(2)).filter(|w| w[0] == a && w[1] == b).count();
                assert_eq!(count, per_pair, "n = {n}: {b} follows {a} {count} times");
            }
        }
    }
    // The textbook square of four: ABDC, BCAD, CDBA, DACB.
    assert_eq!(balanced_latin_square(4), vec![vec![0, 1, 3, 2], vec![1, 2, 0, 3], vec![2, 3, 1, 0], vec![3, 0, 2, 1]]);
}

/// The paper's design with `participants` participants and `seed`.
pub fn paper_study(participants: usize, seed: u64) -> String {
    let mut text = format!(
        "name = \"paper\"\nseed = {seed}\n[questionnaires]\nsus = \"start\"\ntlx = \"block\"\n\
         [[block]]\nname = \"free\"\nconditions = [\"Normal\"]\ntrials = 3\n\
         [[block]]\nname = \"packet loss\"\nconditions = [\"PLM-1\", \"PLM-2\", \"PLM-3\"]\n\
         [[block]]\nname = \"delay\"\nconditions = [\"DLM-1\", \"DLM-2\", \"DLM-3\"]\n\
         [[block]]\nname = \"communication loss\"\nconditions = [\"CLM-1\", \"CLM-2\", \"CLM-3\"]\n"
    );
    for p in 1..=participants {
        text += &format!("[[participant]]\nid = \"P{p:02}\"\ngroup = \"{}\"\n", ["novice", "intermediate", "expert"][p % 3]);
    }
    text
}

#[test]
fn the_same_seed_gives_the_same_schedules_and_a_whole_square_is_balanced() {
    let a = parse_study(&paper_study(8, 2025), "a.toml", "a").unwrap();
    let b = parse_study(&paper_study(8, 2025), "b.toml", "b").unwrap();
    for p in 0..8 {
        assert_eq!(schedule(&a, p), schedule(&b, p), "participant {p}");
        let s = schedule(&a, p);
        assert_eq!(s.trials.len(), 12);
        // Every block's trials are together, in the participant's block order.
        let order: Vec<usize> = s.trials.iter().map(|t| t.block).collect();
        let mut dedup = order.clone();
        dedup.dedup();
        assert_eq!(dedup, s.blocks);
        // A SUS before everything, a TLX after each block.
        assert_eq!(s.due.iter().map(|d| d.key()).collect::<Vec<_>>()[0], "sus");
        assert_eq!(s.due.len(), 5);
    }
    // Eight participants take the square of four twice: each block in each
    // position exactly twice.
    assert!(position_counts(&a).iter().flatten().all(|&c| c == 2), "{:?}", position_counts(&a));
    assert!(balance(&a).contains("every block in every position 2 time(s)"), "{}", balance(&a));
    // Fifteen are three squares and three rows: 3 to 4 times.
    let c = parse_study(&paper_study(15, 2025), "c.toml", "c").unwrap();
    assert!(balance(&c).contains("add 1 participant(s)") && balance(&c).contains("3 to 4 times"), "{}", balance(&c));
    // Pinned: the schedule does not change with a version of a dependency.
    let p1 = schedule(&a, 0);
    let names: Vec<&str> = p1.trials.iter().map(|t| a.conditions[t.condition].name.as_str()).collect();
    assert_eq!(names, PINNED_P01, "participant P01's schedule under seed 2025 changed");
    assert_eq!(p1.trials[0].seed, PINNED_P01_SEED);
}

/// Participant P01's conditions in order, seed 2025 (recorded when the rule was written).
const PINNED_P01: [&str; 12] = ["Normal", "Normal", "Normal", "PLM-2", "PLM-3", "PLM-1", "CLM-1", "CLM-2", "CLM-3", "DLM-2", "DLM-1", "DLM-3"];
const PINNED_P01_SEED: u64 = 14_716_294_976_397_898_109;

/// The shuffle within a block is uniform: over 6,000 participants the six
/// orders of three severities come up 1,000 times each in expectation; the
/// chi-square statistic (5 degrees of freedom) stays below 20.52, its 0.999
/// quantile. The schedule is a function of the seed, so this either always
/// passes or always fails for this file.
#[test]
fn severities_are_shuffled_uniformly_within_a_block() {
    let m = 6000;
    let study = parse_study(&paper_study(m, 99), "u.toml", "u").unwrap();
    let plm = study.blocks.iter().position(|b| b.name == "packet loss").unwrap();
    let mut counts = std::collections::BTreeMap::<Vec<usize>, u32>::new();
    for p in 0..m {
        let order: Vec<usize> = schedule(&study, p).trials.iter().filter(|t| t.block == plm).map(|t| t.condition).collect();
        *counts.entry(order).or_default() += 1;
    }
    assert_eq!(counts.len(), 6, "{counts:?}");
    let e = m as f64 / 6.0;
    let chi2: f64 = counts.values().map(|&o| (f64::from(o) - e).powi(2) / e).sum();
    assert!(chi2 < 20.52, "chi-square {chi2:.2} over 5 df: the shuffle is not uniform ({counts:?})");
    // Another seed gives other orders.
    let other = parse_study(&paper_study(m, 100), "u.toml", "u").unwrap();
    let differ = (0..50).filter(|&p| schedule(&study, p).trials != schedule(&other, p).trials).count();
    assert!(differ >= 45, "only {differ} of 50 schedules differ between seeds 99 and 100");
}

#[test]
fn an_explicit_table_gives_each_participant_their_line() {
    let text = "seed = 1\n[order]\nblocks = \"table\"\nwithin = \"fixed\"\n\
                [[block]]\nname = \"a\"\nconditions = [\"Normal\"]\n[[block]]\nname = \"b\"\nconditions = [\"PLM-1\", \"PLM-2\"]\n\
                [[participant]]\nid = \"X\"\nblocks = [\"b\", \"a\"]\n[[participant]]\nid = \"Y\"\nblocks = [1, 2]\n";
    let s = parse_study(text, "t.toml", "t").unwrap();
    assert_eq!(s.order, BlockOrder::Table);
    let x = schedule(&s, 0);
    assert_eq!(x.blocks, vec![1, 0]);
    let names: Vec<&str> = x.trials.iter().map(|t| s.conditions[t.condition].name.as_str()).collect();
    assert_eq!(names, ["PLM-1", "PLM-2", "Normal"]);
    assert_eq!(schedule(&s, 1).blocks, vec![0, 1]);
}

/// A bad study file is refused with its file, line and field.
#[test]
fn bad_study_files_are_refused_naming_the_line_and_field() {
    let tables = "[[block]]\nname = \"a\"\nconditions = [\"Normal\", \"PLM-2\"]\n[[participant]]\nid = \"P1\"\n";
    let base = format!("seed = 1\n{tables}");
    let cases: &[(&str, &str, &str)] = &[
        // (file, expected "file:line: `field`", expected words)
        (&base.replace("\"PLM-2\"]", "\"PLM-9\"]"), "s.toml:4: `block[1].conditions[2]`", "neither a `[[condition]]`"),
        ("seed = \"x\"\n", "s.toml:1: `seed`", "expected an integer"),
        (&format!("name = \"n\"\n{tables}"), "s.toml: `seed`", "missing"),
        (&format!("colour = 3\n{base}"), "s.toml:1: `colour`", "unknown field"),
        (&format!("{base}colour = [3]\n"), "s.toml:7: `participant[1].colour`", "a string, a number or a boolean"),
        (&format!("{base}[[participant]]\nid = \"P1\"\n"), "s.toml:8: `participant[2].id`", "two participants"),
        (&format!("{base}[trial]\nrun_args = [\"--no-isolate\", \"--seed\", \"3\"]\n"), "s.toml:8: `trial.run_args[2]`", "--seed"),
        (&format!("{base}[trial]\nrun_args = [\"--duration=3\"]\n"), "s.toml:8: `trial.run_args[1]`", "`--duration`: write it as `trial.duration_s`"),
        (&format!("{base}[trial]\nrun_args = [\"--no-isolat\"]\n"), "s.toml:8: `trial.run_args[1]`", "unexpected argument '--no-isolat' found"),
        (&format!("{base}[trial]\nrun_args = [\n  \"--no-isolate\",\n  \"--rt-priority\", \"0\",\n]\n"), "s.toml:10: `trial.run_args[2]`", "invalid value '0' for '--rt-priority"),
        (&format!("{base}[trial]\nrun_args = [\"--no-isolate\", \"extra\"]\n"), "s.toml:8: `trial.run_args[2]`", "unexpected argument 'extra'"),
        (&format!("{base}[trial]\nrun_args = [\"--video-mbps\", \"2\", \"--streams\", \"2\"]\n"), "s.toml:8: `trial.run_args`", "goes with one stream"),
        (&format!("{base}[trial]\nduration_s = -1\n"), "s.toml:8: `trial.duration_s`", "more than 0"),
        (&format!("{base}[[condition]]\nname = \"x\"\nstage = [{{ model = \"bernoulli\", p = 2 }}]\n"), "s.toml:9: `condition[1].stage`", "`p`"),
        (&format!("seed = 1\n[order]\nblocks = \"table\"\n{tables}"), "s.toml:7: `participant[1].blocks`", "missing"),
        (&format!("seed = 1\n[order]\nblocks = \"zigzag\"\n{tables}"), "s.toml:3: `order.blocks`", "latin"),
        (&format!("{base}[[block]]\nname = \"a\"\nconditions = [\"DLM-1\"]\n"), "s.toml:8: `block[2].name`", "two blocks"),
        (&base.replace("name = \"a\"", "name = \"a/b\""), "s.toml:3: `block[1].name`", "folder"),
        (&format!("seed = 1\nbaseline = \"DLM-3\"\n{tables}"), "s.toml:2: `baseline`", "not a condition"),
        (&format!("seed = 1\ntrials = 0\n{tables}"), "s.toml:2: `trials`", "1 to 100"),
    ];
    for (text, at, words) in cases {
        let e = parse_study(text, "s.toml", "s").expect_err(text).to_string();
        assert!(e.starts_with(at), "expected `{at}…`, got: {e}\n--- file:\n{text}");
        assert!(e.contains(words), "expected `{words}` in: {e}");
    }
    assert!(parse_study(&base, "s.toml", "s").is_ok());
    let ok = parse_study(&format!("{base}[trial]\nrun_args = [\"--no-isolate\", \"--return-scenario=DLM-1\", \"--video-mbps\", \"2\"]\n"), "s.toml", "s").unwrap();
    assert_eq!(ok.trial.run_args, ["--no-isolate", "--return-scenario=DLM-1", "--video-mbps", "2"], "kept as written");
    let e = parse_study(&format!("{base}[trial]\nrun_args = [\"--seed=3\"]\n"), "s.toml", "s").unwrap_err().to_string();
    assert_eq!(
        e,
        "s.toml:8: `trial.run_args[1]`: `--seed`: the study sets it for each trial (the study decides --out, --seed, --run-id, --json, --duration-s, --duration, --frames, --capture, --report-json, --rate-hz, --console, --robot)"
    );
    // Who plays the trials, and where the lab's programs are met.
    let lab_cases: [(String, &str, &str); 8] = [
        (format!("{base}[trial]\npeers = \"robots\"\n"), "s.toml:8: `trial.peers`", "lab (the lab's console and robot"),
        (format!("{base}[trial.lab]\ningress = \"udp://127.0.0.1:9\"\n"), "s.toml:7: `trial.peers`", "say who plays each trial"),
        (format!("{base}[trial]\npeers = \"lab\"\n[trial.lab]\nscenario = \"PLM-1\"\n"), "s.toml:9: `trial.lab.scenario`", "not where a trial meets the lab's programs"),
        (format!("{base}[trial]\npeers = \"lab\"\n[trial.lab]\ningress = \"tcp://x\"\n"), "s.toml:9: `trial.lab`", "tcp://x"),
        (format!("{base}[trial]\npeers = \"lab\"\ncapture = \"c.lz4\"\n"), "s.toml:8: `trial.capture`", "replayed by netfi's own console"),
        (format!("{base}[trial]\npeers = \"lab\"\npeer_wait_s = 0\n"), "s.toml:9: `trial.peer_wait_s`", "more than 0"),
        (format!("{base}[clean]\nnetfi_added_p99_ms = -1\n"), "s.toml:8: `clean.netfi_added_p99_ms`", "more than 0"),
        (format!("{base}[trial]\nrun_args = [\"--console\", \"lab\"]\n"), "s.toml:8: `trial.run_args[1]`", "write it as `trial.peers`"),
    ];
    for (text, at, words) in &lab_cases {
        let e = parse_study(text, "s.toml", "s").expect_err(text).to_string();
        assert!(e.starts_with(at), "expected `{at}…`, got: {e}\n--- file:\n{text}");
        assert!(e.contains(words), "expected `{words}` in: {e}");
    }
    let lab = parse_study(&format!("{base}[trial]\npeers = \"lab\"\n[trial.lab]\ningress = \"udp://127.0.0.1:9\"\nconsole_from = \"first\"\negress = \"udp://127.0.0.1:10\"\nno-return = true\n"), "s.toml", "s").unwrap();
    let run = lab.trial.run("PLM-1", None).unwrap();
    assert_eq!((run.peers.console(), run.peers.robot()), (netfi::service::args::Peer::Lab, netfi::service::args::Peer::Lab));
    assert_eq!(run.peers.ends.ingress.to_string(), "udp://127.0.0.1:9");
    // The same file as a dry run: netfi's own ends, the lab's left aside.
    let dry = parse_study(&format!("{base}[trial]\npeers = \"synthetic\"\n[trial.lab]\ningress = \"udp://127.0.0.1:9\"\nconsole_from = \"first\"\n"), "s.toml", "s").unwrap();
    let run = dry.trial.run("PLM-1", None).unwrap();
    assert_eq!((run.peers.console(), run.peers.robot()), (netfi::service::args::Peer::Own, netfi::service::args::Peer::Own));
}

/// Student's sleep data (Cushny and Peebles, 1905), as R ships it
/// (`datasets::sleep`): `t.test(extra ~ group, data = sleep, paired = TRUE)`
/// gives t = -4.0621, df = 9, p-value = 0.002833; `wilcox.test` on the same
/// pairs V = 0, p-value = 0.009091 (normal approximation: a zero and a tie).
#[test]
// A depression score of 3.14 is a measurement, not an approximation of π.
#[allow(clippy::approx_constant)]
fn the_paired_tests_give_the_published_figures() {
    let g1 = [0.7, -1.6, -0.2, -1.2, -0.1, 3.4, 3.7, 0.8, 0.0, 2.0];
    let g2 = [1.9, 0.8, 1.1, 0.1, -0.1, 4.4, 5.5, 1.6, 4.6, 3.4];
    let d: Vec<f64> = g1.iter().zip(&g2).map(|(a, b)| a - b).collect();
    let t = paired_t(&d).unwrap();
    assert!((t.t - -4.0621).abs() < 5e-5, "t = {}", t.t);
    assert_eq!(t.df, 9.0);
    assert!((t.p - 0.002833).abs() < 5e-7, "p = {}", t.p);
    assert!((t.mean_difference - -1.58).abs() < 1e-12);
    let w = wilcoxon(&d).unwrap();
    assert_eq!((w.v, w.n, w.method), (0.0, 9, WilcoxonMethod::Normal));
    assert!((w.p - 0.009091).abs() < 5e-7, "p = {}", w.p);
    // Hollander and Wolfe's depression scores (R's `?wilcox.test`):
    // V = 40, one-sided p = 0.01953, so two-sided 0.0390625 exactly (5 of
    // the 512 sign patterns reach 40 or more).
    let x = [1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30];
    let y = [0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29];
    let d: Vec<f64> = x.iter().zip(&y).map(|(a, b)| a - b).collect();
    let w = wilcoxon(&d).unwrap();
    assert_eq!((w.v, w.method), (40.0, WilcoxonMethod::Exact));
    assert!((w.p - 0.0390625).abs() < 1e-15, "p = {}", w.p);
    // Ten positive differences: the most extreme of 1,024 patterns, twice.
    assert!((wilcoxon(&[1., 2., 3., 4., 5., 6., 7., 8., 9., 10.]).unwrap().p - 2.0 / 1024.0).abs() < 1e-15);
    // Undefined cases say so.
    assert!(paired_t(&[1.0, 1.0, 1.0]).is_none() && paired_t(&[1.0]).is_none() && wilcoxon(&[0.0, 0.0]).is_none());
    // R: p.adjust(c(0.01, 0.02, 0.03, 0.04, 0.05), "holm") = 0.05 0.08 0.09 0.09 0.09.
    let h = holm(&[0.03, 0.01, 0.05, 0.02, 0.04]);
    let want = [0.09, 0.05, 0.09, 0.08, 0.09];
    assert!(h.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12), "{h:?}");
}
