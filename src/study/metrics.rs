//! A trial's figures, one row per trial: what the participant did (time,
//! motion, clutch) and what the network did to it (loss, delay, outages),
//! taken from the trial's run report and its per-frame trace.
//!
//! Pure: the report comes in as JSON and the trace as rows; reading the
//! files is the shell's ([`super::trials`]). Every figure is the run
//! report's own (exact, or with the precision the report states: its delay
//! percentiles come from a histogram at most 2^-10 above the exact value),
//! or counted here exactly from the trace.

use serde_json::Value;

/// One figure of a trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Metric {
    /// Its column name (unit last).
    pub name: &'static str,
    /// What it is, for the report's tables and plots.
    pub label: &'static str,
    /// Where it comes from, for the documentation.
    pub source: &'static str,
}

/// The columns of the study's table that come before the metrics
/// (attributes come between them and the metrics).
pub const FIXED_COLUMNS: [&str; 13] = [
    "participant",
    "trial",
    "attempt",
    "outcome",
    "block",
    "block_position",
    "condition",
    "repetition",
    "seed",
    "stopped",
    "started_utc",
    "trial_dir",
    "note",
];

macro_rules! metric {
    ($name:literal, $label:literal, $source:literal) => {
        Metric { name: $name, label: $label, source: $source }
    };
}

/// Every metric, in the order of the table's columns.
pub const METRICS: [Metric; 23] = [
    metric!("duration_s", "Trial duration (s)", "console.duration_s: the console's streaming time"),
    metric!("console_motion_arm0_mm", "Console motion, arm 0 (mm)", "kinematics.console.length_mm[0]"),
    metric!("console_motion_arm1_mm", "Console motion, arm 1 (mm)", "kinematics.console.length_mm[1]"),
    metric!("robot_motion_arm0_mm", "Robot motion, arm 0 (mm)", "kinematics.robot.length_mm[0]"),
    metric!("robot_motion_arm1_mm", "Robot motion, arm 1 (mm)", "kinematics.robot.length_mm[1]"),
    metric!("clutch_activations", "Clutch activations (console)", "kinematics.console.clutch_activations"),
    metric!("robot_clutch_activations", "Clutch activations seen by the robot", "kinematics.robot.clutch_activations"),
    metric!("robot_stalls", "Robot stalls", "kinematics.robot.stalls.count"),
    metric!("robot_stall_longest_ms", "Longest robot stall (ms)", "kinematics.robot.stalls.longest_ns"),
    metric!("robot_stall_total_ms", "Robot stalled, total (ms)", "kinematics.robot.stalls.total_ns"),
    metric!("divergence_max_arm0_mm", "Largest console-robot divergence, arm 0 (mm)", "kinematics.divergence[0].max_mm"),
    metric!("divergence_max_arm1_mm", "Largest console-robot divergence, arm 1 (mm)", "kinematics.divergence[1].max_mm"),
    metric!("divergence_final_arm0_mm", "Final divergence, arm 0 (mm)", "kinematics.divergence[0].final_mm"),
    metric!("divergence_final_arm1_mm", "Final divergence, arm 1 (mm)", "kinematics.divergence[1].final_mm"),
    metric!("frames_sent", "Frames sent", "frames.sent"),
    metric!("frames_received", "Frames received by the robot", "frames.received"),
    metric!("loss_rate", "Realized loss rate", "loss_rate: dropped / entered"),
    metric!("delay_mean_ms", "Injected delay, mean (ms)", "injected_delay_ns.mean"),
    metric!("delay_p50_ms", "Injected delay, median (ms)", "injected_delay_ns.p50 (histogram, at most 2^-10 above)"),
    metric!("delay_p99_ms", "Injected delay, 99th percentile (ms)", "injected_delay_ns.p99 (histogram, at most 2^-10 above)"),
    metric!("outages", "Outages (runs of frames an outage dropped)", "trace.csv: maximal runs of consecutive frames dropped by `outage`"),
    metric!("outage_mean_ms", "Outage, mean length (ms)", "trace.csv: first dropped frame's ingress to the next frame's"),
    metric!("outage_longest_ms", "Outage, longest (ms)", "trace.csv: as outage_mean_ms"),
];

/// The index of the metric `name` in [`METRICS`].
pub fn metric_index(name: &str) -> Option<usize> {
    METRICS.iter().position(|m| m.name == name)
}

/// A trial's figures, in [`METRICS`]' order; `None` where the run did not
/// give one (no kinematics without the direct copy, no delay without
/// delivered frames).
pub type Figures = Vec<Option<f64>>;

/// The realized outages of a trial, counted from its trace.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Outages {
    /// Maximal runs of consecutive frames (by ingress index) dropped by an
    /// `outage` stage.
    pub count: u64,
    /// Their mean length, ms: from the ingress of a run's first frame to
    /// that of the frame after it (or of its own last frame, for a run
    /// that lasts to the end).
    pub mean_ms: Option<f64>,
    pub longest_ms: Option<f64>,
}

/// A frame's row of the trace, as far as outages need it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TraceFrame {
    pub ingress_index: u64,
    pub ingress_ns: u64,
    /// Dropped by an `outage` stage.
    pub outage: bool,
}

/// The outages of frames given in any order (copies left out by the caller).
pub fn outages(mut frames: Vec<TraceFrame>) -> Outages {
    frames.sort_unstable_by_key(|f| f.ingress_index);
    let mut lengths_ns: Vec<u64> = Vec::new();
    let mut open: Option<u64> = None;
    let mut last_ns = 0;
    for f in &frames {
        match (open, f.outage) {
            (None, true) => open = Some(f.ingress_ns),
            (Some(start), false) => {
                lengths_ns.push(f.ingress_ns.saturating_sub(start));
                open = None;
            }
            _ => {}
        }
        last_ns = f.ingress_ns;
    }
    if let Some(start) = open {
        lengths_ns.push(last_ns.saturating_sub(start));
    }
    let count = lengths_ns.len() as u64;
    let ms = |ns: u64| ns as f64 / 1e6;
    Outages {
        count,
        mean_ms: (count > 0).then(|| lengths_ns.iter().map(|&l| ms(l)).sum::<f64>() / count as f64),
        longest_ms: lengths_ns.iter().max().map(|&l| ms(l)),
    }
}

/// The figures of a trial from its run report (`report.json` as JSON) and
/// its outages.
pub fn figures(report: &Value, outages: &Outages) -> Figures {
    let f = |ptr: &str| report.pointer(ptr).and_then(Value::as_f64);
    let ns_ms = |ptr: &str| f(ptr).map(|ns| ns / 1e6);
    let values = [
        f("/console/duration_s").or_else(|| f("/duration_s")),
        f("/kinematics/console/length_mm/0"),
        f("/kinematics/console/length_mm/1"),
        f("/kinematics/robot/length_mm/0"),
        f("/kinematics/robot/length_mm/1"),
        f("/kinematics/console/clutch_activations"),
        f("/kinematics/robot/clutch_activations"),
        f("/kinematics/robot/stalls/count"),
        ns_ms("/kinematics/robot/stalls/longest_ns"),
        ns_ms("/kinematics/robot/stalls/total_ns"),
        f("/kinematics/divergence/0/max_mm"),
        f("/kinematics/divergence/1/max_mm"),
        f("/kinematics/divergence/0/final_mm"),
        f("/kinematics/divergence/1/final_mm"),
        f("/frames/sent"),
        f("/frames/received"),
        f("/loss_rate"),
        ns_ms("/injected_delay_ns/mean"),
        ns_ms("/injected_delay_ns/p50"),
        ns_ms("/injected_delay_ns/p99"),
        Some(outages.count as f64),
        outages.mean_ms,
        outages.longest_ms,
    ];
    debug_assert_eq!(values.len(), METRICS.len());
    values.to_vec()
}
