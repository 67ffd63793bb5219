//! The study's presets (docs/spec.md §4): the parameters its code ran, and
//! calibrated variants, written once. `scenario` turns them into stages;
//! `fit` reads them for `--like`.
//!
//! Names match case-insensitively and with or without the dash (`PLM-2`,
//! `plm2`).

use super::{DelayParams, GeLomaxParams, ModelSpec, OutageParams};

/// The preset names: the study's, in the order it lists them, then their
/// calibrated variants (`-cal`), which keep each preset's shape and scale one
/// parameter so that the preset realizes its label (see [`preset_stages`]).
pub const PRESET_NAMES: [&str; 19] = [
    "Normal", "PLM-1", "PLM-2", "PLM-3", "DLM-1", "DLM-2", "DLM-3", "CLM-1", "CLM-2", "CLM-3", "PLM-1-cal", "PLM-2-cal",
    "PLM-3-cal", "DLM-1-cal", "DLM-2-cal", "DLM-3-cal", "CLM-1-cal", "CLM-2-cal", "CLM-3-cal",
];

/// What each preset is labelled in the study (the target, not necessarily
/// what its parameters realize).
pub fn preset_label(name: &str) -> Option<&'static str> {
    let canonical = canonical_name(name)?;
    Some(match canonical {
        "Normal" => "nothing injected",
        "PLM-1" => "10% packet loss",
        "PLM-2" => "30% packet loss",
        "PLM-3" => "50% packet loss",
        "DLM-1" => "100 ms delay",
        "DLM-2" => "300 ms delay",
        "DLM-3" => "500 ms delay",
        "CLM-1" => "10% communication loss",
        "CLM-2" => "30% communication loss",
        "CLM-3" => "50% communication loss",
        "PLM-1-cal" => "10% packet loss, calibrated",
        "PLM-2-cal" => "30% packet loss, calibrated",
        "PLM-3-cal" => "50% packet loss, calibrated",
        "DLM-1-cal" => "100 ms delay, calibrated",
        "DLM-2-cal" => "300 ms delay, calibrated",
        "DLM-3-cal" => "500 ms delay, calibrated",
        "CLM-1-cal" => "10% communication loss, calibrated",
        "CLM-2-cal" => "30% communication loss, calibrated",
        "CLM-3-cal" => "50% communication loss, calibrated",
        _ => unreachable!("canonical_name returns only listed names"),
    })
}

/// The canonical spelling of a preset name, if `name` is one.
pub fn canonical_name(name: &str) -> Option<&'static str> {
    let squash = |s: &str| s.chars().filter(|c| *c != '-' && *c != '_').collect::<String>().to_ascii_lowercase();
    let wanted = squash(name);
    PRESET_NAMES.into_iter().find(|p| squash(p) == wanted)
}

/// The transition matrix of every PLM preset (Good, Bad).
pub const STUDY_TRANSITION: [[f64; 2]; 2] = [[0.95, 0.05], [0.10, 0.90]];

fn plm(alpha: [f64; 2], lambda: [f64; 2]) -> ModelSpec {
    ModelSpec::GeLomax(GeLomaxParams::two_state(STUDY_TRANSITION, alpha, lambda))
}

fn dlm(min_ms: f64, weights: [f64; 2], rates_per_ms: [f64; 2]) -> ModelSpec {
    ModelSpec::Delay(DelayParams::hyperexp(min_ms, &weights, &rates_per_ms).expect("preset constants are valid"))
}

fn clm(max_ms: f64, cooldown_ms: f64) -> ModelSpec {
    ModelSpec::Outage(OutageParams::time(1.0, 0.0, max_ms, cooldown_ms).expect("preset constants are valid"))
}

/// The models of a preset, in pipeline order (none for `Normal`, one for
/// every other), or `None` if `name` is not a preset.
pub fn preset_models(name: &str) -> Option<Vec<ModelSpec>> {
    let canonical = canonical_name(name)?;
    let model = match canonical {
        "Normal" => return Some(Vec::new()),
        "PLM-1" => plm([4.428, 4.966], [1.638, 0.271]),
        "PLM-2" => plm([4.604, 3.901], [3.552, 1.466]),
        "PLM-3" => plm([3.859, 3.797], [3.324, 6.049]),
        "DLM-1" => dlm(70.0, [0.72645, 0.27355], [0.02711, 0.08529]),
        "DLM-2" => dlm(210.0, [0.89258, 0.10742], [0.01081, 0.01624]),
        "DLM-3" => dlm(406.0, [0.89574, 0.10426], [0.01025, 0.01551]),
        "CLM-1" => clm(3000.0, 8500.0),
        "CLM-2" => clm(1000.0, 1000.0),
        "CLM-3" => clm(2000.0, 1000.0),
        // Calibrated variants: the preset's shape with one scale fitted so
        // that the exact long-run value is the label, at 1 kHz for CLM
        // (`netfi fit loss 10% --like PLM-1`, …, `netfi fit outage 50% --like
        // CLM-3`; parameters to 7 significant digits). PLM: both λ scaled;
        // DLM: both rates scaled; CLM: the cooldown.
        "PLM-1-cal" => plm([4.428, 4.966], [1.659083, 0.2744881]),
        "PLM-2-cal" => plm([4.604, 3.901], [3.506295, 1.447136]),
        "PLM-3-cal" => plm([3.859, 3.797], [3.284075, 5.976345]),
        "DLM-1-cal" => dlm(70.0, [0.72645, 0.27355], [0.02711332, 0.08530046]),
        "DLM-2-cal" => dlm(210.0, [0.89258, 0.10742], [0.01071203, 0.01609282]),
        "DLM-3-cal" => dlm(406.0, [0.89574, 0.10426], [0.01026215, 0.01552838]),
        "CLM-1-cal" => clm(3000.0, 13504.5),
        "CLM-2-cal" => clm(1000.0, 1167.833),
        "CLM-3-cal" => clm(2000.0, 1000.5),
        _ => unreachable!("canonical_name returns only listed names"),
    };
    Some(vec![model])
}
