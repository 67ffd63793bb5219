//! Copies and flips in a real run (docs/spec.md §3.8, §3.9): a `duplicate`
//! and a `corrupt` stage applied by the real-time emulator between the
//! real console and simulator.

use super::{netfi, out_dir, run, u, ONE_RUN_AT_A_TIME};
use serde_json::Value;

/// Duplicate (10%), then corrupt (20%, each frame and copy its own flip),
/// then Bernoulli loss (5%, which also drops copies), then a short uniform
/// delay that may reorder. Every frame and copy is accounted for, exactly;
/// the simulator's checksum catches the flips that land in bytes it covers.
#[test]
fn duplicates_and_corruption_are_accounted_for_exactly() {
    let dir = out_dir("dup-corrupt-scenario");
    std::fs::create_dir_all(&dir).unwrap();
    let scenario = dir.join("dup_corrupt.toml");
    std::fs::write(
        &scenario,
        "name = \"dup_corrupt\"\n\
         [[stage]]\nmodel = \"duplicate\"\np = 0.1\n\
         [[stage]]\nmodel = \"corrupt\"\np = 0.2\n\
         [[stage]]\nmodel = \"bernoulli\"\np = 0.05\n\
         [[stage]]\nmodel = \"delay\"\nmin_ms = 1\ndist = \"uniform\"\njitter_ms = 2\norder = \"reorder\"\n",
    )
    .unwrap();
    let (r, ok, out) = run("dup-corrupt", &[scenario.to_str().unwrap(), "--frames", "6000", "--rate-hz", "2000", "--seed", "11"]);
    std::fs::remove_dir_all(&dir).ok();
    assert!(ok, "{r:#}");
    let f = &r["frames"];
    let dropped: u64 = f["dropped"].as_object().unwrap().values().map(u).sum();
    let (entered, duplicated, delivered, held) = (u(&f["entered"]), u(&f["duplicated"]), u(&f["delivered"]), u(&f["held_at_end"]));
    // sent = entered; every frame and copy has one fate; all reached the robot.
    assert_eq!(u(&f["sent"]), entered, "{f}");
    assert_eq!(entered + duplicated, delivered + dropped + held, "{f}");
    assert_eq!(delivered, u(&f["received"]), "{f}");
    assert_eq!(held, 0, "{f}");
    assert_eq!(f["balanced"], true, "{f}");
    assert!(delivered > entered - dropped, "copies were delivered: {f}");

    // The trace: per frame, the copies made are its copy rows plus
    // `copies_dropped`; delivered copies = copies made − copies dropped.
    let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    let header: Vec<&str> = trace.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no column {name}"));
    let (fate, copy, copies_dropped, corrupted, recv) = (col("fate"), col("copy"), col("copies_dropped"), col("corrupted"), col("recv_ns"));
    let rows: Vec<Vec<&str>> = trace.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let originals = rows.iter().filter(|c| c[copy] == "0").count() as u64;
    let copy_rows: Vec<&Vec<&str>> = rows.iter().filter(|c| c[copy] != "0").collect();
    let made_dropped: u64 = rows.iter().filter_map(|c| c[copies_dropped].parse::<u64>().ok()).sum();
    assert_eq!(originals, entered);
    assert_eq!(copy_rows.len() as u64 + made_dropped, duplicated);
    let copies_delivered = copy_rows.iter().filter(|c| c[fate] == "delivered").count() as u64;
    assert_eq!(copies_delivered, duplicated - made_dropped, "every copy taken was delivered");
    assert_eq!(rows.iter().filter(|c| c[fate] == "delivered").count() as u64, delivered);
    assert_eq!(rows.iter().filter(|c| c[fate] == "dropped").count() as u64 + made_dropped, dropped);
    // Every delivered row, copies included, has the robot's receive time.
    assert!(rows.iter().filter(|c| c[fate] == "delivered").all(|c| c[recv].parse::<u64>().is_ok()), "a delivered row without recv_ns");

    // Corruption: caught + passed = corrupted delivered; the simulator's
    // bad checksums are exactly the caught ones (the console's are valid).
    let c: &Value = &f["corruption"];
    let corrupted_delivered = u(&c["delivered"]);
    assert_eq!(corrupted_delivered, rows.iter().filter(|r| r[fate] == "delivered" && r[corrupted] == "1").count() as u64);
    assert_eq!(u(&c["caught"]) + u(&c["passed"]), corrupted_delivered, "{c}");
    assert_eq!(u(&c["caught"]), u(&r["simulator"]["bad_checksum"]), "{c}");
    assert_eq!(u(&c["corrupted"]), corrupted_delivered, "nothing held, nothing dropped after the corrupt stage but loss");
    // One flip per corrupted item, uniform over the 992 bits: caught with
    // probability 44/124 = 11/31, independently. Within 5 binomial
    // standard deviations (two-sided α ≈ 6e-7).
    let n = corrupted_delivered as f64;
    let p = 11.0 / 31.0;
    let sd = (n * p * (1.0 - p)).sqrt();
    assert!(n > 500.0, "{c}");
    assert!((u(&c["caught"]) as f64 - n * p).abs() < 5.0 * sd, "caught {} of {n}, expected {:.0} ± {:.0}", u(&c["caught"]), n * p, 5.0 * sd);
    // Realized rates of the stages, each within 5 binomial standard deviations.
    let dup_rate = duplicated as f64 / entered as f64;
    assert!((dup_rate - 0.1).abs() < 5.0 * (0.1 * 0.9 / entered as f64).sqrt(), "duplicated {duplicated} of {entered}");
    // Corruption and loss are independent: of the items that passed the
    // loss stage, a fraction 0.2 were corrupted.
    let passed_loss = (entered + duplicated - u(&f["dropped"]["bernoulli"])) as f64;
    let corrupted_rate = u(&c["corrupted"]) as f64 / passed_loss;
    assert!((corrupted_rate - 0.2).abs() < 5.0 * (0.2 * 0.8 / passed_loss).sqrt(), "corrupted rate {corrupted_rate}");
}

/// The robot → console feedback path applies `duplicate` in its return
/// scenario: every feedback sample and copy is accounted for and reaches the
/// console; `corrupt` there (feedback is not an ITP frame) is refused by
/// name before the run starts.
#[test]
fn the_feedback_path_duplicates_and_refuses_corruption() {
    let dir = out_dir("fb-dup-scenarios");
    std::fs::create_dir_all(&dir).unwrap();
    let dup = dir.join("fb_dup.toml");
    std::fs::write(&dup, "name = \"fb_dup\"\n[[stage]]\nmodel = \"duplicate\"\np = 0.2\n[[stage]]\nmodel = \"bernoulli\"\np = 0.05\n").unwrap();
    let corrupt = dir.join("fb_corrupt.toml");
    std::fs::write(&corrupt, "name = \"fb_corrupt\"\n[[stage]]\nmodel = \"corrupt\"\np = 0.2\n").unwrap();
    let (r, ok, _) = run("fb-dup", &["Normal", "--return-scenario", dup.to_str().unwrap(), "--frames", "3000", "--rate-hz", "2000", "--seed", "9"]);
    assert!(ok, "{r:#}");
    let fb = &r["feedback"];
    let dropped: u64 = fb["dropped"].as_object().unwrap().values().map(u).sum();
    let (entered, duplicated, delivered) = (u(&fb["entered"]), u(&fb["duplicated"]), u(&fb["delivered"]));
    assert_eq!(entered + duplicated, delivered + dropped + u(&fb["held_at_end"]), "{fb}");
    assert_eq!(Some(delivered), fb["received_by_console"].as_u64(), "{fb}");
    assert_eq!(fb["balanced"], true, "{fb}");
    // 3000 feedback samples, each copied with probability 0.2: within 5
    // binomial standard deviations.
    assert!((duplicated as f64 - 600.0).abs() < 5.0 * (3000.0f64 * 0.2 * 0.8).sqrt(), "{fb}");
    let out = out_dir("fb-corrupt");
    let o = {
        let _guard = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        netfi().args(["run", "Normal", "--return-scenario", corrupt.to_str().unwrap(), "--frames", "100", "--seed", "9", "--out"]).arg(&out).output().unwrap()
    };
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_dir_all(&out).ok();
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("the `corrupt` stage") && stderr.contains("fb_corrupt"), "{stderr}");
}
