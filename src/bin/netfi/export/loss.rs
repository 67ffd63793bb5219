//! The loss models netem approximates: `ge_lomax` as the simple Gilbert
//! model, and `corrupt` per packet.

use super::pct;
use anyhow::Result;
use netfi::fit::family::mean_loss_run_exact;
use netfi::model::{GeLomax, GeLomaxParams, Model, Verdict};
use rand::SeedableRng;

/// The simple Gilbert model (`loss gemodel p r 100% 0%`) with the loss rate
/// and mean loss run of a `ge_lomax` stage: runs of Bad are geometric with
/// mean `1/r`, and the loss is `p/(p + r)`, so `r = 1/R` and
/// `p = r·L/(1 − L)`.
pub(super) fn ge_lomax_as_gilbert(p: &GeLomaxParams) -> Result<(String, String)> {
    let model = GeLomax::new(p)?;
    let loss = model.loss_rate_exact();
    if loss >= 1.0 {
        return Ok(("loss random 100%".into(), "every frame is lost in the long run: loss random 100%".into()));
    }
    let (run, how) = match p.transition.len() {
        1 => (model.mean_burst(0) / model.burst_survival(0, 1), "exact"),
        2 => match mean_loss_run_exact(p) {
            Some(r) => (r, "exact"),
            None => (simulated_mean_run(&model), "simulated over 10^7 frames"),
        },
        _ => (simulated_mean_run(&model), "simulated over 10^7 frames"),
    };
    if loss <= 0.0 || !run.is_finite() {
        return Ok(("loss random 0%".into(), "no frame is lost in the long run: loss random 0%".into()));
    }
    let r = 1.0 / run;
    let pp = (r * loss / (1.0 - loss)).min(1.0);
    let note = format!(
        "Lomax bursts become geometric (netem loss gemodel, simple Gilbert) with the same loss rate {:.6} and mean loss run {:.4} frames ({how}); the heavy tail of long runs is lost",
        loss, run
    );
    Ok((format!("loss gemodel {} {} 100% 0%", pct(pp), pct(r)), note))
}

fn simulated_mean_run(model: &GeLomax) -> f64 {
    let mut m = model.clone();
    let mut rng = netfi::model::StageRng::seed_from_u64(1);
    let (mut drops, mut runs, mut prev) = (0u64, 0u64, false);
    for _ in 0..10_000_000u64 {
        let d = m.decide(0, &mut rng) == Verdict::Drop;
        drops += u64::from(d);
        runs += u64::from(d && !prev);
        prev = d;
    }
    if runs == 0 {
        f64::INFINITY
    } else {
        drops as f64 / runs as f64
    }
}

/// The netem words for a `corrupt` stage, and its note.
pub(super) fn corrupt_line(p: &netfi::model::CorruptParams, label: &str, notes: &mut Vec<String>) -> String {
    let headers = "netem flips one random bit of the whole packet, headers included (over UDP a header flip is caught by the UDP checksum or the stack), netfi one of the 124 ITP bytes";
    match (p.p, p.ber_per_byte) {
        (_, Some(q)) => {
            let per_packet = -(124.0 * (-q.get()).ln_1p()).exp_m1();
            notes.push(format!(
                "{label}: approximated: netem corrupts per packet, so ber_per_byte {} becomes corrupt {} = 1 − (1 − q)^124, the frames with at least one byte in error; netem then flips one bit where netfi flips one in each byte in error (up to 4), and {headers}",
                q.get(),
                pct(per_packet)
            ));
            format!("corrupt {}", pct(per_packet))
        }
        (Some(p), None) => {
            notes.push(format!("{label}: approximated: {headers}"));
            format!("corrupt {}", pct(p.get()))
        }
        // `Corrupt::new` refuses a stage with neither.
        (None, None) => String::new(),
    }
}

