//! A study file as TOML gives it, before any check: every value with its
//! span, so an error can name its line.

use serde::Deserialize;
use toml::Spanned;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Raw {
    pub(super) name: Option<String>,
    pub(super) description: Option<String>,
    pub(super) seed: Option<Spanned<i64>>,
    pub(super) data: Option<String>,
    pub(super) trials: Option<Spanned<i64>>,
    pub(super) baseline: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) hide_condition: bool,
    pub(super) trial: Option<RawTrial>,
    pub(super) order: Option<RawOrder>,
    pub(super) questionnaires: Option<RawQuestionnaires>,
    #[serde(default)]
    pub(super) condition: Vec<Spanned<RawCondition>>,
    #[serde(default)]
    pub(super) block: Vec<Spanned<RawBlock>>,
    #[serde(default)]
    pub(super) participant: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    pub(super) measure: Vec<Spanned<RawMeasure>>,
    pub(super) clean: Option<RawClean>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawClean {
    pub(super) netfi_added_p99_ms: Option<Spanned<f64>>,
    pub(super) steal_fraction: Option<Spanned<f64>>,
}

/// A time as a file writes it: a number in the field's unit, or text with
/// its own (`"10min"`, `"90 s"`), as scenario files take times.
#[derive(Deserialize)]
#[serde(untagged)]
pub(super) enum TimeValue {
    Number(f64),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawMeasure {
    pub(super) name: Spanned<String>,
    pub(super) label: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTrial {
    pub(super) duration_s: Option<Spanned<TimeValue>>,
    pub(super) capture: Option<String>,
    pub(super) rate_hz: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) run_args: Vec<Spanned<String>>,
    pub(super) peers: Option<Spanned<String>>,
    pub(super) peer_wait_s: Option<Spanned<f64>>,
    pub(super) lab: Option<Spanned<toml::Table>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOrder {
    pub(super) blocks: Option<Spanned<String>>,
    pub(super) within: Option<Spanned<String>>,
    pub(super) first: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawQuestionnaires {
    pub(super) sus: Option<Spanned<String>>,
    pub(super) tlx: Option<Spanned<String>>,
    pub(super) tlx_weighting: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCondition {
    pub(super) name: Spanned<String>,
    pub(super) scenario: Option<Spanned<String>>,
    pub(super) stage: Option<Vec<toml::Table>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBlock {
    pub(super) name: Spanned<String>,
    pub(super) conditions: Spanned<Vec<Spanned<String>>>,
    pub(super) trials: Option<Spanned<i64>>,
}
