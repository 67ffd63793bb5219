//! A study file (TOML) → a validated [`Study`], with errors that name the
//! file, the line, the field, and what would be accepted.
//!
//! Pure: the text comes in as a `&str` with the name of its source; paths
//! in it (the data folder, scenario files, a capture) are kept as written,
//! for the shell to resolve against the file's directory.
//!
//! ```toml
//! name = "Peg transfer under network degradation"
//! seed = 2025                     # every schedule and trial seed derives from it
//! data = "peg-data"               # the data folder (default: "<file stem>-data")
//! trials = 1                      # trials of each condition in a block (default 1)
//! baseline = "Normal"             # what the report compares against (default: Normal, if used)
//! hide_condition = true           # the participant's view never names the condition
//!
//! [trial]                         # how each trial's `netfi run` is started
//! duration_s = 600                # the longest a trial runs (s, or "10min"); the experimenter stops it sooner
//! peers = "lab"                   # lab: the lab's console and robot, at [trial.lab]; synthetic (default): netfi's own, a dry run
//! peer_wait_s = 60                # lab: how long a trial waits for the console's first frame before it is interrupted
//! capture = "console.bin"         # synthetic only: replay a recording instead of the synthetic console
//! rate_hz = 1000
//! run_args = ["--no-isolate"]     # any other `netfi run` options, as `netfi run` reads them
//!
//! [trial.lab]                     # where the emulator meets the lab's programs: `netfi run`'s flags, without `--`
//! ingress = "udp://127.0.0.1:47001"
//! console-from = "first"
//! egress = "udp://127.0.0.1:47002"
//!
//! [clean]                         # when a trial is `suspect` (what netfi and the host added)
//! netfi_added_p99_ms = 1          # default 1 ms
//! steal_fraction = 0.05           # default 5 % of the trial's CPU time stolen
//!
//! [order]
//! blocks = "latin"                # latin (balanced Latin square) | table | fixed
//! within = "shuffle"              # conditions shuffled within a block | fixed
//! first = "free"                  # a block everyone takes first (latin only)
//!
//! [questionnaires]
//! sus = "start"                   # start | none
//! tlx = "block"                   # block (after each block) | trial | none
//! tlx_weighting = "raw"           # raw | pairwise (the 15 pairwise choices weight the scales)
//!
//! [[measure]]                     # what the experimenter counts in each trial
//! name = "drops"
//! label = "Pegs dropped"
//! [[condition]]                   # conditions that are not presets
//! name = "loss-30"
//! stage = [{ loss = "30%" }]      # inline stages, as in a scenario file
//! [[condition]]
//! name = "lte"
//! scenario = "lte.toml"           # or a scenario file (or a preset)
//!
//! [[block]]
//! name = "free"
//! conditions = ["Normal"]
//! trials = 3
//! [[block]]
//! name = "packet loss"
//! conditions = ["PLM-1", "PLM-2", "PLM-3"]
//!
//! [[participant]]
//! id = "P01"
//! group = "novice"                # any other key is an attribute
//! blocks = ["free", "packet loss"]  # only with order.blocks = "table"
//! ```

use crate::service::args::RunArgs;
use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

/// The most participants, conditions per block, trials per condition and
/// trials per participant a study file may name: far beyond any lab study,
/// and bounds on every file and table the study writes.
pub const MAX_PARTICIPANTS: usize = 10_000;
/// The most trials of one condition in one block.
pub const MAX_TRIALS_PER_CONDITION: u32 = 100;
/// The most trials in one participant's schedule.
pub const MAX_TRIALS_PER_PARTICIPANT: usize = 999;
/// The longest trial, in seconds (a day).
pub const MAX_TRIAL_S: f64 = 86_400.0;
/// The longest name or id (it becomes a folder name).
pub const MAX_NAME_LEN: usize = 64;

/// The `netfi run` arguments a study decides for each trial, by clap's ids
/// of [`RunArgs`]' fields, with the study file's field that gives each
/// instead (`None`: the study sets it itself); `run_args` may not give
/// them. Their flags are the command's ([`RunArgs::command`]).
pub const STUDY_RUN_ARGS: [(&str, Option<&str>); 11] = [
    ("out", None),
    ("seed", None),
    ("run_id", None),
    ("json", None),
    ("duration_s", Some("trial.duration_s")),
    ("frames", None),
    ("capture", Some("trial.capture")),
    ("report_json", None),
    ("rate_hz", Some("trial.rate_hz")),
    ("console", Some("trial.peers")),
    ("robot", Some("trial.peers")),
];

/// A study file that could not be read, with where and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct StudyFileError {
    /// The file.
    pub origin: String,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// The field as written, e.g. `block[2].conditions[1]`.
    pub field: Option<String>,
    /// What is wrong, and what would be accepted.
    pub problem: String,
}

impl fmt::Display for StudyFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        crate::scenario::write_located(f, &self.origin, self.line, None, self.field.as_deref(), &self.problem)
    }
}

/// A validated study.
#[derive(Debug, Clone, PartialEq)]
pub struct Study {
    pub name: String,
    pub seed: u64,
    /// The data folder as written (relative to the study file), or `None`
    /// for `<file stem>-data` beside it.
    pub data: Option<String>,
    /// The condition the report tests the others against, if any.
    pub baseline: Option<usize>,
    /// The participant's view never names the condition.
    pub hide_condition: bool,
    pub trial: TrialSpec,
    /// Every condition the blocks use, in the order they first appear.
    pub conditions: Vec<Condition>,
    pub blocks: Vec<Block>,
    pub participants: Vec<Participant>,
    pub order: BlockOrder,
    pub within: Within,
    pub questionnaires: Questionnaires,
    /// What the experimenter counts in each trial (`[[measure]]`).
    pub measures: Vec<Measure>,
    /// The block every participant takes first (`order.first`), the
    /// others counterbalanced after it.
    pub first_block: Option<usize>,
    /// When a trial is `suspect`.
    pub clean: CleanRule,
}

/// When a trial is `suspect` rather than clean (`[clean]`): what netfi
/// itself added, or the host took, beyond these; or frames lost before
/// the emulator, or released while no robot listened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CleanRule {
    /// The most netfi itself may add to a frame's delay at the 99th
    /// percentile, ms (default 1).
    pub netfi_added_p99_ms: f64,
    /// The largest share of the trial's CPU time the host may steal
    /// (default 0.05).
    pub steal_fraction: f64,
}

impl Default for CleanRule {
    fn default() -> Self {
        CleanRule { netfi_added_p99_ms: 1.0, steal_fraction: 0.05 }
    }
}

/// Who plays each trial's console and robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Peers {
    /// netfi's own: the synthetic console (or the capture) and the
    /// simulated robot; a dry run of the study.
    #[default]
    Synthetic,
    /// The lab's own programs, met where `[trial.lab]` says.
    Lab,
}

/// How each trial's `netfi run` is started.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialSpec {
    /// The longest a trial runs, s (`--duration-s`); `None`: a capture's
    /// whole length, else `netfi run`'s default.
    pub duration_s: Option<f64>,
    /// A recording replayed as the console (`--capture`), as written.
    pub capture: Option<String>,
    /// `--rate-hz`.
    pub rate_hz: Option<f64>,
    /// Other `netfi run` options, as given (checked as `netfi run` reads
    /// them when the file is read).
    pub run_args: Vec<String>,
    /// Who plays the console and the robot.
    pub peers: Peers,
    /// `[trial.lab]` as `netfi run` flags: where the emulator meets the
    /// lab's programs (used with [`Peers::Lab`] only).
    pub lab_args: Vec<String>,
    /// How long a trial waits for the lab's console's first frame, s
    /// (`peer_wait_s`; default 60).
    pub peer_wait_s: Option<f64>,
}

impl TrialSpec {
    /// A trial's `netfi run` of `scenario`: this spec's duration and rate,
    /// the capture (`capture`: the file as the shell resolves it), and the
    /// options of `run_args`, read as `netfi run` reads them. What the study
    /// sets for each trial alone ([`STUDY_RUN_ARGS`]) is left to the caller.
    pub fn run(&self, scenario: &str, capture: Option<&Path>) -> Result<RunArgs, clap::Error> {
        let mut own = RunArgs::new(scenario);
        own.source.duration_s = self.duration_s;
        own.source.rate_hz = self.rate_hz;
        own.source.capture = capture.map(Path::to_path_buf);
        let lab = match self.peers {
            Peers::Synthetic => &[][..],
            Peers::Lab => {
                // Both ends the lab's, unless `[trial.lab]` keeps one of
                // netfi's (`robot = "own"`).
                let says = |flag: &str| self.lab_args.iter().any(|a| a == flag);
                own.peers.console = (!says("--console")).then_some(crate::service::args::Peer::Lab);
                own.peers.robot = (!says("--robot")).then_some(crate::service::args::Peer::Lab);
                &self.lab_args[..]
            }
        };
        RunArgs::from_argv(own.to_argv().into_iter().chain(lab.iter().cloned()).chain(self.run_args.iter().cloned()))
    }

    /// Whether a program of the lab's plays an end of each trial.
    pub fn lab(&self) -> bool {
        self.peers == Peers::Lab
    }
}

/// One condition: its name (a folder and column name) and what it runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Condition {
    pub name: String,
    pub source: ConditionSource,
}

/// What a condition's trials run.
#[derive(Debug, Clone, PartialEq)]
pub enum ConditionSource {
    /// A built-in preset, by its canonical name.
    Preset(&'static str),
    /// A scenario file, as written (relative to the study file).
    File(String),
    /// A scenario given inline: its TOML text, already validated.
    Inline(String),
}

impl ConditionSource {
    /// What a person reads for it: the preset, the file, or "inline".
    pub fn describe(&self) -> String {
        match self {
            ConditionSource::Preset(p) => format!("preset {p}"),
            ConditionSource::File(f) => format!("file {f}"),
            ConditionSource::Inline(_) => "inline stages".into(),
        }
    }
}

/// A block: conditions run together, each `trials` times.
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    pub name: String,
    /// Indices into [`Study::conditions`], as the file lists them.
    pub conditions: Vec<usize>,
    pub trials: u32,
}

/// A participant: an id (a folder name), attributes, and, with an
/// explicit order table, the order of the blocks.
#[derive(Debug, Clone, PartialEq)]
pub struct Participant {
    pub id: String,
    /// Every other key of the participant's table, as text.
    pub attributes: BTreeMap<String, String>,
    /// Indices into [`Study::blocks`] (with [`BlockOrder::Table`]).
    pub blocks: Option<Vec<usize>>,
}

/// How the blocks are ordered for each participant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockOrder {
    /// A balanced Latin square's rows, taken by the participants in the
    /// file's order.
    Latin,
    /// Each participant's own `blocks`.
    Table,
    /// The file's order for everyone.
    Fixed,
}

/// How the trials within a block are ordered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Within {
    /// Shuffled with a seed of the participant and the block.
    Shuffle,
    /// The block's order, each condition's trials together.
    Fixed,
}

/// When a NASA-TLX is asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TlxWhen {
    None,
    /// After the last trial of each block.
    Block,
    /// After every trial.
    Trial,
}

/// The questionnaires a study asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Questionnaires {
    /// A System Usability Scale before the first trial.
    pub sus: bool,
    pub tlx: TlxWhen,
    /// How the TLX is scored (`questionnaires.tlx_weighting`).
    pub tlx_weighting: TlxWeighting,
}


/// A measure only a person can count (errors, drops, failed attempts),
/// entered per trial by the experimenter: a column of the study's table,
/// compared across the conditions like every figure.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Measure {
    /// Its column name (letters, digits, `_`).
    pub name: String,
    /// What it counts, for the page and the report.
    pub label: String,
}

/// The largest count a measure takes.
pub const MAX_COUNT: u32 = 1_000_000;

/// How the NASA-TLX is scored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TlxWeighting {
    /// The raw TLX: the unweighted mean of the six scales.
    #[default]
    Raw,
    /// Hart and Staveland's weighting: the participant also chooses, in
    /// each of the 15 pairs of scales, the one that mattered more; a
    /// scale's weight is how often it was chosen (0–5), the score
    /// Σ weight × rating / 15.
    Pairwise,
}

impl Study {
    /// The measure `name`, if the study declares it.
    pub fn measure(&self, name: &str) -> Option<&Measure> {
        self.measures.iter().find(|m| m.name == name)
    }
}
