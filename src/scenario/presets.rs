//! The study's presets (SPEC §4), with the parameters its code ran.
//!
//! Each preset is a list of stage specifications. `Normal` is the empty list.
//! Names match case-insensitively and with or without the dash (`PLM-2`,
//! `plm2`).

use super::spec::{ModelSpec, StageSpec};
use crate::model::{
    DelayDist, DelayParams, GeLomaxParams, Millis, Order, OutageParams, OutageUnit, Probability,
};

/// The preset names, in the order the study lists them.
pub const PRESET_NAMES: [&str; 10] = [
    "Normal", "PLM-1", "PLM-2", "PLM-3", "DLM-1", "DLM-2", "DLM-3", "CLM-1", "CLM-2", "CLM-3",
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
        _ => unreachable!("canonical_name returns only listed names"),
    };
    Some(vec![StageSpec { name: None, preset: Some(canonical.to_string()), model }])
}
