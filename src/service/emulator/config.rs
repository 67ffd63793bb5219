//! What the emulator runs, resolved once from its arguments: each lane's
//! own arguments, scenario, seed and queue; where the loop runs; its live
//! control. Nothing after this reads the arguments' defaults again.
//!
//! Started by `netfi run`, the emulator is given every seed (`--seed`,
//! `--return-seed`, `--video-seed`) and the run's own copy of each
//! scenario, and uses them as given; alone, it applies the same rules
//! ([`crate::service::seeds`]) to what it was given.

use crate::model::ModelKind;
use crate::scenario::ScenarioSpec;
use crate::service::args::{EmulatorArgs, ScenarioArgs, StreamArgs};
use crate::service::args::streams;
use crate::service::seeds;
use crate::scenario::ScenarioError;
use crate::service::args::ArgsError;
use crate::transport::{IpcConfig, RunId, RunIdError};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Why the emulator's arguments make no emulator.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error(transparent)]
    Args(#[from] ArgsError),
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    RunId(#[from] RunIdError),
    #[error("--queue-capacity must be at least 1 frame")]
    QueueCapacity,
    #[error("--streams needs --run-id")]
    StreamsNeedRunId,
    /// What went wrong with stream `stream`'s own arguments.
    #[error("stream {stream}: {cause}")]
    Stream { stream: usize, cause: Box<ConfigError> },
}

/// One lane as resolved.
#[derive(Debug, Clone)]
pub struct LaneConfig {
    /// The lane's own arguments: its run id, seed and directory (the
    /// reverse paths read their flags here).
    pub args: EmulatorArgs,
    pub scenario: ScenarioSpec,
    pub seed: u64,
    pub queue_capacity: usize,
    /// Where its trace, histograms and report go.
    pub out_dir: PathBuf,
}

impl LaneConfig {
    /// Whether a sample with an opaque payload may come (UDP raw payloads).
    pub fn accept_raw(&self) -> bool {
        self.args.transports.opaque(&self.args.ends.ingress, &self.args.ends.egress)
    }

    /// The stages this lane's frames cannot go through, beyond those its
    /// channel refuses: what its transports cannot apply.
    pub fn unsupported(&self) -> &'static [ModelKind] {
        self.args.transports.unsupported(&self.args.ends.ingress, &self.args.ends.egress)
    }
}

/// The emulator as resolved.
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    pub lanes: Vec<LaneConfig>,
    /// Core to pin the loop to (`None`: not pinned).
    pub core: Option<usize>,
    /// Run the loop at this SCHED_FIFO priority (needs root or CAP_SYS_NICE).
    pub rt_priority: Option<i32>,
    /// Clear the loop's core of other processes' threads, movable kernel
    /// threads and device interrupts for the run.
    pub isolate: bool,
    /// Serve live control (and telemetry, every `telemetry_ms`; 0: none)
    /// on lane 0.
    pub control: Option<(IpcConfig, u64)>,
    /// Use the reordering release queue whatever the scenario.
    pub reorder_queue: bool,
    /// Where the run's own files go (the joint report of several lanes).
    pub out_dir: PathBuf,
}

/// Lane `k`'s own arguments: its run id, scenario, seed and directory.
fn lane_args(args: &EmulatorArgs, scenarios: &BTreeMap<usize, String>, seed: u64, k: usize) -> EmulatorArgs {
    let n = args.stream.streams as usize;
    let mut lane = EmulatorArgs {
        run_id: args.run_id.as_deref().map(|r| streams::run_id(r, k)),
        scenario: ScenarioArgs {
            scenario: scenarios.get(&k).unwrap_or(&args.scenario.scenario).clone(),
            seed: Some(seeds::stream(seed, k)),
            queue_capacity: args.scenario.queue_capacity,
        },
        out: streams::dir(&args.out, n, k),
        stream: StreamArgs::default(),
        ..args.clone()
    };
    lane.channels.map_seeds(|s| seeds::stream(s, k));
    lane
}

/// The lane of `args` (already its own).
fn lane(args: EmulatorArgs) -> Result<LaneConfig, ConfigError> {
    let scenario = crate::load::resolve(&args.scenario.scenario)?;
    let seed = seeds::run(args.scenario.seed, &scenario);
    let default_capacity = args.transports.default_queue_capacity(&args.ends.ingress, &args.ends.egress).unwrap_or(crate::service::link::DEFAULT_QUEUE_CAPACITY);
    let queue_capacity = args.scenario.queue_capacity.or(scenario.queue_capacity).unwrap_or(default_capacity);
    if queue_capacity < 1 {
        return Err(ConfigError::QueueCapacity);
    }
    Ok(LaneConfig { out_dir: args.out.clone(), scenario, seed, queue_capacity, args })
}

impl EmulatorConfig {
    /// The emulator of `lanes`, placed and controlled as `args` say.
    pub(crate) fn with_lanes(args: &EmulatorArgs, lanes: Vec<LaneConfig>) -> Result<EmulatorConfig, ConfigError> {
        let core = match args.placement.no_pin {
            true => None,
            false => args.placement.core.or_else(|| core_affinity::get_core_ids().and_then(|c| c.last().map(|c| c.id))),
        };
        let control = match (&args.run_id, args.control.no_control) {
            (Some(run), false) => Some((IpcConfig::new(RunId::new(run)?), args.control.telemetry_ms)),
            _ => None,
        };
        // A run under live control may be switched to any scenario, one
        // that reorders included: its queue keeps release-time order from
        // the start (within noise of the FIFO ring, docs/performance.md
        // "The reordering queue under control").
        let reorder_queue = args.control.reorder_queue || (control.is_some() && !args.control.fifo_queue);
        Ok(EmulatorConfig {
            lanes,
            core,
            rt_priority: args.placement.rt_priority,
            isolate: args.placement.isolate,
            control,
            reorder_queue,
            out_dir: args.out.clone(),
        })
    }

    /// The emulator that `args` ask for (checked).
    pub fn of(args: &EmulatorArgs) -> Result<EmulatorConfig, ConfigError> {
        args.validate()?;
        // Before any port opens: a core it cannot be pinned to leaves
        // nothing behind. The host's online cores, not this process's mask:
        // a runner started it with the mask the runner keeps off that core.
        if !args.placement.no_pin {
            let online: Vec<usize> = crate::host::affinity::online_cpus().into_iter().collect();
            crate::service::args::check_core("--core", args.placement.core, &online)?;
        }
        let lanes = if args.stream.several() {
            if args.run_id.is_none() {
                return Err(ConfigError::StreamsNeedRunId);
            }
            let scenarios = args.stream.named_scenarios()?;
            let seed = lane(args.clone())?.seed;
            (0..args.stream.streams as usize)
                .map(|k| lane(lane_args(args, &scenarios, seed, k)).map_err(|cause| ConfigError::Stream { stream: k, cause: Box::new(cause) }))
                .collect::<Result<Vec<_>, _>>()?
        } else {
            vec![lane(args.clone())?]
        };
        Self::with_lanes(args, lanes)
    }

    /// Whether the emulator serves several lanes (streams).
    pub fn several(&self) -> bool {
        self.lanes.len() > 1
    }
}
