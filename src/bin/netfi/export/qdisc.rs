//! One netem qdisc, built from a scenario's stages.

use super::delay::{delay_as_netem, jitter_as_netem};
use super::link::{rate_as_netem, slot_line};
use super::loss::{corrupt_line, ge_lomax_as_gilbert};
use super::{pct, stage_label, tc_field, tick_time_us, TC_U32_MAX};
use anyhow::{bail, Result};
use netfi::scenario::{ModelSpec, StageSpec};

/// netem's default queue limit, in packets.
const NETEM_DEFAULT_LIMIT: u64 = 1000;

/// One netem qdisc being built from a scenario's stages: the clause each
/// of its parts took (with the stage that gave it), the notes, and what
/// sizes its queue.
#[derive(Default)]
pub(super) struct Netem {
    loss: Option<(usize, String)>,
    delay: Option<(usize, String)>,
    dup: Option<(usize, String)>,
    corrupt: Option<(usize, String)>,
    slot: Option<(usize, String)>,
    rate: Option<(usize, String)>,
    pub(super) notes: Vec<String>,
    /// A `rate` stage's queue, in packets.
    rate_limit: Option<u64>,
    /// A generated distribution table: its name and its file.
    pub(super) table: Option<(String, String)>,
    /// The longest delay netem will give, ms.
    pub(super) longest_delay_ms: f64,
}

impl Netem {
    /// Maps stage `i`, or refuses it (a stage netem cannot express, or a
    /// part of the qdisc an earlier stage already took).
    pub(super) fn add(&mut self, i: usize, st: &StageSpec) -> Result<()> {
        let label = stage_label(i, st);
        let (part, what) = match &st.model {
            ModelSpec::Delay(_) | ModelSpec::Jitter(_) | ModelSpec::Reorder(_) => (&self.delay, "delay"),
            ModelSpec::Slot(_) => (&self.slot, "slot"),
            ModelSpec::Duplicate(_) => (&self.dup, "duplication"),
            ModelSpec::Corrupt(_) => (&self.corrupt, "corruption"),
            ModelSpec::Rate(_) => (&self.rate, "rate"),
            ModelSpec::LinkTrace(_) => bail!(
                "{label}: netem cannot follow a link trace (its `rate` is fixed); netfi export refuses `trace` stages: run Mahimahi's mm-link with the same trace file instead"
            ),
            ModelSpec::Replay(_) => bail!(
                "{label}: netem cannot replay recorded per-frame fates (it draws each packet's fate afresh); netfi export refuses `replay` stages"
            ),
            ModelSpec::Outage(_) => bail!(
                "{label}: netem cannot express outage windows with a cooldown (it has no state that drops every packet for a drawn time and then none for another); netfi export refuses it"
            ),
            _ => (&self.loss, "loss model"),
        };
        if let Some((j, _)) = part {
            bail!("{label}: netem takes one {what} per qdisc and stage {} already uses it", *j + 1);
        }
        let text = self.clause(i, st, &label)?;
        let part = match &st.model {
            ModelSpec::Delay(_) | ModelSpec::Jitter(_) | ModelSpec::Reorder(_) => &mut self.delay,
            ModelSpec::Slot(_) => &mut self.slot,
            ModelSpec::Duplicate(_) => &mut self.dup,
            ModelSpec::Corrupt(_) => &mut self.corrupt,
            ModelSpec::Rate(_) => &mut self.rate,
            _ => &mut self.loss,
        };
        *part = Some((i, text));
        Ok(())
    }

    /// The netem words for stage `i` (a model `add` accepts), noting how
    /// exact they are.
    fn clause(&mut self, i: usize, st: &StageSpec, label: &str) -> Result<String> {
        let note = |notes: &mut Vec<String>, n: String| notes.push(format!("{label}: {n}"));
        Ok(match &st.model {
            ModelSpec::Bernoulli(p) => {
                note(&mut self.notes, "exact (loss random)".into());
                format!("loss random {}", pct(p.p.get()))
            }
            ModelSpec::Markov4(p) => {
                note(&mut self.notes, "exact (loss state)".into());
                let g = |v: Option<netfi::model::Probability>, d: f64| pct(v.map_or(d, |x| x.get()));
                format!("loss state {} {} {} {} {}", pct(p.p13.get()), g(p.p31, 1.0 - p.p13.get()), g(p.p32, 0.0), g(p.p23, 1.0), g(p.p14, 0.0))
            }
            ModelSpec::GilbertElliott(p) => {
                note(&mut self.notes, "exact (loss gemodel)".into());
                let pv = p.p.get();
                let (r, bad, good) = (p.r.map_or(1.0 - pv, |x| x.get()), p.loss_bad.map_or(1.0, |x| x.get()), p.loss_good.map_or(0.0, |x| x.get()));
                format!("loss gemodel {} {} {} {}", pct(pv), pct(r), pct(bad), pct(good))
            }
            ModelSpec::GeLomax(p) => {
                let (text, n) = ge_lomax_as_gilbert(p)?;
                note(&mut self.notes, format!("approximated: {n}"));
                text
            }
            ModelSpec::Delay(p) => {
                let (text, n, longest, dist) = delay_as_netem(p, label)?;
                note(&mut self.notes, n);
                self.longest_delay_ms = self.longest_delay_ms.max(longest);
                self.table = dist;
                text
            }
            ModelSpec::Jitter(p) => {
                let (text, n, longest) = jitter_as_netem(p, label)?;
                note(&mut self.notes, n);
                self.longest_delay_ms = self.longest_delay_ms.max(longest);
                text
            }
            ModelSpec::Duplicate(p) => {
                note(&mut self.notes, if i == 0 {
                    "exact (duplicate; netem sends the copy through its loss and delay again, as netfi sends it through the later stages)".into()
                } else {
                    format!("approximated: netem duplicates before anything else, so the {i} stage(s) before this one apply to the copy afresh in netem but once to both in netfi")
                });
                format!("duplicate {}", pct(p.p.get()))
            }
            ModelSpec::Corrupt(p) => corrupt_line(p, label, &mut self.notes),
            ModelSpec::Reorder(p) => {
                tc_field(label, "gap", p.gap, TC_U32_MAX)?;
                note(&mut self.notes, "exact (delay … reorder … gap …)".into());
                self.longest_delay_ms = self.longest_delay_ms.max(p.delay_ms.get());
                format!("delay {} reorder {} gap {}", tick_time_us(label, "delay", "`delay_ms`", p.delay_ms.get())?, pct(p.p.get()), p.gap)
            }
            ModelSpec::Slot(p) => slot_line(p, label, &mut self.notes)?,
            ModelSpec::Rate(p) => {
                let (text, n, limit) = rate_as_netem(p, label)?;
                note(&mut self.notes, n);
                self.rate_limit = Some(limit);
                text
            }
            ModelSpec::Outage(_) | ModelSpec::LinkTrace(_) | ModelSpec::Replay(_) => unreachable!("refused by `add`"),
        })
    }

    /// netem's `limit`: enough for the packets held over the longest delay
    /// at `rate_hz`, with 25% spare, at least netem's default or the rate
    /// stage's queue; refused beyond tc's 32-bit field.
    pub(super) fn queue_limit(&mut self, rate_hz: f64) -> Result<u64> {
        let needed_f = (rate_hz * self.longest_delay_ms / 1e3 * 1.25).ceil() + 1.0;
        if needed_f > TC_U32_MAX as f64 {
            bail!(
                "--rate-hz {}: a delay of up to {:.1} ms holds about {:.0} packets at this rate, beyond what tc's 32-bit `limit` takes (at most {TC_U32_MAX}); lower --rate-hz or the delay",
                netfi::model::units::show(rate_hz),
                self.longest_delay_ms,
                needed_f
            );
        }
        let needed = needed_f as u64;
        let limit = match self.rate_limit {
            // The rate stage's queue is netem's limit; a delay's hold shares it.
            Some(l) if needed > l => {
                self.notes.push(format!("queue: the rate stage's limit {l} is raised to {needed} to hold the delayed packets too (netem has one queue for both)"));
                needed
            }
            Some(l) => l,
            None => needed.max(NETEM_DEFAULT_LIMIT),
        };
        if needed > NETEM_DEFAULT_LIMIT && self.rate_limit.is_none() {
            self.notes.push(format!(
                "queue: at {rate_hz} Hz a delay of up to {:.1} ms holds about {} packets, more than netem's default limit of {NETEM_DEFAULT_LIMIT}; limit raised to {limit} (packets beyond the limit are dropped)",
                self.longest_delay_ms,
                (rate_hz * self.longest_delay_ms / 1e3).ceil()
            ));
        }
        Ok(limit)
    }

    /// The qdisc's words after `limit`, in tc's order.
    pub(super) fn clauses(&self) -> impl Iterator<Item = &str> {
        [&self.loss, &self.delay, &self.dup, &self.corrupt, &self.slot, &self.rate].into_iter().flatten().map(|(_, t)| t.as_str())
    }
}

