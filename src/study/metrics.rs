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
pub const FIXED_COLUMNS: [&str; 15] = [
    "participant",
    "trial",
    "attempt",
    "outcome",
    "clean",
    "suspect_because",
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
pub const METRICS: [Metric; 29] = [
    metric!("duration_s", "Trial duration (s)", "console.duration_s: netfi's console's streaming time; with the lab's console, the run's: start to stop"),
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
    metric!("command_span_s", "First to last command (s)", "trace.csv: the first frame's ingress to the last's"),
    metric!("netfi_added_p99_ms", "Delay netfi added, p99 (ms)", "overhead_ns.added_over_direct.p99 (netfi's own ends); with the lab's, ingress_wait + decision + release_lateness p99s (an upper bound)"),
    metric!("release_lateness_p99_ms", "Release lateness, p99 (ms)", "overhead_ns.release_lateness.p99"),
    metric!("steal_fraction", "CPU time stolen from the host", "steal.fraction"),
    metric!("lost_before_emulator", "Frames lost before the emulator", "frames.lost_before_emulator; UDP: ingress_kernel_drops; ROS 2: lost_before_ingress"),
    metric!("released_to_no_robot", "Frames released while no robot listened", "emulator.frames.delivered_unsubscribed"),
];

/// The figures of [`METRICS`] that say whether netfi and the host kept
/// out of the trial's way (`[clean]`).
pub const CLEAN_FIGURES: [&str; 4] = ["netfi_added_p99_ms", "steal_fraction", "lost_before_emulator", "released_to_no_robot"];

/// Why a trial with `figures` is suspect under `rule` (empty: clean).
pub fn suspect_because(figures: &Figures, rule: &crate::study::file::CleanRule) -> Vec<String> {
    let f = |name: &str| metric_index(name).and_then(|i| figures.get(i).copied().flatten());
    let mut why = Vec::new();
    if let Some(v) = f("netfi_added_p99_ms").filter(|v| *v > rule.netfi_added_p99_ms) {
        why.push(format!("netfi added {v:.3} ms at p99 (more than {} ms)", rule.netfi_added_p99_ms));
    }
    if let Some(v) = f("steal_fraction").filter(|v| *v > rule.steal_fraction) {
        why.push(format!("the host stole {:.1} % of the CPU time (more than {:.1} %)", v * 100.0, rule.steal_fraction * 100.0));
    }
    if let Some(v) = f("lost_before_emulator").filter(|v| *v > 0.0) {
        why.push(format!("{v} frames lost before the emulator"));
    }
    if let Some(v) = f("released_to_no_robot").filter(|v| *v > 0.0) {
        why.push(format!("{v} frames released before the robot listened"));
    }
    why
}

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

/// What a trial's trace gives besides its run report: the outages, and
/// the first and last frames' ingress, ns.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TraceFigures {
    pub outages: Outages,
    pub first_to_last_s: Option<f64>,
}

impl TraceFigures {
    /// Of frames given in any order (copies left out by the caller).
    pub fn of(frames: Vec<TraceFrame>) -> TraceFigures {
        let first = frames.iter().map(|f| f.ingress_ns).min();
        let last = frames.iter().map(|f| f.ingress_ns).max();
        let first_to_last_s = first.zip(last).map(|(a, b)| (b - a) as f64 / 1e9);
        TraceFigures { outages: outages(frames), first_to_last_s }
    }
}

/// The motion of a ROS 2 run's lanes (`ros2.json`'s `forward.motion`, lane
/// by lane: lane k is arm k), in the ITP report's shape where it has a
/// length in metres (PoseStamped, TransformStamped): `kinematics`' mm
/// figures. JointState's joint units are no length in mm: left out.
pub fn ros2_kinematics(lanes: &[Value]) -> Option<Value> {
    let motions: Vec<&Value> = lanes.iter().filter_map(|l| l.pointer("/forward/motion").filter(|m| m.get("unit") == Some(&Value::from("m")))).collect();
    if motions.is_empty() {
        return None;
    }
    let mm = |m: &Value, ptr: &str| m.pointer(ptr).and_then(Value::as_f64).map(|v| v * 1e3);
    let arm = |k: usize, ptr: &str| motions.get(k).and_then(|m| mm(m, ptr));
    let stalls = |key: &str, max: bool| {
        let v = motions.iter().filter_map(|m| m.pointer(&format!("/robot/stalls/{key}")).and_then(Value::as_u64));
        if max { v.max() } else { Some(v.sum()) }
    };
    Some(serde_json::json!({
        "console": { "length_mm": [arm(0, "/console/length"), arm(1, "/console/length")] },
        "robot": {
            "length_mm": [arm(0, "/robot/length"), arm(1, "/robot/length")],
            "stalls": { "count": stalls("count", false), "longest_ns": stalls("longest_ns", true), "total_ns": stalls("total_ns", false) },
        },
        "divergence": [
            { "max_mm": arm(0, "/divergence_max"), "final_mm": arm(0, "/divergence_final") },
            { "max_mm": arm(1, "/divergence_max"), "final_mm": arm(1, "/divergence_final") },
        ],
    }))
}

/// The figures of a trial from its run report (`report.json` as JSON),
/// its trace's figures, and, for ROS 2 lanes, their `ros2.json`s.
pub fn figures(report: &Value, trace: &TraceFigures, ros2: &[Value]) -> Figures {
    let outages = &trace.outages;
    let f = |ptr: &str| report.pointer(ptr).and_then(Value::as_f64);
    let ns_ms = |ptr: &str| f(ptr).map(|ns| ns / 1e6);
    let ros2_kin = ros2_kinematics(ros2);
    let k = |ptr: &str| f(&format!("/kinematics{ptr}")).or_else(|| ros2_kin.as_ref().and_then(|k| k.pointer(ptr)).and_then(Value::as_f64));
    let k_ms = |ptr: &str| k(ptr).map(|ns| ns / 1e6);
    let p99 = |what: &str| f(&format!("/overhead_ns/{what}/p99"));
    // netfi's own added delay: over the direct hop measured in the same
    // run where netfi plays both ends; with the lab's ends no direct hop
    // exists, and the emulator's own three parts bound it from above.
    let netfi_added_ns = f("/overhead_ns/added_over_direct/p99").or_else(|| {
        let parts = [p99("ingress_wait"), p99("decision"), p99("release_lateness")];
        parts.iter().all(Option::is_some).then(|| parts.iter().flatten().sum())
    });
    let lost = f("/frames/lost_before_emulator")
        .or_else(|| f("/transports/udp/ingress_kernel_drops"))
        .or_else(|| (!ros2.is_empty()).then(|| ros2.iter().filter_map(|l| l.pointer("/forward/lost_before_ingress").and_then(Value::as_f64)).sum()));
    let values = [
        f("/console/duration_s").or_else(|| f("/duration_s")),
        k("/console/length_mm/0"),
        k("/console/length_mm/1"),
        k("/robot/length_mm/0"),
        k("/robot/length_mm/1"),
        k("/console/clutch_activations"),
        k("/robot/clutch_activations"),
        k("/robot/stalls/count"),
        k_ms("/robot/stalls/longest_ns"),
        k_ms("/robot/stalls/total_ns"),
        k("/divergence/0/max_mm"),
        k("/divergence/1/max_mm"),
        k("/divergence/0/final_mm"),
        k("/divergence/1/final_mm"),
        f("/frames/sent"),
        f("/frames/received"),
        f("/loss_rate"),
        ns_ms("/injected_delay_ns/mean"),
        ns_ms("/injected_delay_ns/p50"),
        ns_ms("/injected_delay_ns/p99"),
        Some(outages.count as f64),
        outages.mean_ms,
        outages.longest_ms,
        trace.first_to_last_s,
        netfi_added_ns.map(|ns| ns / 1e6),
        ns_ms("/overhead_ns/release_lateness/p99"),
        f("/steal/fraction"),
        lost,
        f("/emulator/frames/delivered_unsubscribed"),
    ];
    debug_assert_eq!(values.len(), METRICS.len());
    values.to_vec()
}
