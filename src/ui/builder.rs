//! What the scenario builder offers: for every model, a stage with its
//! parameters at typical values (the study's presets where it has one,
//! netem's usual figures otherwise), the values its choice fields take, and
//! which numbers are probabilities. The page turns each number into a
//! slider and each choice into a list; the TOML it writes goes through the
//! scenario parser like any file.

use crate::model::ModelKind;
use serde_json::{json, Value};

/// A stage of `kind` with typical parameters, as a scenario file writes it;
/// `None` for the stages that read a file (`trace`, `replay`): the page
/// cannot hand the server a file of the user's, so they are written by hand.
pub fn default_stage(kind: ModelKind) -> Option<Value> {
    Some(match kind {
        ModelKind::Bernoulli => json!({ "model": "bernoulli", "p": 0.1 }),
        ModelKind::GeLomax => json!({
            "model": "ge_lomax",
            "transition": [[0.95, 0.05], [0.1, 0.9]],
            "alpha": [4.604, 3.901],
            "lambda": [3.552, 1.466],
        }),
        ModelKind::Markov4 => json!({ "model": "markov4", "p13": 0.01, "p31": 0.3, "p32": 0.1, "p23": 0.05, "p14": 0.005 }),
        ModelKind::GilbertElliott => {
            json!({ "model": "gilbert_elliott", "p": 0.01, "r": 0.1, "loss_bad": 0.7, "loss_good": 0.001 })
        }
        ModelKind::Delay => json!({
            "model": "delay",
            "min_ms": 210.0,
            "dist": "hyperexp",
            "weights": [0.89258, 0.10742],
            "rates_per_ms": [0.01081, 0.01624],
            "order": "reorder",
        }),
        ModelKind::Outage => json!({
            "model": "outage", "p_start": 1.0, "unit": "time", "min_ms": 0.0, "max_ms": 1000.0, "cooldown_ms": 1000.0,
        }),
        ModelKind::Jitter => json!({
            "model": "jitter", "mean_ms": 100.0, "sd_ms": 20.0, "dist": "normal", "correlation": 0.25, "order": "reorder",
        }),
        ModelKind::Duplicate => json!({ "model": "duplicate", "p": 0.01 }),
        ModelKind::Corrupt => json!({ "model": "corrupt", "p": 0.01 }),
        ModelKind::Reorder => json!({ "model": "reorder", "p": 0.25, "gap": 5, "delay_ms": 10.0 }),
        ModelKind::Slot => json!({ "model": "slot", "min_ms": 2.0, "max_ms": 6.0, "packets": 8 }),
        ModelKind::Rate => json!({ "model": "rate", "rate_bit_s": 1_000_000, "queue_packets": 1000 }),
        ModelKind::LinkTrace | ModelKind::Replay => return None,
    })
}

/// The values a choice field of a stage takes, by field name.
pub fn choices() -> Value {
    json!({
        "dist": ["hyperexp", "uniform", "constant", "normal", "pareto", "paretonormal"],
        "order": ["reorder", "fifo"],
        "unit": ["time", "frames"],
    })
}

/// Fields whose numbers are probabilities (a slider over [0, 1]); every
/// entry of a transition matrix is one too.
pub const PROBABILITY_FIELDS: [&str; 15] = [
    "p", "p_start", "r", "h", "k", "loss_bad", "loss_good", "p13", "p31", "p32", "p23", "p14", "correlation", "transition",
    "weights",
];

/// Everything the builder page needs, as one JSON object: the models with
/// their default stages, the choices, the probability fields, the presets
/// (name and what it is) and the database's target kinds.
pub fn catalogue() -> Value {
    let models: Vec<Value> =
        ModelKind::ALL.iter().filter_map(|k| Some(json!({ "name": k.name(), "stage": default_stage(*k)? }))).collect();
    let presets: Vec<Value> = crate::scenario::PRESET_NAMES
        .iter()
        .map(|n| json!({ "name": n, "label": crate::scenario::preset_label(n).unwrap_or("") }))
        .collect();
    json!({
        "models": models,
        "choices": choices(),
        "probability_fields": PROBABILITY_FIELDS,
        "presets": presets,
        "targets": [
            { "field": "loss", "label": "packet loss (fraction)", "value": 0.05, "max": 0.5 },
            { "field": "delay_ms_mean", "label": "mean delay (ms)", "value": 150.0, "max": 500.0 },
            { "field": "outage", "label": "communication loss (fraction)", "value": 0.1, "max": 0.5 },
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every default stage is a valid scenario as the page would write it.
    #[test]
    fn every_default_stage_parses() {
        for k in ModelKind::ALL {
            let Some(stage) = default_stage(k) else { continue };
            let text = format!("name = \"t\"\n[[stage]]\n{}", toml::to_string(&stage).unwrap());
            crate::scenario::parse_str(&text, "<ui>", "t").unwrap_or_else(|e| panic!("{}: {e}", k.name()));
        }
    }
}
