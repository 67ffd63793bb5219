//! Each participant's schedule: the order of the blocks, the trials within
//! each block, every trial's seed, and the questionnaires due between them.
//!
//! Pure and reproducible: a schedule is a function of the study file alone
//! (its seed, blocks, participants and order rule), so it can be printed
//! before the study starts and recomputed at every trial.
//!
//! Seeds: a participant's key is the 64-bit FNV-1a hash of their id; the
//! shuffle of block `b` draws from a SplitMix64 stream started at
//! `splitmix64(seed ^ SHUFFLE_TAG ^ key ^ splitmix64(b))`, and trial `n`
//! (1-based position) runs with `splitmix64(splitmix64(seed ^ TRIAL_TAG ^
//! key) ^ n)`. The shuffle is Fisher–Yates with bounded draws by rejection
//! (Lemire), so it is the same on every platform and with every version of
//! `rand`. A repeated trial keeps its seed: its condition's faults are drawn
//! from the same stream as the first attempt's.

use super::file::{BlockOrder, Study, TlxWhen, Within};
use super::square::balanced_latin_square;
use crate::scenario::splitmix64;

const SHUFFLE_TAG: u64 = 0x5348_5546_464c_4531; // "SHUFFLE1"
const TRIAL_TAG: u64 = 0x5452_4941_4c53_4431; // "TRIALSD1"

/// One trial of a participant's schedule.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Trial {
    /// 1-based position in the participant's schedule.
    pub number: u32,
    /// Index into [`Study::blocks`].
    pub block: usize,
    /// 1-based position of the block in this participant's order.
    pub block_position: u32,
    /// Index into [`Study::conditions`].
    pub condition: usize,
    /// 1-based: the how-manieth trial of this condition in this block.
    pub repetition: u32,
    /// The seed of the trial's `netfi run`.
    pub seed: u64,
}

/// A questionnaire due at a point of the schedule.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub enum Due {
    /// The System Usability Scale, before trial 1.
    Sus,
    /// A NASA-TLX after the trial `after` (the last of block `block` with
    /// [`TlxWhen::Block`]).
    Tlx { after: u32, block: usize },
}

impl Due {
    /// The key it is stored under: `sus`, `tlx-NN` (after trial NN).
    pub fn key(&self) -> String {
        match self {
            Due::Sus => "sus".into(),
            Due::Tlx { after, .. } => format!("tlx-{after:02}"),
        }
    }

    /// The trial that must not start before it is answered (1-based), if
    /// any: trial 1 for the SUS, the next trial for a TLX.
    pub fn before_trial(&self) -> u32 {
        match self {
            Due::Sus => 1,
            Due::Tlx { after, .. } => after + 1,
        }
    }
}

/// A participant's whole schedule.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Schedule {
    /// Index into [`Study::participants`].
    pub participant: usize,
    /// The row of the balanced Latin square taken (with [`BlockOrder::Latin`]).
    pub square_row: Option<usize>,
    /// The blocks in this participant's order (indices into [`Study::blocks`]).
    pub blocks: Vec<usize>,
    pub trials: Vec<Trial>,
    /// The questionnaires, in the order they are due.
    pub due: Vec<Due>,
}

/// The 64-bit FNV-1a hash of `bytes`.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3))
}

/// The seed of trial `number` (1-based) of participant `id`.
pub fn trial_seed(study_seed: u64, id: &str, number: u32) -> u64 {
    splitmix64(splitmix64(study_seed ^ TRIAL_TAG ^ fnv1a(id.as_bytes())) ^ u64::from(number))
}

/// A SplitMix64 stream: the generator is one addition, its output the
/// `splitmix64` finalizer, so the sequence is fixed by the seed alone.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        let x = self.0;
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        splitmix64(x)
    }

    /// Uniform in `0..n` (n ≥ 1), unbiased: Lemire's multiply with
    /// rejection of the short first interval.
    fn below(&mut self, n: u64) -> u64 {
        let threshold = n.wrapping_neg() % n;
        loop {
            let m = u128::from(self.next()) * u128::from(n);
            if (m as u64) >= threshold {
                return (m >> 64) as u64;
            }
        }
    }
}

/// Shuffles `items` in place (Fisher–Yates, last to first).
fn shuffle<T>(items: &mut [T], rng: &mut SplitMix) {
    for i in (1..items.len()).rev() {
        let j = rng.below(i as u64 + 1) as usize;
        items.swap(i, j);
    }
}

/// The schedule of participant `p` (an index into the study's participants).
///
/// # Panics
/// If `p` is not a participant of `study`.
pub fn schedule(study: &Study, p: usize) -> Schedule {
    let participant = &study.participants[p];
    let key = fnv1a(participant.id.as_bytes());
    let (square_row, blocks) = match study.order {
        BlockOrder::Latin => match study.first_block {
            None => {
                let square = balanced_latin_square(study.blocks.len());
                let row = p % square.len();
                (Some(row), square[row].clone())
            }
            // The first block, then a square of the others, in the file's order.
            Some(first) => {
                let rest: Vec<usize> = (0..study.blocks.len()).filter(|&b| b != first).collect();
                let square = square_of(rest.len());
                let row = p % square.len();
                let order = std::iter::once(first).chain(square.get(row).into_iter().flatten().map(|&k| rest[k])).collect();
                (Some(row), order)
            }
        },
        BlockOrder::Table => (None, participant.blocks.clone().expect("the parser requires a table row of every participant")),
        BlockOrder::Fixed => (None, (0..study.blocks.len()).collect()),
    };
    let mut trials = Vec::new();
    let mut due = Vec::new();
    if study.questionnaires.sus {
        due.push(Due::Sus);
    }
    for (position, &b) in blocks.iter().enumerate() {
        let block = &study.blocks[b];
        // Each condition's trials, in the block's order, then shuffled.
        let mut items: Vec<(usize, u32)> = block.conditions.iter().flat_map(|&c| (1..=block.trials).map(move |r| (c, r))).collect();
        if study.within == Within::Shuffle {
            let mut rng = SplitMix(splitmix64(study.seed ^ SHUFFLE_TAG ^ key ^ splitmix64(b as u64)));
            shuffle(&mut items, &mut rng);
            // The k-th trial of a condition in the block is the k-th to come.
            let mut seen = vec![0u32; study.conditions.len()];
            for item in &mut items {
                seen[item.0] += 1;
                item.1 = seen[item.0];
            }
        }
        for (condition, repetition) in items {
            let number = trials.len() as u32 + 1;
            trials.push(Trial {
                number,
                block: b,
                block_position: position as u32 + 1,
                condition,
                repetition,
                seed: trial_seed(study.seed, &participant.id, number),
            });
            if study.questionnaires.tlx == TlxWhen::Trial {
                due.push(Due::Tlx { after: number, block: b });
            }
        }
        if study.questionnaires.tlx == TlxWhen::Block {
            due.push(Due::Tlx { after: trials.len() as u32, block: b });
        }
    }
    Schedule { participant: p, square_row, blocks, trials, due }
}

/// The balanced Latin square of `n` blocks; one empty row for none.
fn square_of(n: usize) -> Vec<Vec<usize>> {
    if n == 0 {
        vec![Vec::new()]
    } else {
        balanced_latin_square(n)
    }
}

/// How often each block stands in each position across the participants'
/// schedules: `counts[block][position]`.
pub fn position_counts(study: &Study) -> Vec<Vec<u32>> {
    let n = study.blocks.len();
    let mut counts = vec![vec![0u32; n]; n];
    for p in 0..study.participants.len() {
        for (pos, &b) in schedule(study, p).blocks.iter().enumerate() {
            counts[b][pos] += 1;
        }
    }
    counts
}

/// What the order rule gives across the participants, in words: whether
/// every block stands in every position equally often.
pub fn balance(study: &Study) -> String {
    let counts = position_counts(study);
    // A block everyone takes first stands apart: the balance is of the others.
    let first = study.first_block;
    let all: Vec<u32> = counts
        .iter()
        .enumerate()
        .filter(|(b, _)| Some(*b) != first)
        .flat_map(|(_, row)| row.iter().skip(usize::from(first.is_some())).copied())
        .collect();
    let (lo, hi) = (all.iter().min().copied().unwrap_or(0), all.iter().max().copied().unwrap_or(0));
    let m = study.participants.len();
    let rule = match study.order {
        BlockOrder::Latin => {
            let counterbalanced = study.blocks.len() - usize::from(study.first_block.is_some());
            let rows = square_of(counterbalanced).len();
            let whole = m / rows;
            let rest = m % rows;
            if rest == 0 {
                format!("balanced Latin square of {rows} rows, taken {whole} time(s) whole by {m} participants")
            } else {
                format!(
                    "balanced Latin square of {rows} rows: {m} participants take it {whole} time(s) whole and {rest} row(s) more \
                     (add {} participant(s) for a whole square)",
                    rows - rest
                )
            }
        }
        BlockOrder::Table => format!("each participant's own order ({m} participants)"),
        BlockOrder::Fixed => format!("the file's order for all {m} participants"),
    };
    let rule = match first {
        Some(b) => format!("`{}` first for everyone, then {rule}", study.blocks[b].name),
        None => rule,
    };
    if lo == hi {
        format!("{rule}: every block in every position {lo} time(s)")
    } else {
        format!("{rule}: a block stands in a position {lo} to {hi} times")
    }
}
