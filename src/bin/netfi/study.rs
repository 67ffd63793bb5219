//! `netfi study`: plan a study, run its trials one by one, mark them,
//! record questionnaires, show progress, and write the report.

use anyhow::{bail, Result};
use clap::{Args, Subcommand, ValueEnum};
use netfi::study::file::{BlockOrder, ConditionSource};
use netfi::study::questionnaire::{self, Instrument};
use netfi::study::schedule::{balance, Due};
use netfi::study::store::{OpenStudy, ScheduleRecord};
use netfi::study::trials::{self, Mark};
use netfi::study::view;
use std::path::PathBuf;

/// Run a study: each participant's schedule of conditions, trial by trial
/// (each a `netfi run`), their questionnaires, and the comparison of the
/// conditions.
#[derive(Debug, Args)]
pub struct StudyArgs {
    #[command(subcommand)]
    pub command: StudyCmd,
}

#[derive(Debug, Subcommand)]
pub enum StudyCmd {
    /// Print every participant's schedule (blocks, trials, seeds,
    /// questionnaires), and with --write record it in the data folder.
    Plan {
        /// The study file (TOML).
        file: PathBuf,
        /// Only this participant.
        #[arg(long, short)]
        participant: Option<String>,
        /// Record the schedules (`DATA/schedule.json`, a copy of the study file).
        #[arg(long)]
        write: bool,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Run the participant's next trial until it ends, or until Ctrl-C
    /// (SIGINT or SIGTERM): the run then stops and reports as Ctrl-C stops
    /// `netfi run`, and the trial is marked stopped.
    Next {
        /// The study file (TOML).
        file: PathBuf,
        /// The participant's id.
        #[arg(long, short)]
        participant: String,
        /// The `netfi` executable the trial runs (default: this one).
        #[arg(long, hide = true)]
        netfi: Option<PathBuf>,
    },
    /// Mark the trial that ran (or --trial N) done (counted), failed (over,
    /// not counted) or repeat (run again).
    Mark {
        /// The study file (TOML).
        file: PathBuf,
        /// The participant's id.
        #[arg(long, short)]
        participant: String,
        /// done, failed or repeat.
        how: MarkArg,
        /// The trial (default: the one waiting for its mark).
        #[arg(long)]
        trial: Option<u32>,
        /// A note kept with the trial (in the table's `note` column).
        #[arg(long, default_value = "")]
        note: String,
        /// A `[[measure]]` of the study counted in the trial, NAME=COUNT
        /// (e.g. `--count drops=2`); again for each.
        #[arg(long = "count", value_name = "NAME=COUNT")]
        counts: Vec<String>,
    },
    /// Record the study's `[[measure]]`s counted in a trial (the last that
    /// ran, or --trial N), without changing its mark.
    Count {
        /// The study file (TOML).
        file: PathBuf,
        /// The participant's id.
        #[arg(long, short)]
        participant: String,
        /// The trial (default: the last that ran).
        #[arg(long)]
        trial: Option<u32>,
        /// NAME=COUNT for each measure (e.g. `drops=2 errors=0`).
        #[arg(required = true, value_name = "NAME=COUNT")]
        counts: Vec<String>,
    },
    /// Record a questionnaire due now: `sus` with ten answers 1–5, or
    /// `tlx` with six scales 0–100 (mental, physical, temporal, performance,
    /// effort, frustration); or --missing with the reason it was not given.
    Answer {
        /// The study file (TOML).
        file: PathBuf,
        /// The participant's id.
        #[arg(long, short)]
        participant: String,
        /// sus or tlx.
        instrument: InstrumentArg,
        /// The answers, in order.
        values: Vec<u32>,
        /// Record it as not given, for this reason.
        #[arg(long, value_name = "REASON")]
        missing: Option<String>,
        /// A weighted NASA-TLX's 15 choices, in the order of the pairs
        /// (mental–physical, mental–temporal, mental–performance,
        /// mental–effort, mental–frustration, physical–temporal, …,
        /// effort–frustration): the scale chosen in each (mental, physical,
        /// temporal, performance, effort or frustration), comma-separated.
        #[arg(long, value_name = "SCALE,…", value_delimiter = ',')]
        pairs: Option<Vec<String>>,
    },
    /// Each participant's progress (trials done, what comes next).
    Status {
        /// The study file (TOML).
        file: PathBuf,
        /// Only this participant, trial by trial.
        #[arg(long, short)]
        participant: Option<String>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write the study's table (trials.csv, sus.csv, tlx.csv), the
    /// comparison of the conditions (summary.json) and report.html.
    Report {
        /// The study file (TOML).
        file: PathBuf,
        /// Where (default: DATA/report).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Compare within the groups of this participant attribute too
        /// (default: `group`, when every participant has one).
        #[arg(long)]
        group: Option<String>,
        /// Leave the suspect trials (`[clean]`) out of the comparison; the
        /// report says how many it left out.
        #[arg(long)]
        leave_out_suspect: bool,
    },
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum MarkArg {
    Done,
    Failed,
    Repeat,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum InstrumentArg {
    Sus,
    Tlx,
}

pub fn run(args: StudyArgs) -> Result<()> {
    match args.command {
        StudyCmd::Plan { file, participant, write, json } => plan(&OpenStudy::open(&file)?, participant.as_deref(), write, json),
        StudyCmd::Next { file, participant, netfi } => next(&OpenStudy::open(&file)?, &participant, netfi),
        StudyCmd::Mark { file, participant, how, trial, note, counts } => {
            let s = OpenStudy::open(&file)?;
            let p = s.participant(&participant)?;
            let how = match how {
                MarkArg::Done => Mark::Done,
                MarkArg::Failed => Mark::Failed,
                MarkArg::Repeat => Mark::Repeat,
            };
            let counts = trials::parse_counts(&counts).map_err(anyhow::Error::msg)?;
            let a = trials::mark_counting(&s, p, trial, how, &note, &counts)?;
            println!("{participant}: trial {} ({}, attempt {}) marked {}", a.trial, a.condition, a.attempt, a.state.as_str());
            Ok(())
        }
        StudyCmd::Count { file, participant, trial, counts } => {
            let s = OpenStudy::open(&file)?;
            let p = s.participant(&participant)?;
            let counts = trials::parse_counts(&counts).map_err(anyhow::Error::msg)?;
            let a = trials::count(&s, p, trial, &counts)?;
            let said: Vec<String> = a.counts.iter().map(|(k, v)| format!("{k} {v}")).collect();
            println!("{participant}: trial {} ({}, attempt {}): {}", a.trial, a.condition, a.attempt, said.join(", "));
            Ok(())
        }
        StudyCmd::Answer { file, participant, instrument, values, missing, pairs } => answer(&file, &participant, instrument, &values, pairs.as_deref(), missing.as_deref()),
        StudyCmd::Status { file, participant, json } => status(&OpenStudy::open(&file)?, participant.as_deref(), json),
        StudyCmd::Report { file, out, group, leave_out_suspect } => {
            let s = OpenStudy::open(&file)?;
            let (dir, suspect) = netfi::study::report::write(&s, out.as_deref(), group.as_deref(), leave_out_suspect)?;
            eprintln!("{suspect}");
            println!("{}", dir.display());
            Ok(())
        }
    }
}

fn plan(s: &OpenStudy, only: Option<&str>, write: bool, json: bool) -> Result<()> {
    let which: Vec<usize> = match only {
        Some(id) => vec![s.participant(id)?],
        None => (0..s.study.participants.len()).collect(),
    };
    if write {
        let path = s.record_schedules()?;
        eprintln!("schedules recorded in {}", path.display());
    }
    if json {
        let records: Vec<ScheduleRecord> = which.iter().map(|&p| ScheduleRecord::of(s, p)).collect();
        println!("{}", serde_json::to_string_pretty(&records)?);
        return Ok(());
    }
    let st = &s.study;
    println!(
        "{} — seed {}, {} block(s), {} condition(s), {} participant(s); data in {}",
        st.name,
        st.seed,
        st.blocks.len(),
        st.conditions.len(),
        st.participants.len(),
        s.data.display()
    );
    println!("order: {}", balance(st));
    match st.trial.peers {
        netfi::study::file::Peers::Lab => println!("peers: the lab's console and robot ({})", if st.trial.lab_args.is_empty() { "iceoryx2, each trial's run id in DATA/running.json".to_string() } else { st.trial.lab_args.join(" ") }),
        netfi::study::file::Peers::Synthetic if st.trial.capture.is_some() => println!("peers: netfi's own console replaying the capture, and its simulated robot (a dry run)"),
        netfi::study::file::Peers::Synthetic => println!("peers: netfi's own synthetic console and simulated robot (a dry run)"),
    }
    for c in s.changed_inputs()? {
        println!("CHANGED: {c}");
    }
    for c in &st.conditions {
        let base = if st.baseline.is_some_and(|b| st.conditions[b].name == c.name) { "  (baseline)" } else { "" };
        let what = match &c.source {
            ConditionSource::Inline(_) => "inline stages".to_string(),
            other => other.describe(),
        };
        println!("  condition {:<16} {what}{base}", c.name);
    }
    for p in which {
        let sch = &s.schedules[p];
        let part = &st.participants[p];
        let attrs: Vec<String> = part.attributes.iter().map(|(k, v)| format!("{k}={v}")).collect();
        let row = match (st.order, sch.square_row) {
            (BlockOrder::Latin, Some(r)) => format!(" — square row {}", r + 1),
            _ => String::new(),
        };
        let blocks: Vec<&str> = sch.blocks.iter().map(|&b| st.blocks[b].name.as_str()).collect();
        println!("\n{}{}{row}: {}", part.id, if attrs.is_empty() { String::new() } else { format!(" ({})", attrs.join(", ")) }, blocks.join(" → "));
        let print_due = |after: u32| {
            for d in sch.due.iter().filter(|d| d.before_trial() == after + 1) {
                match d {
                    Due::Sus => println!("      System Usability Scale"),
                    Due::Tlx { .. } => println!("      NASA-TLX"),
                }
            }
        };
        print_due(0);
        for t in &sch.trials {
            println!(
                "  {:>3}  {:<20} {:<16} {}/{}  seed {}",
                t.number,
                st.blocks[t.block].name,
                st.conditions[t.condition].name,
                t.repetition,
                st.blocks[t.block].trials,
                t.seed
            );
            print_due(t.number);
        }
    }
    Ok(())
}

fn next(s: &OpenStudy, participant: &str, netfi: Option<PathBuf>) -> Result<()> {
    let p = s.participant(participant)?;
    let netfi = match netfi {
        Some(n) => n,
        None => std::env::current_exe()?,
    };
    netfi::service::signals::install();
    let a = trials::run_next(s, p, &netfi, netfi::service::signals::stop_requested, |a| {
        eprintln!("{participant}: trial {} ({}), attempt {}, seed {}: running in {}", a.trial, a.condition, a.attempt, a.seed, s.participant_dir(p).join(&a.dir).display());
    })?;
    let how = if a.stopped { "stopped" } else { "ended" };
    println!("{participant}: trial {} ({}) {how}: {} ({})", a.trial, a.condition, a.state.as_str(), a.run_status.as_deref().unwrap_or("?"));
    for f in &a.faults {
        println!("  fault: {f}");
    }
    if a.state == netfi::study::AttemptState::Ran {
        println!("  mark it: netfi study mark {} --participant {participant} done|failed|repeat", s.file.display());
    }
    Ok(())
}

fn answer(file: &std::path::Path, participant: &str, instrument: InstrumentArg, values: &[u32], pairs: Option<&[String]>, missing: Option<&str>) -> Result<()> {
    let s = OpenStudy::open(file)?;
    let p = s.participant(participant)?;
    let (lock, state) = netfi::study::store::claim(&s, p, "netfi study answer")?;
    let instrument = match instrument {
        InstrumentArg::Sus => Instrument::Sus,
        InstrumentArg::Tlx => Instrument::Tlx,
    };
    let Some(due) = questionnaire::due_now(&s, p, instrument, |t| state.finished(t)) else {
        bail!("no {} of `{participant}` is due now (see `netfi study status {} --participant {participant}`)", match instrument {
            Instrument::Sus => "System Usability Scale",
            Instrument::Tlx => "NASA-TLX",
        }, file.display());
    };
    let pairs: Option<Vec<usize>> = pairs
        .map(|words| {
            words
                .iter()
                .map(|w| questionnaire::tlx_scale_named(w).ok_or_else(|| anyhow::anyhow!("--pairs: `{w}` is no TLX scale (mental, physical, temporal, performance, effort, frustration)")))
                .collect::<Result<Vec<_>>>()
        })
        .transpose()?;
    let path = questionnaire::record(&s, p, &due, values, pairs.as_deref(), missing)?;
    lock.release();
    println!("{participant}: {} recorded in {}", due.key(), path.display());
    Ok(())
}

fn status(s: &OpenStudy, only: Option<&str>, json: bool) -> Result<()> {
    let which: Vec<usize> = match only {
        Some(id) => vec![s.participant(id)?],
        None => (0..s.study.participants.len()).collect(),
    };
    let views = which.iter().map(|&p| view::participant(s, p)).collect::<Result<Vec<_>, _>>()?;
    if json {
        println!("{}", serde_json::to_string_pretty(&views)?);
        return Ok(());
    }
    if let Some(v) = views.first() {
        for c in &v.study_changed {
            println!("CHANGED: {c}");
        }
    }
    for v in &views {
        let counts: Vec<String> = v.counts.iter().map(|(k, n)| format!("{n} {k}")).collect();
        let next = match v.next.kind {
            "trial" => format!("next: trial {} ({}, block {})", v.next.trial.unwrap_or(0), v.next.condition.as_deref().unwrap_or("?"), v.next.block.as_deref().unwrap_or("?")),
            "running" => match &v.next.waiting_for {
                Some(w) => format!("running: trial {}, waiting for {w}", v.next.trial.unwrap_or(0)),
                None => format!("running: trial {}", v.next.trial.unwrap_or(0)),
            },
            "unmarked" => format!("trial {} waits for its mark", v.next.trial.unwrap_or(0)),
            "questionnaire" => format!("due: {}", v.next.key.as_deref().unwrap_or("?")),
            _ => "finished".into(),
        };
        let busy = v.busy.as_ref().map(|b| format!(" [busy: {b}]")).unwrap_or_default();
        println!("{:<12} {} trials: {}; {next}{busy}", v.participant, v.trials.len(), counts.join(", "));
        if only.is_some() {
            for t in &v.trials {
                let extra = [
                    (t.attempts > 1).then(|| format!("{} attempts", t.attempts)),
                    t.stopped.then(|| "stopped".to_string()),
                    (t.clean == "suspect").then(|| format!("SUSPECT: {}", t.suspect_because.join("; "))),
                    (!t.counts.is_empty()).then(|| t.counts.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")),
                    (!t.note.is_empty()).then(|| t.note.clone()),
                ];
                let extra: Vec<String> = extra.into_iter().flatten().chain(t.faults.iter().map(|f| format!("fault: {f}"))).collect();
                println!("  {:>3}  {:<20} {:<16} {:<12} {}", t.trial, t.block, t.condition, t.state, extra.join("; "));
            }
        }
    }
    Ok(())
}
