//! A haptic force channel, robot → emulator → console over iceoryx2, built
//! into test builds only. It is the smallest whole reverse channel there
//! is, and the tests use it to show that a channel is this folder and one
//! line in the registry: its own sample type and ports, its flags (hidden:
//! `--haptic`, `--haptic-scenario`, `--haptic-seed`), its seed, its path
//! through a scenario of its own, and its section of the run report, with
//! nothing else in the crate naming it.
//!
//! The robot publishes one [`HapticSample`] per force reading on
//! `netfi/<run>/haptic` and ends with an end marker; the emulator passes
//! each through the haptic scenario (default `Normal`) and releases the
//! survivors on `netfi/<run>/haptic_out`.

use super::declare::{ChannelOpen, LaneShape, NoEndArgs, ReverseChannel, Sources, Want};
use crate::flags::{Argv, Render};
use crate::sample::Payload;
use crate::service::emulator::opening::{Opening, PathPlan};
use super::relay::{Relay, RelayExtra, Relayed};
use crate::service::emulator::path::Reverse;
use crate::service::link::Carried;
use crate::service::schema::PathReport;
use crate::transport::ipc::Iceoryx2;
use crate::transport::{Port, PublisherOpenError, Role, SubscriberOpenError};
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The path's name: its key in `emulator.json`'s paths.
pub const NAME: &str = "haptic";

/// Robot → emulator: the force readings.
pub const HAPTIC: Port = Port::new("haptic", Role::Simulator, Role::Emulator);
/// Emulator → console: the readings that survived the haptic scenario.
pub const HAPTIC_OUT: Port = Port::new("haptic_out", Role::Emulator, Role::Console);

/// One force reading of the robot's instrument, and the emulator's stamps.
/// All times are CLOCK_MONOTONIC ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("netfi::HapticSample.v1")]
#[repr(C)]
pub struct HapticSample {
    /// Robot send time.
    pub send_ns: u64,
    /// The robot's count of its readings; in an end marker, how many it sent.
    pub robot_index: u64,
    /// Assigned by the emulator when the reading enters it.
    pub ingress_index: u64,
    pub ingress_ns: u64,
    pub injected_delay_ns: u64,
    pub release_sched_ns: u64,
    pub release_ns: u64,
    /// Force per axis, mN.
    pub force_mn: [i32; 3],
    /// [`HapticSample::FLAG_END`], or zero.
    pub flags: u32,
}

impl HapticSample {
    /// Marks the end of the robot's readings.
    pub const FLAG_END: u32 = 1;

    /// The end marker after `sent` readings.
    pub fn end_marker(sent: u64) -> HapticSample {
        HapticSample { robot_index: sent, flags: HapticSample::FLAG_END, ..HapticSample::default() }
    }

    /// Whether this is the end marker.
    pub fn is_end(&self) -> bool {
        self.flags & HapticSample::FLAG_END != 0
    }
}

impl Payload for HapticSample {
    const ZERO: Self = HapticSample { send_ns: 0, robot_index: 0, ingress_index: 0, ingress_ns: 0, injected_delay_ns: 0, release_sched_ns: 0, release_ns: 0, force_mn: [0; 3], flags: 0 };
    const TYPE_NAME: &'static str = "netfi::HapticSample.v1";
}

impl Carried for HapticSample {
    fn ingress_ns(&self) -> u64 {
        self.ingress_ns
    }
}

impl Relayed for HapticSample {
    const NAME: &'static str = NAME;
    const TRACE_FILE: &'static str = "trace_haptic.csv";

    fn end_marker(sent: u64) -> HapticSample {
        HapticSample::end_marker(sent)
    }

    fn is_end(&self) -> bool {
        HapticSample::is_end(self)
    }

    fn sender_index(&self) -> u64 {
        self.robot_index
    }

    fn send_ns(&self) -> u64 {
        self.send_ns
    }

    fn taken(&mut self, ingress_index: u64, ingress_ns: u64) {
        (self.ingress_index, self.ingress_ns) = (ingress_index, ingress_ns);
    }

    fn released(&mut self, scheduled_ns: u64, release_ns: impl FnOnce() -> u64) -> u64 {
        (self.release_sched_ns, self.injected_delay_ns) = (scheduled_ns, scheduled_ns - self.ingress_ns);
        self.release_ns = release_ns();
        self.release_ns
    }
}

/// Its flags, hidden from help: the channel exists for tests.
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct HapticArgs {
    /// Carry the robot's force readings back to the console.
    #[arg(long, hide = true)]
    pub haptic: bool,
    /// Through this scenario (default Normal).
    #[arg(long, hide = true, value_name = "SCENARIO")]
    pub haptic_scenario: Option<String>,
    /// Its seed (default: derived from the run's).
    #[arg(long, hide = true)]
    pub haptic_seed: Option<u64>,
}

impl Render for HapticArgs {
    fn render(&self, a: &mut Argv) {
        a.switch("--haptic", self.haptic).opt("--haptic-scenario", self.haptic_scenario.as_ref()).opt("--haptic-seed", self.haptic_seed);
    }
}

/// The haptic flags that do not fit the lane.
#[derive(Debug, thiserror::Error)]
pub enum HapticArgsError {
    #[error("--haptic needs iceoryx2 on both sides")]
    NeedsIceoryx2,
}

/// Why its ports could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum HapticOpenError {
    #[error("opening the emulator → console haptic port: {0}")]
    Out(#[source] PublisherOpenError),
    #[error("opening the robot → emulator haptic port: {0}")]
    In(#[source] SubscriberOpenError),
}

/// The channel's section of the run report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HapticSection {
    pub scenario: String,
    pub seed: u64,
    pub sent_by_robot: Option<u64>,
    pub entered: u64,
    pub delivered: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    pub balanced: bool,
}

/// The haptic channel, declared.
pub struct Haptic;

impl ReverseChannel for Haptic {
    type Args = HapticArgs;
    type EndArgs = NoEndArgs;

    fn end_args(_args: &HapticArgs) -> NoEndArgs {
        NoEndArgs {}
    }

    type ArgsError = HapticArgsError;

    fn check(a: &HapticArgs, lane: &LaneShape) -> Result<(), HapticArgsError> {
        match a.haptic && !lane.both::<Iceoryx2>() {
            true => Err(HapticArgsError::NeedsIceoryx2),
            false => Ok(()),
        }
    }

    fn want(a: &HapticArgs, lane: &LaneShape) -> Option<Want> {
        (a.haptic && lane.both::<Iceoryx2>()).then(|| Want {
            name: NAME,
            flag: "--haptic-scenario",
            scenario: a.haptic_scenario.clone(),
            seed: a.haptic_seed,
            tag: u64::from_le_bytes(*b"haptic\0\0"),
            queue_capacity: crate::service::link::DEFAULT_QUEUE_CAPACITY,
        })
    }

    fn seed(a: &mut HapticArgs) -> &mut Option<u64> {
        &mut a.haptic_seed
    }

    type OpenError = HapticOpenError;

    fn open(_a: &HapticArgs, _want: &Want, plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<HapticOpenError>> {
        let node = o.sessions.iceoryx2.as_ref().expect("the haptic path is asked for with iceoryx2 on both sides");
        let sink = node.publisher_of::<HapticSample>(HAPTIC_OUT).map_err(|e| ChannelOpen::Own(HapticOpenError::Out(e)))?;
        let source = node.subscriber_of::<HapticSample>(HAPTIC).map_err(|e| ChannelOpen::Own(HapticOpenError::In(e)))?;
        Ok(Box::new(plan.open(Relay::new(source, sink), o.expected_frames, o.out_dir)?))
    }

    const PORTS: &'static [Port] = &[HAPTIC, HAPTIC_OUT];

    type Section = HapticSection;

    fn section(s: Sources) -> Option<HapticSection> {
        let p: PathReport<RelayExtra> = s.emulator?.path(NAME)?;
        let a = p.account;
        Some(HapticSection {
            scenario: p.scenario,
            seed: p.seed,
            sent_by_robot: p.extra.sent_by_robot,
            entered: a.entered,
            delivered: a.delivered,
            dropped: a.dropped,
            held_at_end: a.held_at_end,
            balanced: p.balanced,
        })
    }

    fn text(s: &HapticSection) -> String {
        format!(
            "haptic: scenario {} (seed {}): entered {}  delivered {}  dropped {}  held at end {}; {}\n",
            s.scenario,
            s.seed,
            s.entered,
            s.delivered,
            s.dropped.values().sum::<u64>(),
            s.held_at_end,
            if s.balanced { "balanced" } else { "NOT balanced" }
        )
    }

    fn faults(s: &HapticSection) -> Vec<String> {
        (!s.balanced).then(|| "haptic not balanced".to_string()).into_iter().collect()
    }
}
