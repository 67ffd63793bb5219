//! Scenario specifications: what a scenario file says, after validation.
//!
//! A [`ScenarioSpec`] is plain data (it can be printed back as TOML); a
//! [`super::Scenario`] is the runnable form with models and random streams.

use crate::model::{ModelKind, ModelSpec};
use serde::Serialize;

/// One stage of a pipeline.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageSpec {
    /// The stage's stream label, if the file gave one. Without it the label
    /// is `<model>#<n>`, n counting earlier stages of the same model in the
    /// same phase.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The preset this stage came from, if any (for reports).
    #[serde(skip)]
    pub preset: Option<String>,
    #[serde(flatten)]
    pub model: ModelSpec,
}

/// A pipeline active from `start_ms` (offset from the run's first frame).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhaseSpec {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    pub start_ms: f64,
    #[serde(rename = "stage")]
    pub stages: Vec<StageSpec>,
}

/// A whole scenario: one or more phases, in increasing start order, the
/// first starting at 0.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScenarioSpec {
    pub name: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The file's seed, used when the command line gives none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Release-queue capacity (frames held at once), if the file sets it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub queue_capacity: Option<usize>,
    #[serde(rename = "phase")]
    pub phases: Vec<PhaseSpec>,
}

impl StageSpec {
    /// Labels of the stages of one phase, as used to derive random streams.
    pub fn labels(stages: &[StageSpec]) -> Vec<String> {
        let mut counts = [0usize; ModelKind::ALL.len()];
        stages
            .iter()
            .map(|s| {
                let k = s.model.kind();
                let i = ModelKind::ALL.iter().position(|x| *x == k).expect("kind is listed");
                let n = counts[i];
                counts[i] += 1;
                s.name.clone().unwrap_or_else(|| format!("{}#{}", k.name(), n))
            })
            .collect()
    }
}

impl ScenarioSpec {
    /// A single-phase scenario.
    pub fn single(name: impl Into<String>, stages: Vec<StageSpec>) -> Self {
        ScenarioSpec {
            name: name.into(),
            description: None,
            seed: None,
            queue_capacity: None,
            phases: vec![PhaseSpec { name: None, start_ms: 0.0, stages }],
        }
    }

    /// The names of the files its stages read (link traces, recordings),
    /// every phase's, for the shell to rewrite (`load::resolve_anchored`).
    pub fn files_mut(&mut self) -> impl Iterator<Item = &mut String> {
        self.phases.iter_mut().flat_map(|p| p.stages.iter_mut()).filter_map(|s| s.model.file_mut())
    }

    /// The scenario as TOML, in the form the parser reads back: top-level
    /// `[[stage]]` tables for a single phase, `[[phase]]` tables otherwise.
    pub fn to_toml(&self) -> String {
        #[derive(Serialize)]
        struct Single<'a> {
            name: &'a str,
            #[serde(skip_serializing_if = "Option::is_none")]
            description: &'a Option<String>,
            #[serde(skip_serializing_if = "Option::is_none")]
            seed: Option<u64>,
            #[serde(skip_serializing_if = "Option::is_none")]
            queue_capacity: Option<usize>,
            stage: &'a [StageSpec],
        }
        let out = match self.phases.as_slice() {
            [only] if only.start_ms == 0.0 && only.name.is_none() => toml::to_string(&Single {
                name: &self.name,
                description: &self.description,
                seed: self.seed,
                queue_capacity: self.queue_capacity,
                stage: &only.stages,
            }),
            _ => toml::to_string(self),
        };
        out.expect("a scenario spec always serializes")
    }
}
