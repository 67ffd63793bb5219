//! iceoryx2 as a transport of the emulator (`iceoryx2`, or `iox2:`): the
//! run's node, the console's port at the ingress and the simulator's at
//! the egress.

use super::{FramePublisher, FrameSubscriber, IpcNode, Port, PublisherOpenError, Role, SubscriberOpenError};
use crate::transport::declare::{Lane, NoReport, Sides, Transport, Wiring};
use crate::transport::{open_node, EndpointError, NodeError};
use std::fmt;

/// The iceoryx2 transport.
pub struct Iceoryx2;

/// iceoryx2 has no flags of its own: the run id names its services.
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct Iceoryx2Args {}

impl crate::flags::Render for Iceoryx2Args {
    fn render(&self, _a: &mut crate::flags::Argv) {}
}

/// Why an iceoryx2 side does not fit the lane.
#[derive(Debug, thiserror::Error)]
pub enum Iceoryx2ArgsError {
    /// No run id for an iceoryx2 side.
    #[error("--run-id is required with the iceoryx2 ingress and egress")]
    RunIdRequired,
    /// No run id for the iceoryx2 side of a bridge.
    #[error("--run-id is needed for the iceoryx2 side (ingress {ingress}, egress {egress})")]
    RunIdNeeded {
        /// Where frames come from.
        ingress: String,
        /// Where they go.
        egress: String,
    },
    /// `--idle-end-ms` at an iceoryx2 ingress.
    #[error("--idle-end-ms applies to a UDP ingress; an iceoryx2 console ends its stream itself")]
    IdleEnd,
}

/// Why the emulator's iceoryx2 sides could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum Iceoryx2OpenError {
    /// An iceoryx2 side without a run to open it in.
    #[error("an iceoryx2 endpoint needs a run id")]
    RunIdNeeded,
    /// The iceoryx2 node could not be opened.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// The emulator → simulator port could not be opened.
    #[error("opening the emulator → simulator port: {0}")]
    Egress(#[source] PublisherOpenError),
    /// The console → emulator port could not be opened.
    #[error("opening the console → emulator port: {0}")]
    Ingress(#[source] SubscriberOpenError),
}

impl Transport for Iceoryx2 {
    const SCHEME: &'static str = "iceoryx2";
    const SYNTAX: &'static str = "`iceoryx2`";
    type Addr = ();

    /// `iceoryx2`, `iox2:` (or `ipc`): the run's own port on that side.
    fn parse(text: &str) -> Option<Result<(), EndpointError>> {
        let t = text.to_ascii_lowercase();
        matches!(t.as_str(), "iceoryx2" | "ipc" | "iox2" | "iox2:" | "iceoryx2:").then_some(Ok(()))
    }

    fn show(_addr: &(), f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("iceoryx2")
    }

    type Args = Iceoryx2Args;
    type ArgsError = Iceoryx2ArgsError;

    fn check(_args: &Iceoryx2Args, lane: Lane<'_, ()>) -> Result<(), Iceoryx2ArgsError> {
        let s = lane.sides;
        if lane.flags.idle_end && s.ingress.is_some() {
            return Err(Iceoryx2ArgsError::IdleEnd);
        }
        match (s.any(), lane.flags.run_id) {
            (true, None) if s.both() => Err(Iceoryx2ArgsError::RunIdRequired),
            (true, None) => Err(Iceoryx2ArgsError::RunIdNeeded { ingress: lane.ends.0.to_string(), egress: lane.ends.1.to_string() }),
            _ => Ok(()),
        }
    }

    type Session = IpcNode;
    type OpenError = Iceoryx2OpenError;

    fn session(_args: &Iceoryx2Args, _sides: Sides<&()>, w: &Wiring) -> Result<IpcNode, Iceoryx2OpenError> {
        let run_id = w.run_id.ok_or(Iceoryx2OpenError::RunIdNeeded)?;
        Ok(open_node(run_id, Role::Emulator)?)
    }

    type Source = FrameSubscriber;
    type Sink = FramePublisher;

    fn sink(node: &mut IpcNode, _addr: &(), _args: &Iceoryx2Args, _w: &Wiring) -> Result<FramePublisher, Iceoryx2OpenError> {
        node.publisher(Port::EMULATOR).map_err(Iceoryx2OpenError::Egress)
    }

    fn source(node: &mut IpcNode, _addr: &(), _args: &Iceoryx2Args, _w: &Wiring) -> Result<FrameSubscriber, Iceoryx2OpenError> {
        node.subscriber(Port::CONSOLE).map_err(Iceoryx2OpenError::Ingress)
    }

    /// Where a client finds the run: its iceoryx2 root and prefix (a
    /// client on another root or prefix sees no run at all).
    fn describe(node: &IpcNode, _args: &Iceoryx2Args, _ends: (&dyn fmt::Display, &dyn fmt::Display)) -> Option<String> {
        let c = node.config();
        Some(format!("iceoryx2 root {} prefix {}", c.root().display(), c.prefix()))
    }

    fn termination_requested(node: &IpcNode) -> bool {
        node.termination_requested()
    }

    type Report = NoReport;
    const REPORT_FILE: &'static str = "iceoryx2.json";

    fn report(_s: &IpcNode, _args: &Iceoryx2Args, _ends: (&dyn fmt::Display, &dyn fmt::Display), _source: Option<&FrameSubscriber>, _sink: Option<&FramePublisher>) -> Option<NoReport> {
        None
    }
}
