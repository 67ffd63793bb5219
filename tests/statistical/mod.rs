//! The statistical tier: each model against its analytic law, with fixed
//! seeds and stated significance levels. Slower than the unit tests (about
//! 10^7 simulated frames per check); run with `cargo test --test all statistical::`.

mod corrupt;
mod duplicate;
mod jitter;
mod models;
mod presets;
mod reorder_slot;
mod links;
