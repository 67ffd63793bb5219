//! The study's presets (SPEC §4), with the parameters its code ran.
//!
//! Each preset is a list of stage specifications. `Normal` is the empty list.
//! Names match case-insensitively and with or without the dash (`PLM-2`,
//! `plm2`).

use super::spec::{ModelSpec, StageSpec};
use crate::model::{
    DelayDist, DelayParams, GeLomaxParams, Millis, Order, OutageParams, OutageUnit, Probability,
};

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

const STUDY_TRANSITION: [[f64; 2]; 2] = [[0.95, 0.05], [0.10, 0.90]];

fn plm(alpha: [f64; 2], lambda: [f64; 2]) -> ModelSpec {
    ModelSpec::GeLomax(GeLomaxParams {
        transition: STUDY_TRANSITION.iter().map(|r| r.to_vec()).collect(),
        alpha: alpha.to_vec(),
        lambda: lambda.to_vec(),
    })
}

fn dlm(min_ms: f64, weights: [f64; 2], rates_per_ms: [f64; 2]) -> ModelSpec {
    ModelSpec::Delay(DelayParams {
        min_ms: Millis::new(min_ms).expect("preset constant"),
        dist: DelayDist::Hyperexp,
        weights: Some(weights.to_vec()),
        rates_per_ms: Some(rates_per_ms.to_vec()),
        jitter_ms: None,
        order: Order::Reorder,
    })
}

fn clm(max_ms: f64, cooldown_ms: f64) -> ModelSpec {
    ModelSpec::Outage(OutageParams {
        p_start: Probability::new(1.0).expect("preset constant"),
        unit: OutageUnit::Time,
        min_ms: Some(Millis::new(0.0).expect("preset constant")),
        max_ms: Some(Millis::new(max_ms).expect("preset constant")),
        cooldown_ms: Some(Millis::new(cooldown_ms).expect("preset constant")),
        min_frames: None,
        max_frames: None,
        cooldown_frames: None,
    })
}

/// The stage specifications of a preset, or `None` if `name` is not one.
/// Stages carry no explicit name: they get the default label of their kind.
pub fn preset_stages(name: &str) -> Option<Vec<StageSpec>> {
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
    Some(vec![StageSpec { name: None, preset: Some(canonical.to_string()), model }])
}
