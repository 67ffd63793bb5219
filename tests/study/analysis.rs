//! The paper's analysis from `netfi study report`, recomputed here from the
//! study's own tables: measures the experimenter counted (from the command
//! line), a weighted NASA-TLX after each block compared against the
//! baseline's block, the tables by condition and group, Pearson's
//! correlations; and a study file changed after participants began named
//! by `status` and `plan`.

use super::{csv, status, study, study_output, Scratch};
use crate::common::machine;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::path::PathBuf;

const IDS: [&str; 4] = ["P1", "P2", "P3", "P4"];
const BLOCKS: [&str; 3] = ["free", "loss", "outage"];

fn analysis_study() -> String {
    let mut t = String::from(
        "name = \"analysis\"\nseed = 21\ndata = \"data\"\n[trial]\nduration_s = \"1s\"\nrun_args = [\"--no-isolate\"]\n\
         [order]\nfirst = \"free\"\n[questionnaires]\ntlx = \"block\"\ntlx_weighting = \"pairwise\"\n\
         [[measure]]\nname = \"drops\"\nlabel = \"Pegs dropped\"\n\
         [[block]]\nname = \"free\"\nconditions = [\"Normal\"]\n[[block]]\nname = \"loss\"\nconditions = [\"PLM-2\"]\n\
         [[block]]\nname = \"outage\"\nconditions = [\"CLM-2\"]\n",
    );
    for (i, id) in IDS.iter().enumerate() {
        t += &format!("[[participant]]\nid = \"{id}\"\nproficiency = \"{}\"\n", if i < 2 { "novice" } else { "expert" });
    }
    t
}

/// The drops the experimenter counts: participant × block.
fn drops(p: usize, block: &str) -> u32 {
    match block {
        "free" => [0, 1, 0, 1][p],
        "loss" => [5, 6, 5, 7][p],
        _ => [3, 3, 4, 2][p],
    }
}

/// The TLX ratings after a block.
fn tlx(p: usize, block: &str) -> [u32; 6] {
    let offset = match block {
        "free" => 0,
        "loss" => 30,
        _ => 20,
    } + 5 * p as u32;
    [20, 30, 40, 25, 35, 15].map(|x| x + offset - [0, 5, 0, 10][p])
}

/// The 15 choices: the first scale of each pair (weights 5, 4, 3, 2, 1, 0).
const PAIRS: &str = "mental,mental,mental,mental,mental,physical,physical,physical,physical,temporal,temporal,temporal,performance,performance,effort";

fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

fn sd(xs: &[f64]) -> f64 {
    let m = mean(xs);
    (xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (xs.len() - 1) as f64).sqrt()
}

fn close(a: f64, b: f64, what: &str) {
    assert!((a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-300), "{what}: report {a}, recomputed {b}");
}

#[test]
fn the_report_gives_the_papers_tables_from_counted_measures_and_a_weighted_tlx() {
    let _one = machine::alone();
    let dir = Scratch::new("analysis");
    let file = dir.file("study.toml", &analysis_study());
    let f = file.to_str().unwrap();
    let plan = study(&["plan", f]);
    assert!(plan.contains("order: `free` first for everyone, then balanced Latin square of 2 rows"), "{plan}");
    assert!(!plan.contains("CHANGED"), "{plan}");
    for (p, id) in IDS.iter().enumerate() {
        loop {
            let s = status(&file, id);
            match s["next"]["kind"].as_str().unwrap() {
                "questionnaire" => {
                    let block = s["next"]["block"].as_str().unwrap().to_string();
                    let title = s["next"]["title"].as_str().unwrap();
                    assert!(title.starts_with(&format!("NASA-TLX after block {block} (trial ")), "{title}");
                    // A weighted TLX without its pairs is refused.
                    let values: Vec<String> = tlx(p, &block).iter().map(u32::to_string).collect();
                    let mut args = vec!["answer", f, "-p", id, "tlx"];
                    args.extend(values.iter().map(String::as_str));
                    let refused = study_output(&args);
                    assert!(!refused.status.success() && String::from_utf8_lossy(&refused.stderr).contains("give the 15 pairwise choices"));
                    args.extend(["--pairs", PAIRS]);
                    study(&args);
                }
                "trial" => {
                    let block = s["next"]["block"].as_str().unwrap().to_string();
                    study(&["next", f, "-p", id]);
                    let refused = study_output(&["mark", f, "-p", id, "done", "--count", "dorps=1"]);
                    let said = String::from_utf8_lossy(&refused.stderr);
                    assert!(!refused.status.success() && said.contains("`dorps` is no measure of this study (its measures: drops)"), "{said}");
                    if block == "loss" {
                        // Counted at the mark, corrected afterwards.
                        study(&["mark", f, "-p", id, "done", "--count", "drops=99"]);
                        let trial = s["next"]["trial"].as_u64().unwrap().to_string();
                        study(&["count", f, "-p", id, "--trial", &trial, &format!("drops={}", drops(p, &block))]);
                    } else {
                        study(&["mark", f, "-p", id, "done", "--count", &format!("drops={}", drops(p, &block))]);
                    }
                }
                "finished" => break,
                other => panic!("{id}: unexpected next step {other}: {s}"),
            }
        }
        let s = status(&file, id);
        assert_eq!(s["trials"][0]["block"], "free", "{id} takes the baseline's block first");
    }
    let weighted: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.0.join("data/P2/questionnaires/tlx-01.json")).unwrap()).unwrap();
    assert_eq!(weighted["weights"], serde_json::json!([5, 4, 3, 2, 1, 0]));
    let r = tlx(1, "free");
    let want = f64::from(5 * r[0] + 4 * r[1] + 3 * r[2] + 2 * r[3] + r[4]) / 15.0;
    assert_eq!(weighted["weighted"].as_f64(), Some(want));

    let out = PathBuf::from(study(&["report", f, "--group", "proficiency"]).trim());
    let (header, rows) = csv(&std::fs::read_to_string(out.join("trials.csv")).unwrap());
    let col = |h: &[String], n: &str| h.iter().position(|x| x == n).unwrap_or_else(|| panic!("no column {n} in {h:?}"));
    assert_eq!(header.last().map(String::as_str), Some("drops"), "the measure is the table's last column");
    for row in &rows {
        let p = IDS.iter().position(|i| *i == row[0]).unwrap();
        assert_eq!(row[col(&header, "drops")], drops(p, &row[col(&header, "block")]).to_string(), "{row:?}");
    }

    // The paper's table: every condition's mean (sd) over participants, the Holm-adjusted p.
    let (th, table) = csv(&std::fs::read_to_string(out.join("table.csv")).unwrap());
    assert_eq!(table.len(), 9, "all, novice, expert × three conditions");
    let cell = |group: &str, condition: &str, name: &str| -> Option<f64> {
        let row = table.iter().find(|r| r[0] == group && r[1] == condition).unwrap();
        row[col(&th, name)].parse().ok()
    };
    for (group, members) in [("all", &[0, 1, 2, 3][..]), ("novice", &[0, 1][..]), ("expert", &[2, 3][..])] {
        for (condition, block) in [("Normal", "free"), ("PLM-2", "loss"), ("CLM-2", "outage")] {
            let xs: Vec<f64> = members.iter().map(|&p| f64::from(drops(p, block))).collect();
            close(cell(group, condition, "drops_mean").unwrap(), mean(&xs), &format!("{group} {condition} drops mean"));
            close(cell(group, condition, "drops_sd").unwrap(), sd(&xs), &format!("{group} {condition} drops sd"));
        }
    }
    assert_eq!(cell("all", "Normal", "drops_p_holm"), None, "the baseline is not tested against itself");
    // drops: PLM-2 − Normal = 5, 5, 5, 6 (t = 21, df 3); CLM-2 − Normal = 3, 2, 4, 1.
    let law = StudentsT::new(0.0, 1.0, 3.0).unwrap();
    let p_of = |d: &[f64]| 2.0 * law.sf((mean(d) / (sd(d) / 2.0)).abs());
    let (p_loss, p_outage) = (p_of(&[5.0, 5.0, 5.0, 6.0]), p_of(&[3.0, 2.0, 4.0, 1.0]));
    let holm = |p: f64, other: f64| if p <= other { (2.0 * p).min(1.0) } else { (2.0 * other).min(1.0).max(p) };
    close(cell("all", "PLM-2", "drops_p_holm").unwrap(), holm(p_loss, p_outage), "PLM-2 drops p Holm");
    close(cell("all", "CLM-2", "drops_p_holm").unwrap(), holm(p_outage, p_loss), "CLM-2 drops p Holm");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("id=\"table-all\"") && html.contains("id=\"table-novice\"") && html.contains("id=\"by-group\""));
    assert!(html.contains("<sup>*</sup>"), "a significant difference is marked");
    assert!(!html.contains("src=\"http") && !html.contains("href=\"http"), "the page is self-contained");

    // The TLX against the baseline's block, paired by participant.
    let (qh, q) = csv(&std::fs::read_to_string(out.join("questionnaires.csv")).unwrap());
    let qrow = |metric: &str, unit: &str| q.iter().find(|r| r[col(&qh, "group")] == "all" && r[col(&qh, "metric")] == metric && r[col(&qh, "condition")] == unit).unwrap();
    for (k, scale) in ["mental_demand", "physical_demand", "temporal_demand", "performance", "effort", "frustration"].iter().enumerate() {
        for block in BLOCKS {
            let xs: Vec<f64> = (0..4).map(|p| f64::from(tlx(p, block)[k])).collect();
            close(qrow(&format!("tlx_{scale}"), block)[col(&qh, "mean")].parse().unwrap(), mean(&xs), &format!("{scale} {block}"));
        }
    }
    // Every rating of a block is the free block's + 30: the difference is constant, no t.
    assert_eq!(qrow("tlx_raw", "loss")[col(&qh, "mean_difference")], "");
    assert_eq!(qrow("tlx_raw", "loss")[col(&qh, "pairs")], "4");
    assert!(qrow("tlx_weighted", "outage")[col(&qh, "mean")].parse::<f64>().is_ok());
    assert!(html.contains("NASA-TLX against free"));

    // Pearson: drops against the raw TLX over the twelve answers, each
    // paired with the drops of the trial of its block.
    let (ch, corr) = csv(&std::fs::read_to_string(out.join("correlations.csv")).unwrap());
    let row = corr.iter().find(|r| r[0] == "drops" && r[1] == "tlx_raw").unwrap();
    let pairs: Vec<(f64, f64)> = (0..4)
        .flat_map(|p| BLOCKS.map(move |b| (f64::from(drops(p, b)), f64::from(tlx(p, b).iter().sum::<u32>()) / 6.0)))
        .collect();
    let (mx, my) = (mean(&pairs.iter().map(|p| p.0).collect::<Vec<_>>()), mean(&pairs.iter().map(|p| p.1).collect::<Vec<_>>()));
    let sxy: f64 = pairs.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = pairs.iter().map(|(x, _)| (x - mx).powi(2)).sum();
    let syy: f64 = pairs.iter().map(|(_, y)| (y - my).powi(2)).sum();
    let r = sxy / (sxx * syy).sqrt();
    let t = r * 10f64.sqrt() / (1.0 - r * r).sqrt();
    let p = 2.0 * StudentsT::new(0.0, 1.0, 10.0).unwrap().sf(t.abs());
    assert_eq!(row[col(&ch, "n")], "12");
    close(row[col(&ch, "r")].parse().unwrap(), r, "r(drops, raw TLX)");
    close(row[col(&ch, "p")].parse().unwrap(), p, "p(drops, raw TLX)");
    // Every column of the table against every scale is there, computed where defined.
    let duration = corr.iter().find(|r| r[0] == "duration_s" && r[1] == "tlx_frustration").unwrap();
    assert_eq!(duration[col(&ch, "n")], "12");
    assert!(html.contains("id=\"correlations\""));

    // The study file changed after participants began: named, not silent.
    let mut text = std::fs::read_to_string(&file).unwrap();
    text.push_str("# the order sheet was reprinted\n");
    std::fs::write(&file, text).unwrap();
    let said = study(&["status", f]);
    assert!(said.contains(&format!("CHANGED: the study file {f} changed after participants began")), "{said}");
    assert!(said.contains("study-at-first-trial.toml"), "{said}");
    assert!(study(&["plan", f]).contains("CHANGED: the study file"));
    assert!(status(&file, "P1")["study_changed"][0].as_str().unwrap().contains("changed after participants began"));
}
