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

use crate::cli::{ExportCmd, ExportNetemArgs};
use anyhow::{bail, Result};
use netfi::fit::family::{mean_loss_run_exact, Hyperexp};
use netfi::model::{DelayDist, DelayParams, GeLomax, GeLomaxParams, Jitter, JitterDist, JitterParams, Model, Order, Verdict};
use netfi::scenario::{ModelSpec, StageSpec};
use rand::SeedableRng;
use std::fmt::Write;

/// Entries of a generated distribution table (as iproute2's own tables).
const TABLE_SIZE: usize = 4096;
/// netem's fixed-point scale of table entries.
const NETEM_DIST_SCALE: f64 = 8192.0;
/// netem's default queue limit, in packets.
const NETEM_DEFAULT_LIMIT: u64 = 1000;

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

/// One netem qdisc being built from a scenario's stages: the clause each
/// of its parts took (with the stage that gave it), the notes, and what
/// sizes its queue.
#[derive(Default)]
struct Netem {
    loss: Option<(usize, String)>,
    delay: Option<(usize, String)>,
    dup: Option<(usize, String)>,
    corrupt: Option<(usize, String)>,
    slot: Option<(usize, String)>,
    rate: Option<(usize, String)>,
    notes: Vec<String>,
    /// A `rate` stage's queue, in packets.
    rate_limit: Option<u64>,
    /// A generated distribution table: its name and its file.
    table: Option<(String, String)>,
    longest_delay_ms: f64,
}

impl Netem {
    /// Maps stage `i`, or refuses it (a stage netem cannot express, or a
    /// part of the qdisc an earlier stage already took).
    fn add(&mut self, i: usize, st: &StageSpec) -> Result<()> {
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
                let (text, n, longest) = jitter_as_netem(p)?;
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
                format!("delay {} reorder {} gap {}", time_us(p.delay_ms.get()), pct(p.p.get()), p.gap)
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
    fn queue_limit(&mut self, rate_hz: f64) -> Result<u64> {
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
    fn clauses(&self) -> impl Iterator<Item = &str> {
        [&self.loss, &self.delay, &self.dup, &self.corrupt, &self.slot, &self.rate].into_iter().flatten().map(|(_, t)| t.as_str())
    }
}

/// A value of stage field `field` that tc keeps in a field of at most `max`.
fn tc_field(label: &str, field: &str, value: u64, max: u64) -> Result<()> {
    if value > max {
        bail!("{label}: `{field}` {value}: tc keeps it in a {}-bit field, so netem takes 0 to {max}", if max == TC_U32_MAX { "32" } else { "signed 32" });
    }
    Ok(())
}

/// `slot` as netem's `slot MIN MAX [packets N] [bytes B]`, noting how
/// exact it is; refused where tc's signed 32-bit budgets cannot hold it.
fn slot_line(p: &netfi::model::SlotParams, label: &str, notes: &mut Vec<String>) -> Result<String> {
    let mut text = format!("slot {} {}", time_us(p.min_ms.get()), time_us(p.max_ms.get()));
    if let Some(n) = p.packets {
        tc_field(label, "packets", n, TC_S32_MAX)?;
        text.push_str(&format!(" packets {n}"));
    }
    if let Some(b) = p.bytes {
        let scaled = (b as f64 * 166.0 / 124.0).ceil();
        if scaled > TC_S32_MAX as f64 {
            bail!(
                "{label}: `bytes` {b}: netem counts 166 bytes per frame where netfi counts 124, so it becomes {scaled:.0}, beyond tc's signed 32-bit field (netem takes 0 to {TC_S32_MAX}); at most {} here",
                (TC_S32_MAX as f64 * 124.0 / 166.0).floor()
            );
        }
        text.push_str(&format!(" bytes {}", scaled as u64));
        notes.push(format!("{label}: approximated: bytes scaled by 166/124 (netem counts the UDP/IPv4/Ethernet headers too)"));
    } else {
        notes.push(format!("{label}: exact (slot)"));
    }
    Ok(text)
}

/// The script: notes as comments, the distribution table if one is
/// needed, and the `tc` command. Everything taken from the user or a file
/// goes in quoted (words) or with its line breaks escaped (comments): the
/// script is meant to run as root.
fn write_script(args: &ExportNetemArgs, name: &str, netem: &Netem, limit: u64) -> Result<String> {
    validate_dev(&args.dev)?;
    let dev = quote(&args.dev)?;
    let mut out = String::new();
    writeln!(out, "#!/bin/sh").unwrap();
    writeln!(out, "# netem equivalent of netfi scenario {} (netfi {}).", comment(&format!("{name:?}")), netfi::fit::TOOL_VERSION).unwrap();
    for n in &netem.notes {
        writeln!(out, "# - {}", comment(n)).unwrap();
    }
    writeln!(out, "# Randomness differs: netem draws from the kernel's generator, not netfi's seeded streams.").unwrap();
    writeln!(out, "# To remove it: tc qdisc del dev {dev} root").unwrap();
    writeln!(out, "set -e").unwrap();
    if let Some((name, body)) = &netem.table {
        write_table(&mut out, args, name, body)?;
    }
    let mut cmd = format!("tc qdisc replace dev {dev} root netem limit {limit}");
    for text in netem.clauses() {
        cmd.push(' ');
        cmd.push_str(text);
    }
    writeln!(out, "{cmd}").unwrap();
    Ok(out)
}

/// The lines that put distribution table `name` where tc looks for it.
fn write_table(out: &mut String, args: &ExportNetemArgs, name: &str, body: &str) -> Result<()> {
    // tc reads tables from $TC_LIB_DIR when set, else from the directory
    // it was built with, which differs between distributions: the script
    // looks for it where it runs.
    let dirs = match &args.table_dir {
        Some(d) => vec![path_text(d)?],
        None => table_dir_candidates(),
    };
    let quoted: Vec<String> = dirs.iter().map(|d| quote(d)).collect::<Result<_>>()?;
    writeln!(out, "if [ -z \"${{TC_LIB_DIR:-}}\" ]; then").unwrap();
    writeln!(out, "  for d in {}; do", quoted.join(" ")).unwrap();
    if args.table_dir.is_some() {
        writeln!(out, "    TC_LIB_DIR=\"$d\"").unwrap();
    } else {
        writeln!(out, "    if [ -f \"$d/normal.dist\" ]; then TC_LIB_DIR=\"$d\"; break; fi").unwrap();
    }
    writeln!(out, "  done").unwrap();
    writeln!(out, "fi").unwrap();
    writeln!(
        out,
        "if [ ! -d \"${{TC_LIB_DIR:-}}\" ]; then echo \"tc's distribution table directory was not found (looked in: {}); set TC_LIB_DIR\" >&2; exit 1; fi",
        comment(&dirs.join(" ")).replace(['"', '$', '`', '\\'], "?")
    )
    .unwrap();
    writeln!(out, "export TC_LIB_DIR").unwrap();
    writeln!(out, "cat > \"$TC_LIB_DIR/{name}.dist\" <<'NETFI_TABLE'").unwrap();
    out.push_str(body);
    writeln!(out, "NETFI_TABLE").unwrap();
    writeln!(out, "# To remove the table too: rm -f \"$TC_LIB_DIR/{name}.dist\"").unwrap();
    Ok(())
}

/// Where iproute2 installs tc's distribution tables: Debian and Ubuntu
/// under the multiarch directory (`/usr/lib/x86_64-linux-gnu/tc`), Fedora
/// and openSUSE under `/usr/lib64/tc`, iproute2's own default `/usr/lib/tc`.
/// Those found on this machine (with iproute2's `normal.dist`) come first;
/// the script tries each in turn where it runs.
const TABLE_DIRS: [&str; 4] = ["/usr/lib/x86_64-linux-gnu/tc", "/usr/lib/aarch64-linux-gnu/tc", "/usr/lib64/tc", "/usr/lib/tc"];

fn table_dir_candidates() -> Vec<String> {
    let mut dirs: Vec<String> = Vec::new();
    // Other multiarch directories present here.
    if let Ok(rd) = std::fs::read_dir("/usr/lib") {
        let mut found: Vec<String> = rd
            .filter_map(|e| e.ok())
            .map(|e| e.path().join("tc"))
            .filter(|p| p.join("normal.dist").is_file())
            .filter_map(|p| p.to_str().map(str::to_owned))
            .collect();
        found.sort();
        dirs.extend(found);
    }
    for d in TABLE_DIRS {
        if !dirs.iter().any(|x| x == d) {
            dirs.push(d.to_owned());
        }
    }
    let here = |d: &String| std::path::Path::new(d).join("normal.dist").is_file();
    dirs.sort_by_key(|d| !here(d));
    if !dirs.iter().any(here) {
        eprintln!(
            "warning: tc's distribution tables were not found on this machine (looked in {}); the script looks again where it runs, or set TC_LIB_DIR",
            dirs.join(", ")
        );
    }
    dirs
}

/// Checks a network interface name by the kernel's own rule
/// (`dev_valid_name`): 1 to 15 bytes, not `.` or `..`, no `/`, `:` or
/// white space. Anything else the kernel allows (`$`, `;`, quotes) is legal
/// and is quoted in the script.
pub fn validate_dev(dev: &str) -> Result<()> {
    const IFNAMSIZ: usize = 16;
    if dev.is_empty() || dev.len() >= IFNAMSIZ {
        bail!("--dev {dev:?}: an interface name has 1 to {} bytes, this one {}", IFNAMSIZ - 1, dev.len());
    }
    if dev == "." || dev == ".." {
        bail!("--dev {dev:?}: `.` and `..` are not interface names");
    }
    if let Some(c) = dev.chars().find(|c| matches!(c, '/' | ':') || c.is_whitespace() || c.is_control()) {
        bail!("--dev {dev:?}: an interface name may not contain {c:?} (no `/`, `:`, white space or control characters)");
    }
    Ok(())
}

/// A word for `sh`, quoted where needed. `shlex` (already a dependency of
/// the build, and the quoting rust-lang's `cc` trusts) rather than a
/// hand-written quoter: it quotes everything a POSIX shell expands and
/// refuses a NUL, which no quoting can carry.
fn quote(word: &str) -> Result<String> {
    shlex::try_quote(word).map(|w| w.into_owned()).map_err(|e| anyhow::anyhow!("{word:?} cannot be quoted for the shell: {e}"))
}

fn path_text(p: &std::path::Path) -> Result<String> {
    p.to_str().map(str::to_owned).ok_or_else(|| anyhow::anyhow!("--table-dir {}: not valid UTF-8", p.display()))
}

/// Text for a `#` comment: control characters (a line break would end the
/// comment and start a command) are written escaped.
fn comment(text: &str) -> String {
    text.chars().map(|c| if c.is_control() { c.escape_default().to_string() } else { c.to_string() }).collect()
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

/// `jitter` as netem's `delay … distribution …`: the command text, the
/// note, and the longest delay netem can give (mean + 4 sigma, its tables'
/// reach).
fn jitter_as_netem(p: &JitterParams) -> Result<(String, String, f64)> {
    let j = Jitter::new(p).map_err(|e| anyhow::anyhow!("{e}"))?;
    // The standard deviation of netem's table variate for each law.
    let table_sd = match p.dist {
        JitterDist::Normal => 1.0,
        JitterDist::Pareto => 4.0 / 3.0 * 0.75f64.sqrt(),
        JitterDist::Paretonormal => netfi::model::jitter::PARETONORMAL_SD,
    };
    let sigma_ms = p.sd_ms / table_sd;
    let rho = p.correlation.get();
    let mut text = format!("delay {} {}", time_us(p.mean_ms.get()), time_us(sigma_ms));
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

/// A duration for tc, in microseconds (tc keeps nanoseconds).
/// Bytes netem counts of an ITP frame's datagram beyond its payload: UDP
/// (8), IPv4 (20) and Ethernet (14) headers.
const NETEM_HEADER_BYTES: i64 = 42;

/// `rate` as netem's `rate … [packet_overhead [cellsize [celloverhead]]]`:
/// the text, the note, and the queue limit in packets.
fn rate_as_netem(p: &netfi::model::RateParams, label: &str) -> Result<(String, String, u64)> {
    let m = netfi::model::Rate::new(p).map_err(|e| anyhow::anyhow!("{label}: {e}"))?;
    let packets = m.packets();
    let overhead = packets.overhead_bytes as i64 - NETEM_HEADER_BYTES;
    let mut text = format!("rate {}bit", m.rate_bit_s());
    let (cell, cell_overhead) = m.cell().unwrap_or((0, 0));
    if overhead != 0 || cell != 0 {
        text.push_str(&format!(" {overhead}"));
    }
    if cell != 0 {
        text.push_str(&format!(" {cell} {cell_overhead}"));
    }
    let mut notes = vec![format!(
        "packet_overhead {overhead}: netem counts the UDP/IPv4/Ethernet headers ({NETEM_HEADER_BYTES} bytes) netfi leaves out of the payload"
    )];
    let per_frame = packets.count(packets.payload_bytes);
    if per_frame > 1 {
        notes.push(format!("approximated: netfi cuts each {}-byte payload into {per_frame} packets sharing its fate; netem sends each datagram as it comes", packets.payload_bytes));
    }
    let limit = match packets.limit {
        netfi::model::backlog::QueueLimit::Packets(n) => n,
        netfi::model::backlog::QueueLimit::Bytes(b) => {
            let n = (b / packets.largest_packet_bytes()).max(1);
            notes.push(format!("approximated: netem's limit counts packets: queue_bytes {b} becomes {n} packets of this stage's size"));
            n
        }
    };
    Ok((text, format!("rate (netem's own): {}", notes.join("; ")), limit))
}

fn time_us(ms: f64) -> String {
    format!("{}us", (ms * 1e3).round() as u64)
}

/// The simple Gilbert model (`loss gemodel p r 100% 0%`) with the loss rate
/// and mean loss run of a `ge_lomax` stage: runs of Bad are geometric with
/// mean `1/r`, and the loss is `p/(p + r)`, so `r = 1/R` and
/// `p = r·L/(1 − L)`.
fn ge_lomax_as_gilbert(p: &GeLomaxParams) -> Result<(String, String)> {
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

/// The netem delay clause, the note, the longest delay netem will give (ms),
/// and the distribution table (name, file body) if one is needed.
#[allow(clippy::type_complexity)]
fn delay_as_netem(p: &DelayParams, label: &str) -> Result<(String, String, f64, Option<(String, String)>)> {
    let min = p.min_ms.get();
    let fifo = if p.order == Order::Fifo {
        "; order = \"fifo\" is not reproduced (netem releases each packet at its own time, so jitter reorders)"
    } else {
        ""
    };
    match p.dist {
        DelayDist::None => Ok((format!("delay {}", time_us(min)), "exact (constant delay)".into(), min, None)),
        DelayDist::Uniform => {
            let j = p.jitter_ms.map_or(0.0, |j| j.get());
            Ok((
                format!("delay {} {}", time_us(min + j / 2.0), time_us(j / 2.0)),
                format!("exact up to microseconds (netem's default uniform jitter, mean ± half-width){fifo}"),
                min + j,
                None,
            ))
        }
        DelayDist::Hyperexp => {
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
                format!("delay {} {} distribution {name}", time_us(mean), time_us(scale)),
                note,
                longest,
                Some((name, body)),
            ))
        }
    }
}

fn fnv(s: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in s.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The netem words for a `corrupt` stage, and its note.
fn corrupt_line(p: &netfi::model::CorruptParams, label: &str, notes: &mut Vec<String>) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;
    use netfi::model::Millis;

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
}
