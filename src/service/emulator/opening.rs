//! What opening a stream's reverse paths needs: the lane's shape, its
//! transports, seed and directory ([`Opening`]), and a reverse path's
//! scenario, seed and queue resolved once ([`PathPlan`]).

use crate::scenario::{Scenario, ScenarioError, ScenarioSpec};
use crate::service::emulator::path::{Channel, Path, PathError};
use std::path::{Path as FsPath, PathBuf};

/// A reverse path's scenario that does not read or does not build, as
/// `flag name` named it (the runner's check and the emulator's own).
#[derive(Debug, thiserror::Error)]
#[error("{flag} {name}")]
pub struct PathScenarioError {
    pub flag: &'static str,
    pub name: String,
    #[source]
    pub cause: ScenarioError,
}

/// Why a lane, or one of its paths, did not open.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error(transparent)]
    PathScenario(#[from] PathScenarioError),
    #[error("{flag} {name}: queue_capacity must be at least 1")]
    QueueCapacity { flag: &'static str, name: String },
    /// A reverse path around its link.
    #[error("{flag} {name}")]
    Path {
        flag: &'static str,
        name: String,
        #[source]
        cause: PathError,
    },
    /// The forward path around its link.
    #[error(transparent)]
    Forward(#[from] PathError),
    /// The lane's own scenario.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error("scenario `{scenario}`: the `{stage}` stage applies to ITP frames, not to raw datagrams (--payload raw)")]
    RawStage { scenario: String, stage: &'static str },
    #[error("creating {}", .dir.display())]
    Dir {
        dir: PathBuf,
        #[source]
        cause: std::io::Error,
    },
    /// The ingress and egress.
    #[error(transparent)]
    Transports(#[from] crate::transport::OpenError),
    /// A reverse path.
    #[error(transparent)]
    Channel(Box<crate::service::channel::ChannelOpenError>),
    /// A file the lane writes at its start.
    #[error(transparent)]
    Write(#[from] crate::service::emulator::report::WriteError),
}

impl From<crate::service::channel::ChannelOpenError> for OpenError {
    fn from(e: crate::service::channel::ChannelOpenError) -> Self {
        OpenError::Channel(Box::new(e))
    }
}

/// What opening a stream's reverse paths needs.
pub struct Opening<'a> {
    /// The lane: its endpoints and its transports' flags.
    pub shape: crate::service::channel::LaneShape<'a>,
    /// What its transports keep open.
    pub sessions: &'a crate::transport::Sessions,
    /// Its seed (the reverse paths' seeds are derived from it).
    pub seed: u64,
    /// Items expected, to size each trace and loss interval.
    pub expected_frames: u64,
    /// Its directory.
    pub out_dir: &'a FsPath,
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
    pub fn resolve(flag: &'static str, name: Option<&str>, given: Option<u64>, seed: u64, tag: u64, capacity: usize) -> Result<PathPlan, OpenError> {
        let name = name.unwrap_or("Normal");
        let spec = crate::load::resolve(name).map_err(|cause| PathScenarioError { flag, name: name.into(), cause })?;
        let seed = crate::service::seeds::derived(given, &spec, seed, tag);
        let queue_capacity = spec.queue_capacity.unwrap_or(capacity);
        if queue_capacity < 1 {
            return Err(OpenError::QueueCapacity { flag, name: name.into() });
        }
        Ok(PathPlan { flag, spec, seed, queue_capacity })
    }

    /// The path of `chan` as planned, its trace in `out_dir` sized for
    /// `expected` items.
    pub fn open<C: Channel>(&self, chan: C, expected: u64, out_dir: &FsPath) -> Result<Path<C>, OpenError> {
        let (flag, name) = (self.flag, self.spec.name.clone());
        let scenario = Scenario::new(&self.spec, self.seed).map_err(|cause| PathScenarioError { flag, name: name.clone(), cause })?;
        let path = Path::new(chan, scenario, self.seed, self.queue_capacity, expected, out_dir, false).map_err(|cause| OpenError::Path { flag, name, cause })?;
        eprintln!("emulator: {} path through scenario {} seed {}, queue {}", C::NAME, self.spec.name, self.seed, self.queue_capacity);
        Ok(path)
    }
}
