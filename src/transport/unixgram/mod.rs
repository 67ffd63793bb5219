//! Unix datagram sockets as a transport of the emulator
//! (`unixgram:PATH`), built into test builds only. It is the smallest whole
//! transport there is, and the tests use it to show that a transport is
//! this folder and one line in the registry: the runner, the plan, the
//! checks and the report take it without naming it.
//!
//! One ITP frame per datagram, as over UDP. The ingress binds `PATH` and
//! takes every datagram sent to it (the socket's file is the run's own, so
//! only its owner can send); an empty datagram ends the stream. The
//! egress sends each released frame to the socket bound at `PATH`, and an
//! empty datagram at the end of the stream.

use crate::clock::now_ns;
use crate::sample::{FrameSample, ITP_FRAME_LEN};
use crate::transport::declare::{Lane, NoReport, Sides, Transport, Wiring};
use crate::transport::{EndpointError, FrameSink, FrameSource, PortError};
use std::fmt;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};

/// The Unix datagram transport.
pub struct Unixgram;

/// It has no flags.
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct UnixgramArgs {}

impl crate::flags::Render for UnixgramArgs {
    fn render(&self, _a: &mut crate::flags::Argv) {}
}

/// Why a socket could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("unixgram:{}: {source}", path.display())]
pub struct UnixgramOpenError {
    /// The socket's path.
    pub path: PathBuf,
    /// Why.
    #[source]
    pub source: std::io::Error,
}

/// The ingress: a socket bound at its path, removed when it closes.
pub struct UnixgramSource {
    socket: UnixDatagram,
    path: PathBuf,
    taken: u64,
}

/// The egress: a socket that sends to the robot's path.
pub struct UnixgramSink {
    socket: UnixDatagram,
    to: PathBuf,
}

fn port_error(path: &Path, e: &std::io::Error) -> PortError {
    PortError { port: format!("unixgram:{}", path.display()), message: e.to_string() }
}

impl FrameSource for UnixgramSource {
    fn try_recv(&mut self, out: &mut FrameSample) -> Result<bool, PortError> {
        let mut wire = [0u8; ITP_FRAME_LEN];
        match self.socket.recv(&mut wire) {
            Ok(0) => {
                *out = FrameSample::end_marker(self.taken);
                Ok(true)
            }
            Ok(len) => {
                *out = FrameSample { send_ns: now_ns(), console_index: self.taken, len: len as u32, wire, ..FrameSample::ZERO };
                self.taken += 1;
                Ok(true)
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => Ok(false),
            Err(e) => Err(port_error(&self.path, &e)),
        }
    }
}

impl Drop for UnixgramSource {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

impl FrameSink for UnixgramSink {
    fn send_with(&mut self, sample: &FrameSample, stamp: impl FnOnce(&mut FrameSample)) -> Result<Option<usize>, PortError> {
        let mut s = *sample;
        stamp(&mut s);
        let bytes = if s.is_end() { &[][..] } else { s.payload() };
        self.socket.send_to(bytes, &self.to).map(|_| None).map_err(|e| port_error(&self.to, &e))
    }
}

impl Transport for Unixgram {
    const SCHEME: &'static str = "unixgram";
    const SYNTAX: &'static str = "`unixgram:PATH`";
    const LISTED: bool = false;
    type Addr = PathBuf;

    fn parse(text: &str) -> Option<Result<PathBuf, EndpointError>> {
        text.strip_prefix("unixgram:").map(|p| Ok(PathBuf::from(p)))
    }

    fn show(addr: &PathBuf, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unixgram:{}", addr.display())
    }

    type Args = UnixgramArgs;
    type ArgsError = std::convert::Infallible;

    fn check(_args: &UnixgramArgs, _lane: Lane<'_, PathBuf>) -> Result<(), std::convert::Infallible> {
        Ok(())
    }

    type Session = ();
    type OpenError = UnixgramOpenError;

    fn session(_args: &UnixgramArgs, _sides: Sides<&PathBuf>, _w: &Wiring) -> Result<(), UnixgramOpenError> {
        Ok(())
    }

    type Source = UnixgramSource;
    type Sink = UnixgramSink;

    fn sink(_s: &mut (), addr: &PathBuf, _args: &UnixgramArgs, _w: &Wiring) -> Result<UnixgramSink, UnixgramOpenError> {
        let named = |source| UnixgramOpenError { path: addr.clone(), source };
        let socket = UnixDatagram::unbound().map_err(named)?;
        Ok(UnixgramSink { socket, to: addr.clone() })
    }

    fn source(_s: &mut (), addr: &PathBuf, _args: &UnixgramArgs, _w: &Wiring) -> Result<UnixgramSource, UnixgramOpenError> {
        let named = |source| UnixgramOpenError { path: addr.clone(), source };
        let socket = UnixDatagram::bind(addr).map_err(named)?;
        socket.set_nonblocking(true).map_err(named)?;
        Ok(UnixgramSource { socket, path: addr.clone(), taken: 0 })
    }

    type Report = NoReport;
    const REPORT_FILE: &'static str = "unixgram.json";

    fn report(_s: &(), _args: &UnixgramArgs, _ends: (&dyn fmt::Display, &dyn fmt::Display), _source: Option<&UnixgramSource>, _sink: Option<&UnixgramSink>) -> Option<NoReport> {
        None
    }
}
