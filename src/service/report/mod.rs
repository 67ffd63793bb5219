//! The run report: the three services' own reports joined into one account
//! of every frame, with the overhead histograms, the delay law and the
//! host's steal time.
//!
//! | file | what |
//! |---|---|
//! | `assemble` | reads what the services left in a run's directory and joins it: the runner's join, and a run started by hand (`RunReport::from_dir`) |
//! | `join` | the pure joins: the frame account, corruption, feedback, overhead, the streams' total |
//! | `text` | the run report as a person reads it, section by section |
//! | `emulator_text` | the stand-alone emulator's own report as text ([`emulator_text`]) |
//! | `trace_merge` | `trace_emulator.csv` + `received.csv` → `trace.csv`, and the delays |
//! | `delay` | the delays seen against the drawn and the model's law |
//! | `phases` | the run's stretches under one condition (phases, live switches, pauses), each with its loss and delay law |
//! | `provenance` | version, command line, start and host |
//! | `files` | files written whole ([`write_whole`]), and the cut ones found |
//!
//! The report's types are the contract `schema::run`, re-exported here.

mod assemble;
mod delay;
mod emulator_text;
pub mod files;
mod join;
pub mod phases;
mod provenance;
mod text;
mod trace_merge;

pub use crate::service::schema::run::*;
pub use assemble::{DirError, RunFacts, RunnerView};
pub use delay::Law;
pub use phases::RunTimeline;
pub use files::{cut_files, write_whole, WriteError};
pub use join::{account, corruption, difference, overhead};
pub use text::{busy_text, dropped_list, line, opt, phase_title, Words};
pub use emulator_text::emulator_text;

use crate::host::Steal;
use crate::service::plan::Plan;

impl RunReport {
    /// Joins what the services left in the run's output directory into the
    /// run's report. `faults` holds what the runner saw go wrong (dead
    /// processes); the report adds missing reports, lost frames, a trace
    /// that could not be joined and cut files. A run `interrupted` (Ctrl-C,
    /// SIGTERM) was stopped at a person's request: a normal end.
    pub fn assemble(plan: &Plan, duration_s: f64, steal: Steal, processes: Vec<ProcessEnd>, faults: Vec<String>, interrupted: bool) -> RunReport {
        let facts = RunFacts {
            run_id: &plan.run_id,
            out: &plan.out,
            scenario: &plan.spec.name,
            spec: Some(&plan.spec),
            seed: plan.seed,
            scenario_path: Some(&plan.scenario_path),
        };
        let s0 = &plan.streams[0];
        let lab = [("console", s0.console.is_none()), ("simulator", s0.simulator.is_none())].into_iter().filter(|(_, lab)| *lab).map(|(role, _)| role).collect();
        RunReport::assemble_run(&facts, RunnerView { duration_s, steal, processes, faults, interrupted, lab })
    }
}
