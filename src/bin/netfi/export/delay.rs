//! `delay` and `jitter` as netem's `delay`: its own tables, or a
//! distribution table of its own.

use super::{pct, tick_time_us};
use anyhow::{bail, Result};
use netfi::fit::family::Hyperexp;
use netfi::model::{DelayDist, DelayParams, Jitter, JitterDist, JitterParams, Order};

/// Entries of a generated distribution table (as iproute2's own tables).
pub(super) const TABLE_SIZE: usize = 4096;
/// netem's fixed-point scale of table entries.
const NETEM_DIST_SCALE: f64 = 8192.0;

/// `jitter` as netem's `delay … distribution …`: the command text, the
/// note, and the longest delay netem can give (mean + 4 sigma, its tables'
/// reach).
pub(super) fn jitter_as_netem(p: &JitterParams, label: &str) -> Result<(String, String, f64)> {
    let j = Jitter::new(p).map_err(|e| anyhow::anyhow!("{e}"))?;
    // The standard deviation of netem's table variate for each law.
    let table_sd = match p.dist {
        JitterDist::Normal => 1.0,
        JitterDist::Pareto => 4.0 / 3.0 * 0.75f64.sqrt(),
        JitterDist::Paretonormal => netfi::model::jitter::PARETONORMAL_SD,
    };
    let sigma_ms = p.sd_ms / table_sd;
    let rho = p.correlation.get();
    let mut text = format!(
        "delay {} {}",
        tick_time_us(label, "delay", "`mean_ms`", p.mean_ms.get())?,
        tick_time_us(label, "jitter", &format!("`sd_ms` / {table_sd:.4}, netem's {} table's spread", p.dist.name()), sigma_ms)?
    );
    if rho > 0.0 {
        text.push(' ');
        text.push_str(&pct(rho));
    }
    if p.sd_ms > 0.0 {
        text.push_str(&format!(" distribution {}", p.dist.name()));
    }
    let mut note = format!(
        "approximated: netem's {} table (4096 quantiles, clipped at ±4 sigma), sigma = sd_ms / {table_sd:.4} so the spread matches",
        p.dist.name()
    );
    if rho > 0.0 {
        note.push_str("; netem's correlation mixes each draw with the last and narrows the jitter, netfi's keeps the law exact");
    }
    if j.clamped_fraction_exact() > 1e-6 {
        note.push_str(&format!("; netfi clamps the {:.3}% of negative draws to 0", 100.0 * j.clamped_fraction_exact()));
    }
    if p.order == Order::Fifo {
        note.push_str("; fifo order is not reproduced: netem releases each packet at its own time");
    }
    if p.sd_ms == 0.0 {
        note = "exact (constant delay)".into();
    }
    Ok((text, note, p.mean_ms.get() + 4.0 * sigma_ms))
}


/// The netem delay clause, the note, the longest delay netem will give (ms),
/// and the distribution table (name, file body) if one is needed.
#[allow(clippy::type_complexity)]
pub(super) fn delay_as_netem(p: &DelayParams, label: &str) -> Result<(String, String, f64, Option<(String, String)>)> {
    let min = p.min_ms.get();
    let fifo = if p.order == Order::Fifo {
        "; order = \"fifo\" is not reproduced (netem releases each packet at its own time, so jitter reorders)"
    } else {
        ""
    };
    match p.dist {
        DelayDist::None => Ok((format!("delay {}", tick_time_us(label, "delay", "`min_ms`", min)?), "exact (constant delay)".into(), min, None)),
        DelayDist::Uniform => {
            let j = p.jitter_ms.map_or(0.0, |j| j.get());
            Ok((
                format!(
                    "delay {} {}",
                    tick_time_us(label, "delay", "`min_ms` + `jitter_ms` / 2", min + j / 2.0)?,
                    tick_time_us(label, "jitter", "`jitter_ms` / 2", j / 2.0)?
                ),
                format!("exact up to microseconds (netem's default uniform jitter, mean ± half-width){fifo}"),
                min + j,
                None,
            ))
        }
        DelayDist::Hyperexp => hyperexp_as_netem(p, label, fifo),
    }
}

/// A hyperexponential delay as a distribution table of [`TABLE_SIZE`]
/// quantiles netem reads as `mu + sigma · t / 8192`; `fifo` is the note's
/// word on order.
#[allow(clippy::type_complexity)]
fn hyperexp_as_netem(p: &DelayParams, label: &str, fifo: &str) -> Result<(String, String, f64, Option<(String, String)>)> {
    let min = p.min_ms.get();
    let h = Hyperexp {
        weights: p.weights.clone().unwrap_or_default(),
        rates: p.rates_per_ms.clone().unwrap_or_default(),
    };
    if h.weights.is_empty() || h.weights.len() != h.rates.len() {
        bail!("{label}: a hyperexponential delay needs weights and rates");
    }
    let mean = min + h.mean_ms();
    let std = h.std_ms();
    let quantiles: Vec<f64> =
        (0..TABLE_SIZE).map(|i| min + h.quantile_ms((i as f64 + 0.5) / TABLE_SIZE as f64)).collect();
    let top = quantiles[TABLE_SIZE - 1];
    let scale = std.max((top - mean) / 3.999).max((mean - min) / 3.999);
    let entries: Vec<i64> = quantiles
        .iter()
        .map(|q| (((q - mean) / scale) * NETEM_DIST_SCALE).round().clamp(-32768.0, 32767.0) as i64)
        .collect();
    // What netem will realize (its arithmetic, at the microsecond times tc passes).
    let mu_us = (mean * 1e3).round();
    let sigma_us = (scale * 1e3).round();
    let realized: Vec<f64> =
        entries.iter().map(|t| (mu_us + sigma_us * *t as f64 / NETEM_DIST_SCALE) / 1e3).collect();
    let realized_mean = realized.iter().sum::<f64>() / TABLE_SIZE as f64;
    let mut sorted = realized.clone();
    sorted.sort_by(f64::total_cmp);
    let realized_p99 = sorted[(0.99 * TABLE_SIZE as f64) as usize];
    let name = format!("netfi-h2-{:08x}", fnv(&format!("{p:?}")) as u32);
    let mut body = format!(
        "# netfi {}: {} ms + hyperexponential (weights {:?}, rates {:?} per ms), {TABLE_SIZE} quantiles\n# in units of {} ms / {NETEM_DIST_SCALE} around {} ms\n",
        netfi::fit::TOOL_VERSION,
        min,
        h.weights,
        h.rates,
        sigma_us / 1e3,
        mu_us / 1e3
    );
    for chunk in entries.chunks(8) {
        let line: Vec<String> = chunk.iter().map(|v| v.to_string()).collect();
        body.push_str(&line.join(" "));
        body.push('\n');
    }
    let note = format!(
        "approximated by the distribution table {name} ({TABLE_SIZE} equiprobable quantiles; netem reads mu + sigma·t/8192 with |t| ≤ 4·8192, so sigma is {:.3} ms rather than the standard deviation {:.3} ms, to keep the whole table inside netem's ±4 sigma without clipping): mean {:.3} ms (exact {:.3}), p99 {:.3} ms (exact {:.3}); the tail beyond the 99.988th percentile ({:.1} ms) is lost{fifo}",
        scale,
        std,
        realized_mean,
        mean,
        realized_p99,
        min + h.quantile_ms(0.99),
        top
    );
    let longest = realized.iter().copied().fold(0.0, f64::max);
    Ok((
        format!(
            "delay {} {} distribution {name}",
            tick_time_us(label, "delay", "the mean, `min_ms` + the hyperexponential's", mean)?,
            tick_time_us(label, "jitter", "the table's scale, from `weights` and `rates_per_ms`", scale)?
        ),
        note,
        longest,
        Some((name, body)),
    ))
}

fn fnv(s: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in s.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

