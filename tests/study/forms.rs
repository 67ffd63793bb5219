//! The pure parts of the questionnaires, the measures, the block kept
//! first, times with units, and Pearson's correlation against references
//! computed independently of the code under test.

use netfi::study::parse_study;
use netfi::study::questionnaire::{complete, sus_score, tlx_pairs, tlx_raw, tlx_scale_named, tlx_weighted, tlx_weights, Instrument, SUS_STATEMENTS, TLX_FORM, TLX_PAIRS};
use netfi::study::schedule::{balance, position_counts, schedule};
use netfi::study::stats::pearson;

const TABLES: &str = "[[block]]\nname = \"free\"\nconditions = [\"Normal\"]\n[[block]]\nname = \"loss\"\nconditions = [\"PLM-1\", \"PLM-2\"]\n\
[[block]]\nname = \"delay\"\nconditions = [\"DLM-1\"]\n[[block]]\nname = \"outage\"\nconditions = [\"CLM-1\"]\n";

fn participants(n: usize) -> String {
    (1..=n).map(|p| format!("[[participant]]\nid = \"P{p}\"\n")).collect()
}

/// The two-sided p of Student's t with an odd number of degrees of
/// freedom, by the closed form of Abramowitz and Stegun 26.7.3:
/// P(|T| ≤ t) = 2/π (θ + sin θ cos θ (1 + 2/3 cos²θ + … + 2·4⋯(ν−3) / 1·3⋯(ν−2) cos^(ν−3) θ)),
/// θ = atan(t / √ν).
fn t_p_odd(t: f64, df: u32) -> f64 {
    assert!(df % 2 == 1);
    let th = (t.abs() / f64::from(df).sqrt()).atan();
    let (s, c) = th.sin_cos();
    let (mut term, mut sum) = (1.0, 1.0);
    for k in 1..(df - 1) / 2 {
        term *= f64::from(2 * k) / f64::from(2 * k + 1) * c * c;
        sum += term;
    }
    1.0 - 2.0 / std::f64::consts::PI * (th + s * c * sum)
}

#[test]
fn pearsons_r_and_its_p_match_references_computed_otherwise() {
    // R's `?cor.test` data (Hollander and Wolfe): `cor.test(x, y)` gives
    // t = 1.8411, df = 7, p-value = 0.1082, cor 0.5711816.
    let x = [44.4, 45.9, 41.9, 53.3, 44.7, 44.1, 50.7, 45.2, 60.1];
    let y = [2.6, 3.1, 2.5, 5.0, 3.6, 4.0, 5.2, 2.8, 3.8];
    let pairs: Vec<(f64, f64)> = x.into_iter().zip(y).collect();
    let c = pearson(&pairs).unwrap();
    assert_eq!(c.n, 9);
    assert!((c.r - 0.5711816).abs() < 5e-8, "r = {}", c.r);
    let t = c.r * 7f64.sqrt() / (1.0 - c.r * c.r).sqrt();
    assert!((t - 1.8411).abs() < 5e-5, "t = {t}");
    assert!((c.p - 0.1082).abs() < 5e-5, "p = {}", c.p);
    assert!((c.p - t_p_odd(t, 7)).abs() < 1e-12, "p = {} against the closed form {}", c.p, t_p_odd(t, 7));
    // By hand: x = 1..5, y = 2,4,5,4,5: Sxy = 6, Sxx = 10, Syy = 6, so
    // r = 6/√60 exactly, t = 3/√2, and with 3 degrees of freedom
    // p = 1 − 2/π (atan √1.5 + √1.5/2.5).
    let c = pearson(&[(1.0, 2.0), (2.0, 4.0), (3.0, 5.0), (4.0, 4.0), (5.0, 5.0)]).unwrap();
    assert!((c.r - 6.0 / 60f64.sqrt()).abs() < 1e-15, "r = {}", c.r);
    let x = 1.5f64.sqrt();
    let p = 1.0 - 2.0 / std::f64::consts::PI * (x.atan() + x / 2.5);
    assert!((c.p - p).abs() < 1e-12, "p = {}, closed form {p}", c.p);
    // A negative correlation keeps its sign; a perfect one has p = 0.
    assert!(pearson(&[(1.0, 5.0), (2.0, 4.0), (3.0, 2.0), (4.0, 1.0)]).unwrap().r < 0.0);
    let line = pearson(&[(1.0, 2.0), (2.0, 4.0), (3.0, 7.0)]).unwrap();
    assert!(line.r > 0.98 && line.p < 0.1, "{line:?}");
    let exact = pearson(&[(0.0, 0.0), (1.0, 2.0), (2.0, 4.0)]).unwrap();
    assert!((exact.r - 1.0).abs() < 1e-15 && exact.p < 1e-6, "a straight line: {exact:?}");
    // Undefined: fewer than three pairs, or a constant side.
    assert!(pearson(&[(1.0, 2.0), (2.0, 3.0)]).is_none());
    assert!(pearson(&[(1.0, 2.0), (2.0, 2.0), (3.0, 2.0)]).is_none());
}

#[test]
fn the_tlx_weighting_counts_each_scale_chosen_in_its_pairs() {
    assert_eq!(tlx_pairs().len(), TLX_PAIRS);
    assert_eq!(tlx_pairs()[0], (0, 1));
    assert_eq!(tlx_pairs()[14], (4, 5));
    // The first of each pair every time: mental 5, physical 4, …, frustration 0.
    let first: Vec<usize> = tlx_pairs().iter().map(|p| p.0).collect();
    let w = tlx_weights(&first).unwrap();
    assert_eq!(w, [5, 4, 3, 2, 1, 0]);
    assert_eq!(w.iter().sum::<u32>(), 15);
    let ratings = [55, 30, 40, 25, 60, 35];
    // (5·55 + 4·30 + 3·40 + 2·25 + 1·60 + 0·35) / 15 = 625 / 15.
    assert_eq!(tlx_weighted(&ratings, &w), 625.0 / 15.0);
    assert_eq!(tlx_raw(&ratings).unwrap(), 245.0 / 6.0);
    // The weights sum to 15, so equal ratings score themselves.
    assert_eq!(tlx_weighted(&[40; 6], &w), 40.0);
    // A choice outside its pair, or too few, is refused.
    let mut wrong = first.clone();
    wrong[0] = 3;
    assert!(tlx_weights(&wrong).unwrap_err().contains("pair 1 is mental_demand or physical_demand"));
    assert!(tlx_weights(&first[..14]).unwrap_err().contains("15 pairs, 14"));
    assert_eq!(tlx_scale_named("performance"), Some(3));
    assert_eq!(tlx_scale_named("Mental"), Some(0));
    assert_eq!(tlx_scale_named("frustration_level"), None);
}

#[test]
fn a_form_is_complete_only_when_every_item_was_answered() {
    let mut sus: Vec<Option<u32>> = [4, 2, 5, 1, 4, 2, 5, 1, 4, 2].into_iter().map(Some).collect();
    assert_eq!(sus_score(&complete(Instrument::Sus, &sus).unwrap()).unwrap(), 85.0);
    sus[2] = None;
    sus[9] = None;
    let e = complete(Instrument::Sus, &sus).unwrap_err();
    assert!(e.contains("not answered: SUS item 3, 10"), "{e}");
    let tlx = [Some(10), None, Some(30), Some(40), Some(50), Some(60)];
    assert!(complete(Instrument::Tlx, &tlx).unwrap_err().contains("NASA-TLX scale physical_demand"));
    assert!(complete(Instrument::Tlx, &[Some(1); 5]).unwrap_err().contains("6 answers expected, 5 given"));
    // The forms' words: the standard statements and anchors.
    assert_eq!(SUS_STATEMENTS[0], "I think that I would like to use this system frequently.");
    assert_eq!(SUS_STATEMENTS[9], "I needed to learn a lot of things before I could get going with this system.");
    let performance = TLX_FORM.iter().find(|s| s.key == "performance").unwrap();
    assert_eq!((performance.low, performance.high), ("Perfect", "Failure"));
}

#[test]
fn a_block_kept_first_leaves_the_others_counterbalanced() {
    let text = format!("seed = 4\n[order]\nfirst = \"free\"\n{TABLES}{}", participants(6));
    let s = parse_study(&text, "s.toml", "s").unwrap();
    assert_eq!(s.first_block, Some(0));
    for p in 0..6 {
        assert_eq!(schedule(&s, p).blocks[0], 0, "P{}", p + 1);
    }
    // Three other blocks: a square of 6 rows, each block in positions 2–4 twice.
    let counts = position_counts(&s);
    assert_eq!(counts[0], [6, 0, 0, 0]);
    for (b, row) in counts.iter().enumerate().skip(1) {
        assert_eq!(row, &[0, 2, 2, 2], "block {b}");
    }
    let said = balance(&s);
    assert!(said.starts_with("`free` first for everyone, then balanced Latin square of 6 rows"), "{said}");
    assert!(said.ends_with("every block in every position 2 time(s)"), "{said}");
    // Carry-over balance of the others: each ordered pair neighbours equally often.
    let rows: Vec<Vec<usize>> = (0..6).map(|p| schedule(&s, p).blocks[1..].to_vec()).collect();
    for a in 1..4 {
        for b in (1..4).filter(|&b| b != a) {
            let n = rows.iter().flat_map(|r| r.windows(2)).filter(|w| w[0] == a && w[1] == b).count();
            assert_eq!(n, 2, "{b} after {a}");
        }
    }
    // Only with a Latin square, and only a block of the file.
    let e = parse_study(&format!("seed = 4\n[order]\nblocks = \"fixed\"\nfirst = \"free\"\n{TABLES}{}", participants(1)), "s.toml", "s").unwrap_err();
    assert!(e.to_string().starts_with("s.toml:4: `order.first`: only with"), "{e}");
    let e = parse_study(&format!("seed = 4\n[order]\nfirst = \"fre\"\n{TABLES}{}", participants(1)), "s.toml", "s").unwrap_err();
    assert!(e.to_string().contains("`fre` is not a block (blocks: free, loss, delay, outage)"), "{e}");
    // One block, kept first: nothing left to balance.
    let one = parse_study("seed = 1\n[order]\nfirst = \"a\"\n[[block]]\nname = \"a\"\nconditions = [\"Normal\"]\n[[participant]]\nid = \"P\"\n", "s.toml", "s").unwrap();
    assert_eq!(schedule(&one, 0).blocks, [0]);
}

#[test]
fn times_take_units_and_measures_are_columns() {
    let base = format!("seed = 1\n{TABLES}{}", participants(1));
    for (written, seconds) in [("600", 600.0), ("\"10min\"", 600.0), ("\"90 s\"", 90.0), ("\"1.5h\"", 5400.0), ("\"250ms\"", 0.25), ("2.5", 2.5)] {
        let s = parse_study(&format!("{base}[trial]\nduration_s = {written}\n"), "s.toml", "s").unwrap();
        assert_eq!(s.trial.duration_s, Some(seconds), "{written}");
    }
    let e = parse_study(&format!("{base}[trial]\nduration_s = \"10 parsecs\"\n"), "s.toml", "s").unwrap_err().to_string();
    assert!(e.starts_with("s.toml:17: `trial.duration_s`: \"10 parsecs\" is not a duration"), "{e}");
    let e = parse_study(&format!("{base}[trial]\nduration_s = \"2 days\"\n"), "s.toml", "s").unwrap_err().to_string();
    assert!(e.contains("not a duration"), "{e}");
    let e = parse_study(&format!("{base}[trial]\nduration_s = \"25h\"\n"), "s.toml", "s").unwrap_err().to_string();
    assert!(e.contains("90000 s: a trial lasts more than 0 and at most 86400 s"), "{e}");

    let m = parse_study(&format!("{base}[[measure]]\nname = \"drops\"\nlabel = \"Pegs dropped\"\n[[measure]]\nname = \"failed_grasps\"\n"), "s.toml", "s").unwrap();
    let names: Vec<(&str, &str)> = m.measures.iter().map(|m| (m.name.as_str(), m.label.as_str())).collect();
    assert_eq!(names, [("drops", "Pegs dropped"), ("failed_grasps", "failed grasps")]);
    for (extra, words) in [
        ("[[measure]]\nname = \"loss_rate\"\n", "`loss_rate` is a column of the study's table"),
        ("[[measure]]\nname = \"drops\"\n[[measure]]\nname = \"drops\"\n", "`drops` twice"),
        ("[[measure]]\nname = \"two words\"\n", "a measure's name is letters, digits and `_`"),
    ] {
        let e = parse_study(&format!("{base}{extra}"), "s.toml", "s").unwrap_err().to_string();
        assert!(e.contains("`measure[") && e.contains(words), "{e}");
    }
    let e = parse_study(&format!("seed = 1\n{TABLES}[[participant]]\nid = \"P1\"\ndrops = 3\n[[measure]]\nname = \"drops\"\n"), "s.toml", "s").unwrap_err().to_string();
    assert!(e.contains("also a participant's attribute"), "{e}");
    let w = parse_study(&format!("{base}[questionnaires]\ntlx = \"block\"\ntlx_weighting = \"pairwise\"\n"), "s.toml", "s").unwrap();
    assert_eq!(w.questionnaires.tlx_weighting, netfi::study::file::TlxWeighting::Pairwise);
    let e = parse_study(&format!("{base}[questionnaires]\ntlx_weighting = \"weighted\"\n"), "s.toml", "s").unwrap_err().to_string();
    assert!(e.contains("`questionnaires.tlx_weighting`: `weighted`: raw"), "{e}");
}
