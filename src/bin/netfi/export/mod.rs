//! `netfi export netem`: a shell script with the `tc qdisc … netem …` command
//! that stands for a scenario, saying what is approximated and refusing what
//! netem cannot express.
//!
//! Mapping (one netem qdisc takes one loss model and one delay):
//! - `bernoulli` → `loss random P` (exact);
//! - `markov4` → `loss state p13 p31 p32 p23 p14` (exact: docs/spec.md §3.3 is netem's);
//! - `gilbert_elliott` → `loss gemodel p r 1-h 1-k` (exact);
//! - `ge_lomax` → `loss gemodel p r 100% 0%`, the simple Gilbert model with
//!   the same loss rate and mean loss-run length: runs become geometric, the
//!   Lomax tail is lost;
//! - `delay` constant → `delay D` (exact); uniform → `delay (min + J/2)
//!   J/2`, netem's default uniform jitter (exact); hyperexponential → a
//!   custom distribution table of 4096 quantiles. netem computes a delay as
//!   `mu + sigma · t / 8192` with `t` a signed 16-bit table entry, so a table
//!   spans ±4 `sigma`: `mu` is the mean and `sigma` the larger of the
//!   standard deviation and a quarter of the table's farthest quantile from
//!   the mean, so nothing is clipped; the tail beyond the 99.988th
//!   percentile (the last table point) is lost. `fifo` order is not
//!   reproduced: netem releases each packet at its own time.
//! - `jitter` → `delay MEAN SIGMA [RHO%] distribution normal|pareto|paretonormal`
//!   with netem's own tables. netem adds `SIGMA · t` with `t` the table's
//!   standardized-by-convention entry, and its tables are not standardized:
//!   `normal` is `Z` (sd 1), `pareto` is `(4/3)(P − 3/2)` (sd 1.155) and
//!   `paretonormal` is `Z/4 + P − 3/2` (sd 1.052), so `SIGMA = sd_ms / sd t`
//!   gives the same standard deviation; the tables hold 4096 quantiles and
//!   clip at ±4 (netem's Pareto loses its tail beyond the 98.9th percentile,
//!   which lowers its mean and spread). A correlation is passed as netem's,
//!   which is approximate: netem mixes each uniform with the previous one,
//!   narrowing the jitter (docs/spec.md §3.7); netfi keeps the law exact.
//!   `fifo` order is not reproduced.
//! - `duplicate` → `duplicate P`: exact when it is the first stage. netem
//!   decides duplication before loss and sends the copy through the whole
//!   qdisc again, so a copy meets netem's loss and delay afresh, as a netfi
//!   copy meets the stages after its `duplicate`; stages before it would apply
//!   once to both in netfi but to each in netem, which the note says.
//! - `corrupt` → `corrupt P` (exact: one random bit of the packet). netem
//!   flips a bit anywhere in the packet it holds, which over UDP includes
//!   the IP and UDP headers (a flip there is caught by the UDP checksum or
//!   drops the packet in the stack), not only the 124 ITP bytes.
//!   With `ber_per_byte = q` (each byte in error independently) netem,
//!   which corrupts per packet, gets `corrupt P` with `P = 1 − (1 − q)^124`,
//!   the probability that a frame has at least one byte in error: the
//!   fraction of frames corrupted is the same, but netem flips one bit in
//!   each where netfi flips one in each byte in error (up to 4), and netem's
//!   headers are exposed too.
//! - `reorder` → `delay D reorder P gap N` (exact: netem's rule; it takes
//!   netem's one delay).
//! - `slot` → `slot MIN MAX [packets N] [bytes B]`: netem counts a packet's
//!   bytes from its link-layer header, 166 for an ITP frame over UDP, IPv4 and
//!   Ethernet, where netfi counts the 124 ITP bytes, so `bytes` is scaled by
//!   166/124 (approximated for other encapsulations).
//! - The queue: netem holds delayed packets in a queue of `limit` packets
//!   (1000 by default) and drops what does not fit; `limit` is raised to
//!   hold the stream for the longest delay in the table, with 25% spare.
//! - `rate` → `rate Rbit [packet_overhead [cellsize [celloverhead]]]`
//!   (docs/spec.md §3.12): netem's own bottleneck. netem counts a packet's
//!   bytes from its link-layer header, 42 more than netfi's payload for an
//!   ITP frame over UDP, IPv4 and Ethernet, so `packet_overhead` is
//!   netfi's `overhead_bytes` − 42 (netem accepts a negative overhead);
//!   the stage's `queue_packets` becomes netem's `limit` (a `queue_bytes`
//!   limit is turned into packets of the stage's size); a payload cut into
//!   several packets is approximated (netem sends each datagram as it is).
//!   netem truncates each packet's time to the ns, netfi rounds up once.
//! - `trace` (a Mahimahi link trace) and `replay` (recorded fates) have no
//!   netem equivalent: netem has no time-varying rate and no per-packet
//!   schedule; they are refused (use Mahimahi's `mm-link` for a trace).
//! - `outage` windows and timelines of several phases have no netem
//!   equivalent: they are refused.


mod delay;
mod link;
mod loss;
mod qdisc;
mod script;

use crate::cli::{ExportCmd, ExportNetemArgs};
use anyhow::{bail, Result};
use netfi::scenario::StageSpec;
use qdisc::Netem;
use script::write_script;

pub fn run(cmd: ExportCmd) -> Result<()> {
    match cmd {
        ExportCmd::Netem(args) => {
            print!("{}", netem(&args)?);
            Ok(())
        }
    }
}

/// The largest value of tc's unsigned 32-bit fields (`limit`, `gap`).
const TC_U32_MAX: u64 = u32::MAX as u64;
/// The largest value of tc's signed 32-bit fields (`slot`'s `packets` and
/// `bytes`).
const TC_S32_MAX: u64 = i32::MAX as u64;

fn netem(args: &ExportNetemArgs) -> Result<String> {
    let spec = netfi::load::resolve(&args.scenario)?;
    if spec.phases.len() > 1 {
        bail!(
            "scenario {} is a timeline of {} phases: netem has no timeline; export each phase as its own scenario and switch them with `tc qdisc change` on your own schedule",
            spec.name,
            spec.phases.len()
        );
    }
    check_rate_hz(args.rate_hz)?;
    let stages = &spec.phases[0].stages;
    let mut netem = Netem::default();
    for (i, st) in stages.iter().enumerate() {
        netem.add(i, st)?;
    }
    let limit = netem.queue_limit(args.rate_hz)?;
    if stages.is_empty() {
        netem.notes.push("nothing to inject: the qdisc passes every packet".into());
    }
    write_script(args, &spec.name, &netem, limit)
}

/// `--rate-hz`: a frame rate the simulated time accepts (it sizes the
/// queue limit, which tc keeps in 32 bits).
fn check_rate_hz(rate_hz: f64) -> Result<()> {
    use netfi::check::{MAX_RATE_HZ, MIN_RATE_HZ};
    if !(rate_hz.is_finite() && (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz)) {
        bail!("--rate-hz {}: expected a frame rate from {MIN_RATE_HZ} to {MAX_RATE_HZ} Hz", netfi::model::units::show(rate_hz));
    }
    Ok(())
}

/// A value of stage field `field` that tc keeps in a field of at most `max`.
fn tc_field(label: &str, field: &str, value: u64, max: u64) -> Result<()> {
    if value > max {
        bail!("{label}: `{field}` {value}: tc keeps it in a {}-bit field, so netem takes 0 to {max}", if max == TC_U32_MAX { "32" } else { "signed 32" });
    }
    Ok(())
}

fn stage_label(i: usize, st: &StageSpec) -> String {
    let mut s = format!("stage {} ({}", i + 1, st.model.kind().name());
    if let Some(p) = &st.preset {
        s.push_str(&format!(", {p}"));
    }
    s.push(')');
    s
}

/// A probability as a tc percentage (tc keeps it to 1/2^32).
fn pct(p: f64) -> String {
    format!("{}%", netfi::fit::family::round_sig(p * 100.0))
}

/// A duration for tc, in microseconds (tc keeps nanoseconds).
fn time_us(ms: f64) -> String {
    format!("{}us", (ms * 1e3).round() as u64)
}

/// The longest `delay` or `jitter` tc takes, in µs. iproute2 before 6.10
/// (Debian 12 ships 6.1) keeps both in netem's 32-bit fields of scheduler
/// ticks, 15.625 a µs (`/proc/net/psched`'s 1000/64), and refuses a time
/// whose ticks do not fit: ⌊2^32 / 15.625⌋ µs, about 274.9 s. `slot`'s
/// times are 64-bit and not bounded so.
const TC_TICK_TIME_US_MAX: u64 = 274_877_906;

/// [`time_us`] for netem's `delay` or `jitter` (`what`), which stage
/// field(s) `fields` gave; refused beyond [`TC_TICK_TIME_US_MAX`], where
/// tc would stop the script.
fn tick_time_us(label: &str, what: &str, fields: &str, ms: f64) -> Result<String> {
    let us = (ms * 1e3).round();
    if us > TC_TICK_TIME_US_MAX as f64 {
        bail!(
            "{label}: netem's `{what}` would be {us:.0} µs (from {fields}), beyond what tc takes: iproute2 before 6.10 keeps delay and jitter in 32-bit fields of scheduler ticks, so at most {TC_TICK_TIME_US_MAX} µs ({:.3} s)",
            TC_TICK_TIME_US_MAX as f64 / 1e6
        );
    }
    Ok(time_us(ms))
}


#[cfg(test)]
mod tests;
