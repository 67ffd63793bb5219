//! What opening a stream's reverse paths needs: the stream's arguments,
//! transports, seed and directory ([`Opening`]), and a reverse path's
//! scenario, seed and queue resolved once ([`PathPlan`]).

use crate::scenario::{Scenario, ScenarioSpec};
use crate::service::args::EmulatorArgs;
use crate::service::emulator::forward::ConsoleAddr;
use crate::service::emulator::path::{Channel, Path};
use crate::transport::Transports;
use anyhow::Context;
use std::path::Path as FsPath;

/// What opening a stream's reverse paths needs.
pub struct Opening<'a> {
    /// The stream's own arguments.
    pub args: &'a EmulatorArgs,
    /// Its transports, open.
    pub t: &'a Transports,
    /// Its seed (the reverse paths' seeds are derived from it).
    pub seed: u64,
    /// Items expected, to size each trace and loss interval.
    pub expected_frames: u64,
    /// Its directory.
    pub out_dir: &'a FsPath,
    /// The console's address, once a UDP ingress knows it.
    pub console: &'a ConsoleAddr,
}

/// A reverse path's scenario, seed and queue, resolved once.
#[derive(Debug, Clone)]
pub struct PathPlan {
    /// The flag it was given by, for messages.
    pub flag: &'static str,
    pub spec: ScenarioSpec,
    pub seed: u64,
    pub queue_capacity: usize,
}

impl PathPlan {
    /// The plan of a reverse path given by `flag` as `name` (default
    /// `Normal`: nothing injected), its seed `given` or derived from the
    /// stream's `seed` by `tag`, its queue the file's or `capacity`.
    pub fn resolve(flag: &'static str, name: Option<&str>, given: Option<u64>, seed: u64, tag: u64, capacity: usize) -> anyhow::Result<PathPlan> {
        let name = name.unwrap_or("Normal");
        let spec = crate::load::resolve(name).with_context(|| format!("{flag} {name}"))?;
        let seed = crate::service::seeds::derived(given, &spec, seed, tag);
        let queue_capacity = spec.queue_capacity.unwrap_or(capacity);
        anyhow::ensure!(queue_capacity >= 1, "{flag} {name}: queue_capacity must be at least 1");
        Ok(PathPlan { flag, spec, seed, queue_capacity })
    }

    /// The path of `chan` as planned, its trace in `out_dir` sized for
    /// `expected` items.
    pub fn open<C: Channel>(&self, chan: C, expected: u64, out_dir: &FsPath) -> anyhow::Result<Path<C>> {
        let scenario = Scenario::new(&self.spec, self.seed).with_context(|| format!("{} {}", self.flag, self.spec.name))?;
        let path = Path::new(chan, scenario, self.seed, self.queue_capacity, expected, out_dir, false)
            .with_context(|| format!("{} {}", self.flag, self.spec.name))?;
        eprintln!("emulator: {} path through scenario {} seed {}, queue {}", C::NAME, self.spec.name, self.seed, self.queue_capacity);
        Ok(path)
    }
}
