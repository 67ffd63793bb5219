//! The study's presets as scenario stages. Their parameters live in
//! [`crate::model::presets`] (docs/spec.md §4), where `fit` reads them too.

use super::spec::StageSpec;
use crate::model::presets::{canonical_name, preset_models};

/// The stage specifications of a preset, or `None` if `name` is not one.
/// Stages carry no explicit name: they get the default label of their kind.
pub fn preset_stages(name: &str) -> Option<Vec<StageSpec>> {
    let canonical = canonical_name(name)?;
    let models = preset_models(canonical)?;
    Some(
        models
            .into_iter()
            .map(|model| StageSpec { name: None, preset: Some(canonical.to_string()), model })
            .collect(),
    )
}
