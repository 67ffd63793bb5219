use super::delay::{delay_as_netem, TABLE_SIZE};
use super::loss::{corrupt_line, ge_lomax_as_gilbert};
use super::pct;
use super::qdisc::Netem;
use netfi::fit::family::mean_loss_run_exact;
use netfi::model::{DelayDist, DelayParams, GeLomax, GeLomaxParams, Millis, Order};

#[test]
fn gilbert_keeps_loss_and_mean_run() {
    let p = GeLomaxParams {
        transition: vec![vec![0.95, 0.05], vec![0.10, 0.90]],
        alpha: vec![4.604, 3.901],
        lambda: vec![3.552, 1.466],
    };
    let (text, note) = ge_lomax_as_gilbert(&p).unwrap();
    assert!(text.starts_with("loss gemodel "), "{text}");
    let nums: Vec<f64> =
        text.split_whitespace().skip(2).map(|s| s.trim_end_matches('%').parse::<f64>().unwrap() / 100.0).collect();
    let loss = GeLomax::new(&p).unwrap().loss_rate_exact();
    let run = mean_loss_run_exact(&p).unwrap();
    assert!((nums[0] / (nums[0] + nums[1]) - loss).abs() < 1e-6, "{nums:?}");
    assert!((1.0 / nums[1] - run).abs() < 1e-5 * run, "{nums:?}");
    assert!(note.contains("geometric"), "{note}");
}

#[test]
fn hyperexp_table_keeps_the_mean_and_stays_in_range() {
    let p = DelayParams {
        min_ms: Millis::new(210.0).unwrap(),
        dist: DelayDist::Hyperexp,
        weights: Some(vec![0.89258, 0.10742]),
        rates_per_ms: Some(vec![0.01081, 0.01624]),
        jitter_ms: None,
        order: Order::Reorder,
    };
    let (text, note, longest, table) = delay_as_netem(&p, "s").unwrap();
    let (_, body) = table.unwrap();
    let entries: Vec<i64> = body
        .lines()
        .filter(|l| !l.starts_with('#'))
        .flat_map(|l| l.split_whitespace().map(|v| v.parse::<i64>().unwrap()))
        .collect();
    assert_eq!(entries.len(), TABLE_SIZE);
    assert!(entries.iter().all(|t| (-32768..=32767).contains(t)));
    assert!(entries.windows(2).all(|w| w[0] <= w[1]));
    assert!(text.contains("distribution netfi-h2-"), "{text}");
    assert!(note.contains("mean 299.1"), "{note}");
    assert!(longest > 1000.0 && longest < 1500.0, "{longest}");
}

#[test]
fn corrupt_per_byte_becomes_the_per_packet_rate() {
    let mut notes = Vec::new();
    let q = netfi::model::CorruptParams::per_byte(0.001).unwrap();
    let text = corrupt_line(&q, "stage 1 (corrupt)", &mut notes);
    // 1 − 0.999^124 = 0.11658…
    assert_eq!(text, format!("corrupt {}", pct(1.0 - 0.999f64.powi(124))));
    assert!(text.starts_with("corrupt 11.6"), "{text}");
    assert!(notes[0].contains("approximated") && notes[0].contains("per packet"), "{notes:?}");
    let p = netfi::model::CorruptParams::new(0.02).unwrap();
    assert_eq!(corrupt_line(&p, "s", &mut notes), "corrupt 2%");
}

/// The queue an export sizes is refused beyond tc's 32-bit `limit`. Delays
/// tc takes (at most 274.9 s, four tables' sigma beyond the mean) hold
/// at most 1.7·10⁹ packets at 10⁶ Hz, so only a longer hold reaches it.
#[test]
fn a_queue_beyond_tcs_32_bit_limit_is_refused() {
    let mut n = Netem::default();
    n.longest_delay_ms = 3_600_000.0;
    let e = n.queue_limit(1e6).unwrap_err().to_string();
    assert!(e.contains("--rate-hz 1000000") && e.contains("32-bit `limit` takes (at most 4294967295)"), "{e}");
    let mut n = Netem::default();
    n.longest_delay_ms = 3_600_000.0;
    assert_eq!(n.queue_limit(9e5).unwrap(), 4_050_000_001);
}
