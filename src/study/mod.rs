//! Studies: participants who each run a schedule of trials under a
//! study's conditions, and the comparison of the conditions afterwards
//! (`netfi study`, and the experimenter's page of `netfi ui`).
//!
//! - The study file ([`file`]) names the conditions, their blocks, the
//!   participants, the order rule and a seed; [`schedule`] turns it into
//!   each participant's trials, reproducibly ([`square`]: balanced Latin
//!   squares). Both pure.
//! - [`store`] keeps the state on disk in the study's data folder, one
//!   folder per participant: whole files written by temp + rename, and a
//!   lock per participant (`flock`, let go by the kernel when its holder
//!   dies), so two experimenters cannot advance one participant at once
//!   and a trial cut by a kill is found and marked `interrupted`.
//! - [`trials`] runs a trial: a `netfi run` child process in
//!   `DATA/P/trial-NN-CONDITION/`; its figures ([`metrics`], pure) come
//!   from the run's report and trace.
//! - [`view`]: a participant's progress, for `netfi study status` and the
//!   experimenter's page.
//! - [`questionnaire`] scores and stores the SUS and NASA-TLX answers.
//! - [`report`] writes the study's table (CSV), the comparison
//!   ([`summary`], [`stats`]: pure) as JSON and a self-contained HTML page.

pub mod file;
pub mod metrics;
mod parse;
pub mod questionnaire;
pub mod report;
pub mod schedule;
pub mod square;
pub mod stats;
pub mod store;
pub mod summary;
pub mod trials;
pub mod view;

pub use file::{Study, StudyFileError};
pub use parse::parse_study;
pub use schedule::{schedule, Schedule};
pub use store::{Attempt, AttemptState, OpenStudy, StudyError};
