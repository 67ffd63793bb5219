//! Fitting and the fault parameter database: fits land within tolerance and
//! reproduce from their seed, the shipped database parses and every entry
//! re-simulates to its stored value, target-based scenarios resolve, the
//! calibrated presets hit their labels, and the `fit` and `export netem`
//! commands behave as documented.
//!
//! Tiers: everything here runs in `cargo test`. The database checks come in
//! two tiers: `database::sampled_*` re-simulates 20 entries (seconds);
//! `database::every_entry_*` re-simulates all 450 twice (about a minute on 2
//! cores). `netfi fit db --verify config/faultdb.toml` runs the same full
//! check from the command line.

mod cli;
mod database;
mod fits;
mod jitter;
mod scenarios;
