//! What `netfi ctl` and the control service say to each other (JSON), and
//! the control events a run's report lists.

use crate::scenario::{parse_str, preset, ScenarioError, ScenarioSpec, PRESET_NAMES};
use serde::{Deserialize, Serialize};


/// One control action, as the run report lists it (`events`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlEvent {
    /// When it took effect, seconds from the run's first frame (the clock of
    /// the phases and of `--at`).
    pub t_s: f64,
    /// What was done, in words.
    pub what: String,
    /// The same time in ns, exactly (absent in reports of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_ns: Option<u64>,
    /// What was done, exactly enough to rebuild the run's timeline from
    /// its scenario and its events (absent in reports of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action: Option<Action>,
}

/// A control action as the loop applied it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Action {
    /// The rest of the run's timeline replaced, from the event's time, by
    /// `scenario` (as TOML) from its phase `from_phase` on; its first
    /// phase became the run's phase `run_phase` (both from 1).
    Switch { scenario: String, from_phase: usize, run_phase: usize },
    Pause,
    Resume,
}

/// A request to the control service (JSON, tagged by `cmd`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Request {
    /// The current scenario, phase and pause.
    Show,
    /// Switch to a scenario from `at_ms` (from the run's first frame), or now.
    Switch {
        scenario: Target,
        #[serde(default)]
        at_ms: Option<f64>,
    },
    /// Go to a phase (number from 1, or name) of the current scenario.
    Phase {
        phase: String,
        #[serde(default)]
        at_ms: Option<f64>,
    },
    /// Every frame passes untouched until `resume`.
    Pause,
    Resume,
}

/// What to switch to: a preset's name, or scenario text (a file's
/// contents, or a target stage such as `[[stage]]\nloss = "30%"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Target {
    Preset(String),
    Toml { text: String, origin: String, name: String },
}

/// The answer: `ok` with a message and the state, or the error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Response {
    pub ok: bool,
    #[serde(default)]
    pub message: String,
    #[serde(default)]
    pub state: Option<State>,
}

/// What `show` prints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// Seconds since the run's first frame (0 before it).
    pub t_s: f64,
    /// Whether a frame has entered yet.
    pub started: bool,
    pub frames_entered: u64,
    pub paused: bool,
    /// The phase running, in the run's timeline (from 1).
    pub phase: usize,
    /// The scenario it comes from, and its phase there (from 1, and name).
    pub scenario: String,
    pub scenario_phase: usize,
    pub phase_name: Option<String>,
    /// The phases still to come: `(t_s, scenario, phase from 1)`.
    pub upcoming: Vec<(f64, String, usize)>,
    /// `fifo` or `reorder`: a FIFO run cannot switch to a reordering scenario.
    pub queue_order: String,
    /// The phases of the scenario running, each as `netfi ctl phase` names
    /// it (absent from older emulators' answers).
    #[serde(default)]
    pub scenario_phases: Vec<PhaseOf>,
}

/// One phase of a scenario: its number (from 1), its name, and its start
/// in the scenario (s).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseOf {
    pub number: usize,
    pub name: Option<String>,
    pub start_s: f64,
}

impl ControlEvent {
    /// When it took effect, ns from the run's first frame: exact where the
    /// event says, else from its seconds.
    pub fn at_ns(&self) -> u64 {
        self.t_ns.unwrap_or_else(|| (self.t_s * 1e9).round() as u64)
    }
}

/// The scenario a request names, with the scenario parser's errors.
pub fn resolve(t: &Target) -> Result<ScenarioSpec, ScenarioError> {
    match t {
        Target::Preset(name) => preset(name).ok_or_else(|| ScenarioError {
            origin: name.clone(),
            line: None,
            location: None,
            field: None,
            problem: format!("not a preset (presets: {})", PRESET_NAMES.join(", ")),
        }),
        Target::Toml { text, origin, name } => parse_str(text, origin, name),
    }
}

