//! The statistical tier: each model against its analytic law, with fixed
//! seeds and stated significance levels. Slower than the unit tests (about
//! 10^7 simulated frames per check); run with `cargo test --test all statistical::`.

/// Nominal frame interval: 1 kHz.
const FRAME_NS: u64 = 1_000_000;

/// `z` with `P(|Z| > z) = 0.001`.
const Z_TWO_SIDED_0_001: f64 = 3.290_527;
/// `z` with `P(Z > z) = 0.001`.
const Z_ONE_SIDED_0_001: f64 = 3.090_232;
/// Student's `t` with 99 degrees of freedom, two-sided 0.001 (100 batches).
const T99_TWO_SIDED_0_001: f64 = 3.391_6;
/// Student's `t` with 99 degrees of freedom, two-sided 0.05 (100 batches).
const T99_TWO_SIDED_0_05: f64 = 1.984_2;
/// Kolmogorov's `c(α)` with `P(√n·D > c) = α` for α = 0.001, asymptotically:
/// `√(−ln(α/2)/2)`.
const KS_C_0_001: f64 = 1.949_5;

mod corrupt;
mod duplicate;
mod jitter;
mod models;
mod presets;
mod reorder_slot;
mod links;
mod loss_interval;
