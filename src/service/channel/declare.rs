//! What a reverse channel declares ([`ReverseChannel`]), and the macro that
//! makes the registry's values from the list of channels
//! ([`channels!`]): the flags of every channel
//! ([`ChannelArgs`](super::ChannelArgs)) and what netfi's own console and
//! robot take of them ([`ChannelEndArgs`](super::ChannelEndArgs)), the
//! reverse paths a lane has (each with its seed's rule), the opening of
//! each, and each one's section of the run report
//! ([`ChannelSections`](super::ChannelSections)). The runner, the plan, the
//! seeds, the argument rendering and the emulator iterate the same list,
//! keyed by the channel's name.

use crate::flags::Render;
use crate::service::emulator::opening::{OpenError, Opening, PathPlan};
use crate::service::emulator::path::Reverse;
use crate::service::schema::{EmulatorProcess, WithPaths};
use crate::transport::Port;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::fmt;

pub use crate::service::emulator::opening::LaneShape;

/// A reverse path a lane has, as its channel asks for it: its name (its
/// key in `emulator.json`'s paths, and its trace file's), the flag that
/// names its scenario (for messages), the scenario and seed given, the tag
/// its seed is derived with when not given, and its default queue.
#[derive(Debug, Clone, PartialEq)]
pub struct Want {
    pub name: &'static str,
    pub flag: &'static str,
    /// The scenario (file or preset); `None`: Normal, nothing injected.
    pub scenario: Option<String>,
    /// The seed given (`None`: the file's, else derived from the lane's).
    pub seed: Option<u64>,
    pub tag: u64,
    pub queue_capacity: usize,
}

impl Want {
    /// Its scenario, seed and queue on a lane seeded `lane_seed`.
    pub fn plan(&self, lane_seed: u64) -> Result<PathPlan, OpenError> {
        PathPlan::resolve(self.flag, self.scenario.as_deref(), self.seed, lane_seed, self.tag, self.queue_capacity)
    }
}

/// What a run report's section of a channel is joined from: the
/// services' reports (the console's and the robot's as written: each
/// channel reads the part it writes there), and whether the run was
/// stopped (what was in flight at the stop is counted as such).
#[derive(Clone, Copy)]
pub struct Sources<'a> {
    /// The emulator's report less its shaping: the process and its paths.
    pub emulator: Option<&'a WithPaths<EmulatorProcess>>,
    /// `console.json`, where the run has it.
    pub console: Option<&'a serde_json::Value>,
    /// `simulator.json`, where the run has it.
    pub simulator: Option<&'a serde_json::Value>,
    pub stopped: bool,
}

impl Sources<'_> {
    /// The console's report's `key`, as a `T`, where it has one.
    pub fn console_part<T: DeserializeOwned>(&self, key: &str) -> Option<T> {
        part(self.console, key)
    }

    /// The robot's report's `key`, as a `T`, where it has one.
    pub fn simulator_part<T: DeserializeOwned>(&self, key: &str) -> Option<T> {
        part(self.simulator, key)
    }
}

fn part<T: DeserializeOwned>(report: Option<&serde_json::Value>, key: &str) -> Option<T> {
    report?.get(key).filter(|v| !v.is_null()).and_then(|v| T::deserialize(v).ok())
}

/// A reverse channel of the emulator (robot → console), declared once: its
/// flags, the path it asks for on a lane (its name, scenario flag and seed
/// rule), how that path is opened, its iceoryx2 ports, and its section of
/// the run report. A folder under `src/service/channel/`, and one line in
/// the registry (`channel/mod.rs`).
pub trait ReverseChannel: 'static {
    /// Its flags (those of `netfi run` and `netfi emulator`).
    type Args: clap::Args + clap::FromArgMatches + Render + Default + Clone + PartialEq + fmt::Debug;
    /// What netfi's own console and robot take of its flags (`netfi
    /// console`, `netfi simulator`).
    type EndArgs: clap::Args + clap::FromArgMatches + Render + Default + Clone + PartialEq + fmt::Debug;
    /// Those of `args`.
    fn end_args(args: &Self::Args) -> Self::EndArgs;
    /// Why its flags do not fit a lane.
    type ArgsError: std::error::Error + Send + Sync + 'static;
    /// Checks its flags against `lane`.
    fn check(args: &Self::Args, lane: &LaneShape) -> Result<(), Self::ArgsError>;
    /// The path it asks for on `lane`, if any.
    fn want(args: &Self::Args, lane: &LaneShape) -> Option<Want>;
    /// The seed its flags give (what a runner decided and passes on).
    fn seed(args: &mut Self::Args) -> &mut Option<u64>;
    /// Why its path could not be opened.
    type OpenError: std::error::Error + Send + Sync + 'static;
    /// Opens the path `want` asked for, as `plan` settled it.
    fn open(args: &Self::Args, want: &Want, plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<Self::OpenError>>;
    /// Its iceoryx2 ports: towards the emulator, and away from it.
    const PORTS: &'static [Port] = &[];

    /// Its section of the run report.
    type Section: Serialize + DeserializeOwned + Clone + PartialEq + fmt::Debug;
    /// Its section, joined from the services' reports; `None` when the run
    /// did not have it.
    fn section(s: Sources) -> Option<Self::Section>;
    /// The section as lines of the run's text report.
    fn text(s: &Self::Section) -> String;
    /// What the section says went wrong.
    fn faults(_s: &Self::Section) -> Vec<String> {
        Vec::new()
    }
    /// The files of the run the section names, by name (`<channel>_…`).
    fn files(_s: &Self::Section, _sources: Sources) -> Vec<(&'static str, std::path::PathBuf)> {
        Vec::new()
    }
}

/// Why a channel's path could not be opened: as any path, or the channel's
/// own reason.
#[derive(Debug, thiserror::Error)]
pub enum ChannelOpen<E: std::error::Error + 'static> {
    /// Its scenario, queue or link.
    #[error(transparent)]
    Path(#[from] OpenError),
    /// Its ports.
    #[error(transparent)]
    Own(E),
}

/// A channel of which netfi's own console and robot take no flags (no
/// group of its own: several channels flatten it).
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
#[group(skip)]
pub struct NoEndArgs {}

impl Render for NoEndArgs {
    fn render(&self, _a: &mut crate::flags::Argv) {}
}

/// Makes the registry's values from the list of channels, each
/// `field: Type` where `Type: ReverseChannel`; an entry marked
/// `[cfg(...)]` (a channel built for tests only) exists where that holds.
macro_rules! channels {
    ($( $(#[doc = $doc:literal])* $([cfg($cfg:meta)])? $field:ident: $T:ty ),+ $(,)?) => {

        /// Every reverse channel's flags.
        #[derive(Debug, Clone, Default, PartialEq, clap::Args)]
        pub struct ChannelArgs {
            $( $(#[doc = $doc])* $(#[cfg($cfg)])? #[command(flatten)] pub $field: <$T as $crate::service::channel::declare::ReverseChannel>::Args, )+
        }

        /// What netfi's own console and robot take of every channel's flags.
        #[derive(Debug, Clone, Default, PartialEq, clap::Args)]
        pub struct ChannelEndArgs {
            $( $(#[doc = $doc])* $(#[cfg($cfg)])? #[command(flatten)] pub $field: <$T as $crate::service::channel::declare::ReverseChannel>::EndArgs, )+
        }

        impl $crate::flags::Render for ChannelArgs {
            fn render(&self, a: &mut $crate::flags::Argv) {
                $( $(#[cfg($cfg)])? a.group(&self.$field); )+
            }
        }

        impl $crate::flags::Render for ChannelEndArgs {
            fn render(&self, a: &mut $crate::flags::Argv) {
                $( $(#[cfg($cfg)])? a.group(&self.$field); )+
            }
        }

        /// Why a channel's flags do not fit the lane.
        #[derive(Debug, thiserror::Error)]
        pub enum ChannelArgsError {
            $( $(#[cfg($cfg)])? #[doc = concat!("The ", stringify!($field), " channel's.")] #[error(transparent)] #[allow(non_camel_case_types)] $field(<$T as $crate::service::channel::declare::ReverseChannel>::ArgsError), )+
        }

        /// Why a channel's path could not be opened.
        #[derive(Debug, thiserror::Error)]
        pub enum ChannelOpenError {
            /// Its scenario, queue or link.
            #[error(transparent)]
            Path(#[from] $crate::service::emulator::opening::OpenError),
            $( $(#[cfg($cfg)])? #[doc = concat!("The ", stringify!($field), " channel's own.")] #[error(transparent)] #[allow(non_camel_case_types)] $field(<$T as $crate::service::channel::declare::ReverseChannel>::OpenError), )+
        }

        impl ChannelArgs {
            /// What netfi's own console and robot take of these flags.
            pub fn end_args(&self) -> ChannelEndArgs {
                ChannelEndArgs { $( $(#[cfg($cfg)])? $field: <$T as $crate::service::channel::declare::ReverseChannel>::end_args(&self.$field), )+ }
            }

            /// Checks every channel's flags against `lane`.
            pub fn check(&self, lane: &$crate::service::channel::declare::LaneShape) -> Result<(), ChannelArgsError> {
                $( $(#[cfg($cfg)])? <$T as $crate::service::channel::declare::ReverseChannel>::check(&self.$field, lane).map_err(ChannelArgsError::$field)?; )+
                Ok(())
            }

            /// The reverse paths `lane` has, by channel (its field in the
            /// registry), in the order a lane polls them.
            pub fn wants(&self, lane: &$crate::service::channel::declare::LaneShape) -> Vec<(&'static str, $crate::service::channel::declare::Want)> {
                let mut out = Vec::new();
                $( $(#[cfg($cfg)])? if let Some(w) = <$T as $crate::service::channel::declare::ReverseChannel>::want(&self.$field, lane) { out.push((stringify!($field), w)); } )+
                out
            }

            /// The seed channel `field`'s flags give.
            pub fn seed_mut(&mut self, field: &str) -> Option<&mut Option<u64>> {
                match field {
                    $( $(#[cfg($cfg)])? stringify!($field) => Some(<$T as $crate::service::channel::declare::ReverseChannel>::seed(&mut self.$field)), )+
                    _ => None,
                }
            }

            /// Each seed given, mapped by `f` (a lane's of a run's).
            pub fn map_seeds(&mut self, f: impl Fn(u64) -> u64) {
                $( $(#[cfg($cfg)])? { let s = <$T as $crate::service::channel::declare::ReverseChannel>::seed(&mut self.$field); *s = s.map(&f); } )+
            }

            /// Opens each reverse path `lane` has, in order.
            pub fn open_all(&self, lane: &$crate::service::channel::declare::LaneShape, o: &$crate::service::emulator::opening::Opening) -> Result<Vec<Box<dyn $crate::service::emulator::path::Reverse>>, ChannelOpenError> {
                let mut out = Vec::new();
                $(
                    $(#[cfg($cfg)])?
                    if let Some(w) = <$T as $crate::service::channel::declare::ReverseChannel>::want(&self.$field, lane) {
                        let plan = w.plan(o.seed)?;
                        let path = <$T as $crate::service::channel::declare::ReverseChannel>::open(&self.$field, &w, &plan, o).map_err(|e| match e {
                            $crate::service::channel::declare::ChannelOpen::Path(e) => ChannelOpenError::Path(e),
                            $crate::service::channel::declare::ChannelOpen::Own(e) => ChannelOpenError::$field(e),
                        })?;
                        out.push(path);
                    }
                )+
                Ok(out)
            }
        }

        /// Every iceoryx2 port of the channels, in the registry's order.
        pub fn channel_ports() -> Vec<$crate::transport::Port> {
            let mut out = Vec::new();
            $( $(#[cfg($cfg)])? out.extend_from_slice(<$T as $crate::service::channel::declare::ReverseChannel>::PORTS); )+
            out
        }

        /// Each channel's section of the run report, where the run had it.
        #[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
        pub struct ChannelSections {
            $( $(#[doc = $doc])* $(#[cfg($cfg)])? #[serde(default)] pub $field: Option<<$T as $crate::service::channel::declare::ReverseChannel>::Section>, )+
        }

        impl ChannelSections {
            /// Joins each channel's section from `sources`.
            pub fn join(sources: $crate::service::channel::declare::Sources) -> ChannelSections {
                ChannelSections { $( $(#[cfg($cfg)])? $field: <$T as $crate::service::channel::declare::ReverseChannel>::section(sources), )+ }
            }

            /// The sections as lines of the run's text report.
            pub fn text(&self) -> String {
                let mut s = String::new();
                $( $(#[cfg($cfg)])? if let Some(x) = &self.$field { s += &<$T as $crate::service::channel::declare::ReverseChannel>::text(x); } )+
                s
            }

            /// What the sections say went wrong.
            pub fn faults(&self) -> Vec<String> {
                let mut out = Vec::new();
                $( $(#[cfg($cfg)])? if let Some(x) = &self.$field { out.extend(<$T as $crate::service::channel::declare::ReverseChannel>::faults(x)); } )+
                out
            }

            /// The files the sections name, by name.
            pub fn files(&self, sources: $crate::service::channel::declare::Sources) -> std::collections::BTreeMap<String, std::path::PathBuf> {
                let mut out = std::collections::BTreeMap::new();
                $(
                    $(#[cfg($cfg)])?
                    if let Some(x) = &self.$field {
                        out.extend(<$T as $crate::service::channel::declare::ReverseChannel>::files(x, sources).into_iter().map(|(k, v)| (k.to_string(), v)));
                    }
                )+
                out
            }
        }
    };
}
pub(crate) use channels;
