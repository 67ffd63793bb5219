//! The names of a run's iceoryx2 resources: the run id, the channels and
//! the roles of its processes.

use core::fmt;
use std::str::FromStr;
use std::sync::Arc;


/// Identifier of one run: 1 to [`RunId::MAX_LEN`] ASCII letters, digits,
/// `_` or `-`. It names every iceoryx2 resource of the run, so runs with
/// different ids never interfere. Cloning is cheap (shared string), so
/// errors on the hot path can carry it without allocating.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunId(Arc<str>);

impl RunId {
    /// Longest accepted run id, in bytes.
    pub const MAX_LEN: usize = 48;

    /// Validates `value` as a run id.
    pub fn new(value: &str) -> Result<Self, RunIdError> {
        if value.is_empty() {
            return Err(RunIdError::Empty);
        }
        if value.len() > Self::MAX_LEN {
            return Err(RunIdError::TooLong {
                run: value.to_owned(),
                len: value.len(),
            });
        }
        if let Some((index, ch)) = value
            .char_indices()
            .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_' || c == '-'))
        {
            return Err(RunIdError::InvalidCharacter {
                run: value.to_owned(),
                ch,
                index,
            });
        }
        Ok(Self(Arc::from(value)))
    }

    /// The run id as written.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The name of the run's iceoryx2 resource `leaf` (a channel's service,
    /// a role's node, a side service): `netfi/<run>/<leaf>`.
    pub fn resource_name(&self, leaf: impl fmt::Display) -> String {
        format!("netfi/{}/{leaf}", self.0)
    }
}

impl fmt::Display for RunId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl FromStr for RunId {
    type Err = RunIdError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

/// Why a string is not a valid [`RunId`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RunIdError {
    /// The run id is the empty string.
    #[error("run id is empty; use 1 to 48 ASCII letters, digits, `_` or `-`")]
    Empty,
    /// The run id is longer than [`RunId::MAX_LEN`] bytes.
    #[error("run id `{run}` is {len} bytes long; at most 48 are accepted")]
    TooLong {
        /// The rejected run id.
        run: String,
        /// Its length in bytes.
        len: usize,
    },
    /// The run id contains a character other than an ASCII letter, digit,
    /// `_` or `-`.
    #[error(
        "run id `{run}` contains {ch:?} at byte {index}; only ASCII letters, digits, `_` and `-` are accepted"
    )]
    InvalidCharacter {
        /// The rejected run id.
        run: String,
        /// The first offending character.
        ch: char,
        /// Its byte offset in `run`.
        index: usize,
    },
}

/// One hop of a run, carried by one publish/subscribe service
/// `netfi/<run>/<name>`: its name, and the roles that publish and
/// subscribe on it (so a dead peer is reported by role). The frames' own
/// hops are here; a reverse channel declares its ports with its channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Port {
    name: &'static str,
    producer: Role,
    consumer: Role,
}

impl Port {
    /// The port `name`, published by `producer`, subscribed by `consumer`.
    pub const fn new(name: &'static str, producer: Role, consumer: Role) -> Port {
        Port { name, producer, consumer }
    }

    /// Console → emulator: the frames as the console sent them.
    pub const CONSOLE: Port = Port::new("console", Role::Console, Role::Emulator);
    /// Emulator → simulator: the frames that survived the scenario.
    pub const EMULATOR: Port = Port::new("emulator", Role::Emulator, Role::Simulator);
    /// Console → simulator directly: the same frames without the emulator,
    /// the baseline hop measured in the same run.
    pub const DIRECT: Port = Port::new("direct", Role::Console, Role::Simulator);

    /// The last component of the service name.
    pub fn as_str(self) -> &'static str {
        self.name
    }

    /// The role that publishes on this port.
    pub fn producer(self) -> Role {
        self.producer
    }

    /// The role that subscribes to this port.
    pub fn consumer(self) -> Role {
        self.consumer
    }
}

impl fmt::Display for Port {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

/// What a process is in the run; names its iceoryx2 node, so that a dead
/// peer can be reported by role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// The surgeon-side command source.
    Console,
    /// The fault injector.
    Emulator,
    /// The patient-side receiver.
    Simulator,
    /// Anything else attached to the run: a recorder, an inspector, a test.
    Tool,
}

impl Role {
    /// All roles.
    pub const ALL: [Role; 4] = [Role::Console, Role::Emulator, Role::Simulator, Role::Tool];

    /// The lowercase name used in node names and messages.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Console => "console",
            Role::Emulator => "emulator",
            Role::Simulator => "simulator",
            Role::Tool => "tool",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}
