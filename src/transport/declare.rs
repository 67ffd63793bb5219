//! What a transport declares ([`Transport`]), and the macro that makes the
//! registry's values from the list of transports ([`transports!`]): the
//! [`Endpoint`](super::Endpoint) an address is parsed into, the
//! [`Ingress`](super::Ingress) and [`Egress`](super::Egress) the emulator's
//! loop drives, the flags of every transport
//! ([`TransportArgs`](super::TransportArgs)), what a lane keeps open of each
//! ([`Sessions`](super::Sessions)) and each transport's part of the report
//! ([`TransportReports`](super::TransportReports)). The loop needs enums
//! (a send or receive is a `match` the compiler sees through, not a virtual
//! call); the macro writes them from the list, so that nothing outside the
//! registry names a transport's variants.

use crate::flags::Render;
use crate::model::ModelKind;
use crate::transport::{EndpointError, FrameSink, FrameSource};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::fmt;
use std::net::SocketAddr;

/// Which of a lane's two sides are of one transport.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sides<A> {
    /// Where frames come from, when it is of this transport.
    pub ingress: Option<A>,
    /// Where they go, when it is of this transport.
    pub egress: Option<A>,
}

impl<A> Sides<A> {
    /// Whether either side is of this transport.
    pub fn any(&self) -> bool {
        self.ingress.is_some() || self.egress.is_some()
    }

    /// Whether both are.
    pub fn both(&self) -> bool {
        self.ingress.is_some() && self.egress.is_some()
    }
}

/// The lane's flags that are not a transport's own, as far as a
/// transport's checks need them.
#[derive(Debug, Clone, Copy, Default)]
pub struct LaneFlags<'a> {
    /// The run id, when one was given (an iceoryx2 side needs one).
    pub run_id: Option<&'a str>,
    /// `--wait-for-peer-s` was given: the egress must know its receivers.
    pub wait_for_peer: bool,
    /// `--idle-end-ms` was given: the ingress must have no end of stream
    /// of its own.
    pub idle_end: bool,
}

/// What a transport's flags are checked against: which of the lane's two
/// sides are its own, and the lane's other flags.
#[derive(Clone, Copy)]
pub struct Lane<'a, A> {
    /// This transport's sides.
    pub sides: Sides<&'a A>,
    /// The lane's two endpoints, as the command line writes them.
    pub ends: (&'a dyn fmt::Display, &'a dyn fmt::Display),
    /// The lane's other flags.
    pub flags: LaneFlags<'a>,
}

/// What opening a lane's transports needs besides their flags.
pub struct Wiring<'a> {
    /// The run, for an iceoryx2 side.
    pub run_id: Option<&'a str>,
    /// Items the release queue may hold (a transport that keeps payloads
    /// of its own sizes its store by it).
    pub queue_capacity: usize,
    /// Open the egress first and wait this long for a receiver on it
    /// before opening the ingress (`None`: do not wait).
    pub wait_for_peer_ns: Option<u64>,
    /// End the stream after this long without a frame, at an ingress with
    /// no end of stream of its own (`--idle-end-ms`).
    pub idle_end_ns: Option<u64>,
    /// Asked while waiting: stop waiting (a signal came).
    pub stop: &'a dyn Fn() -> bool,
}

/// A transport of the emulator's frames: its endpoint syntax, its flags,
/// how a lane opens it, and its part of the report. One folder under
/// `src/transport/`, one line in the registry (`registry.rs`).
pub trait Transport: 'static {
    /// Its URL scheme (`udp` in `udp://ADDR:PORT`): its name in messages.
    const SCHEME: &'static str;
    /// How an endpoint of it is written, for the message that lists what
    /// an endpoint may be.
    const SYNTAX: &'static str;
    /// Whether that message lists it (a transport built for tests only is
    /// not).
    const LISTED: bool = true;
    /// What follows the scheme.
    type Addr: Clone + PartialEq + fmt::Debug + 'static;
    /// `text` as an endpoint of this transport; `None` when it is not one.
    fn parse(text: &str) -> Option<Result<Self::Addr, EndpointError>>;
    /// Writes an endpoint as the command line takes it.
    fn show(addr: &Self::Addr, f: &mut fmt::Formatter<'_>) -> fmt::Result;
    /// The socket address an endpoint names, where it names one.
    fn socket_addr(_addr: &Self::Addr) -> Option<SocketAddr> {
        None
    }

    /// Its flags, flattened into every command that opens transports.
    type Args: clap::Args + clap::FromArgMatches + Render + Default + Clone + PartialEq + fmt::Debug;
    /// Why its flags do not fit the lane.
    type ArgsError: std::error::Error + Send + Sync + 'static;
    /// Checks its flags against the lane: a flag of a side given where the
    /// side is not of this transport, options that do not go together.
    fn check(args: &Self::Args, lane: Lane<'_, Self::Addr>) -> Result<(), Self::ArgsError>;
    /// Whether a sample may carry an opaque payload kept by the transport
    /// (UDP's raw datagrams).
    fn opaque(_args: &Self::Args) -> bool {
        false
    }
    /// The stages a lane of this transport cannot apply, with these flags
    /// (a copy or a flip of a payload the transport keeps elsewhere).
    fn unsupported(_args: &Self::Args) -> &'static [ModelKind] {
        &[]
    }
    /// The release queue's default capacity on a lane of it, when it has its
    /// own.
    fn default_queue_capacity(_args: &Self::Args) -> Option<usize> {
        None
    }

    /// What a lane keeps open of it while either side is of it (the
    /// iceoryx2 node; UDP's payload store).
    type Session;
    /// Why it could not be opened.
    type OpenError: std::error::Error + Send + Sync + 'static;
    /// Opens what its sides share.
    fn session(args: &Self::Args, sides: Sides<&Self::Addr>, w: &Wiring) -> Result<Self::Session, Self::OpenError>;
    /// Where the emulator takes frames from.
    type Source: FrameSource + 'static;
    /// Where it sends what it releases.
    type Sink: FrameSink + 'static;
    /// Opens the egress.
    fn sink(s: &mut Self::Session, addr: &Self::Addr, args: &Self::Args, w: &Wiring) -> Result<Self::Sink, Self::OpenError>;
    /// Opens the ingress.
    fn source(s: &mut Self::Session, addr: &Self::Addr, args: &Self::Args, w: &Wiring) -> Result<Self::Source, Self::OpenError>;
    /// What the lane's log line adds about its sides (`ends`: the
    /// lane's two endpoints as given), once open.
    fn describe(_s: &Self::Session, _args: &Self::Args, _ends: (&dyn fmt::Display, &dyn fmt::Display)) -> Option<String> {
        None
    }
    /// Ended: whether the session asks the run to stop (a signal its
    /// library latched).
    fn termination_requested(_s: &Self::Session) -> bool {
        false
    }

    /// Its part of the report, written beside `emulator.json`.
    type Report: Serialize + DeserializeOwned + Clone + PartialEq + fmt::Debug;
    /// The file it is written to (`udp.json`), and the file of what it
    /// says once open, before the lane is ready (`udp_endpoints.json`).
    const REPORT_FILE: &'static str;
    /// The file of what it says once open, if anything.
    const START_FILE: Option<&'static str> = None;
    /// What it says once open (the sockets as bound).
    fn at_start(_s: &Self::Session) -> Option<serde_json::Value> {
        None
    }
    /// Its report at the end of the lane, of the lane's ports of it.
    fn report(s: &Self::Session, args: &Self::Args, ends: (&dyn fmt::Display, &dyn fmt::Display), source: Option<&Self::Source>, sink: Option<&Self::Sink>) -> Option<Self::Report>;
    /// Adds to its report what it says of the lane's reverse paths (their
    /// reports by channel name) and of its forward stream's release
    /// lateness, once they have finished.
    fn attach(_r: &mut Self::Report, _paths: &std::collections::BTreeMap<String, serde_json::Value>, _forward_lateness: &crate::metrics::Summary) {}
    /// What the log line at the lane's end adds from its report.
    fn summary(_r: &Self::Report) -> String {
        String::new()
    }
    /// Its report as a line of the run's text report.
    fn line(_r: &Self::Report) -> Option<String> {
        None
    }
    /// What its report says went wrong.
    fn faults(_r: &Self::Report) -> Vec<String> {
        Vec::new()
    }
}

/// A transport with no report of its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
pub enum NoReport {}

/// Makes the registry's values from the list of transports, each
/// `Variant(field): Type` where `Type: Transport`.
macro_rules! transports {
    ($( $(#[doc = $doc:literal])* $([cfg($cfg:meta)])? $V:ident($field:ident): $T:ty ),+ $(,)?) => {
        use $crate::transport::declare::{Lane, LaneFlags, Sides, Transport, Wiring};

        /// One side of the emulator, of any transport: where frames come
        /// from, or go to.
        #[derive(Debug, Clone, PartialEq)]
        pub enum Endpoint {
            $( $(#[doc = $doc])* $(#[cfg($cfg)])? $V(<$T as Transport>::Addr), )+
        }

        /// What every endpoint may be, for messages: the listed
        /// transports' syntax.
        pub fn endpoint_syntax() -> Vec<&'static str> {
            let mut out = Vec::new();
            $( $(#[cfg($cfg)])? { if <$T as Transport>::LISTED { out.push(<$T as Transport>::SYNTAX); } } )+
            out
        }

        impl std::str::FromStr for Endpoint {
            type Err = $crate::transport::EndpointError;
            fn from_str(text: &str) -> Result<Self, Self::Err> {
                $( $(#[cfg($cfg)])? { if let Some(a) = <$T as Transport>::parse(text) { return a.map(Endpoint::$V); } } )+
                Err($crate::transport::EndpointError::Scheme { text: text.into() })
            }
        }

        impl std::fmt::Display for Endpoint {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                match self { $( $(#[cfg($cfg)])? Endpoint::$V(a) => <$T as Transport>::show(a, f), )+ }
            }
        }

        impl Endpoint {
            /// Its transport's scheme.
            pub fn scheme(&self) -> &'static str {
                match self { $( $(#[cfg($cfg)])? Endpoint::$V(_) => <$T as Transport>::SCHEME, )+ }
            }

            /// Its address, when it is of transport `X`.
            pub fn of<X: Transport>(&self) -> Option<&X::Addr> {
                match self { $( $(#[cfg($cfg)])? Endpoint::$V(a) => (a as &dyn std::any::Any).downcast_ref::<X::Addr>(), )+ }
            }

            /// The socket address it names, where it names one.
            pub fn socket_addr(&self) -> Option<std::net::SocketAddr> {
                match self { $( $(#[cfg($cfg)])? Endpoint::$V(a) => <$T as Transport>::socket_addr(a), )+ }
            }

            /// Which of `ingress` and `egress` are of transport `X`.
            pub fn sides<'a, X: Transport>(ingress: &'a Endpoint, egress: &'a Endpoint) -> Sides<&'a X::Addr> {
                Sides { ingress: ingress.of::<X>(), egress: egress.of::<X>() }
            }
        }

        /// Where the emulator takes frames from.
        pub enum Ingress {
            $( $(#[doc = $doc])* $(#[cfg($cfg)])? $V(<$T as Transport>::Source), )+
        }

        /// Where the emulator sends what it releases.
        pub enum Egress {
            $( $(#[doc = $doc])* $(#[cfg($cfg)])? $V(<$T as Transport>::Sink), )+
        }

        impl Ingress {
            /// The source, when it is of transport `X`.
            pub fn of<X: Transport>(&self) -> Option<&X::Source> {
                match self { $( $(#[cfg($cfg)])? Ingress::$V(s) => (s as &dyn std::any::Any).downcast_ref::<X::Source>(), )+ }
            }
        }

        impl Egress {
            /// The sink, when it is of transport `X`.
            pub fn of<X: Transport>(&self) -> Option<&X::Sink> {
                match self { $( $(#[cfg($cfg)])? Egress::$V(s) => (s as &dyn std::any::Any).downcast_ref::<X::Sink>(), )+ }
            }
        }

        impl $crate::transport::FrameSource for Ingress {
            #[inline]
            fn try_recv(&mut self, out: &mut $crate::sample::FrameSample) -> Result<bool, $crate::transport::PortError> {
                match self { $( $(#[cfg($cfg)])? Ingress::$V(p) => $crate::transport::FrameSource::try_recv(p, out), )+ }
            }

            fn peers(&mut self) -> Option<usize> {
                match self { $( $(#[cfg($cfg)])? Ingress::$V(p) => $crate::transport::FrameSource::peers(p), )+ }
            }

            #[inline]
            fn dropped(&mut self, sample: &$crate::sample::FrameSample) {
                match self { $( $(#[cfg($cfg)])? Ingress::$V(p) => $crate::transport::FrameSource::dropped(p, sample), )+ }
            }

            #[inline]
            fn sender(&self) -> Option<std::net::SocketAddr> {
                match self { $( $(#[cfg($cfg)])? Ingress::$V(p) => $crate::transport::FrameSource::sender(p), )+ }
            }

            fn senders(&mut self) -> Vec<String> {
                match self { $( $(#[cfg($cfg)])? Ingress::$V(p) => $crate::transport::FrameSource::senders(p), )+ }
            }
        }

        impl $crate::transport::FrameSink for Egress {
            #[inline]
            fn send_with(
                &mut self,
                sample: &$crate::sample::FrameSample,
                stamp: impl FnOnce(&mut $crate::sample::FrameSample),
            ) -> Result<Option<usize>, $crate::transport::PortError> {
                match self { $( $(#[cfg($cfg)])? Egress::$V(p) => $crate::transport::FrameSink::send_with(p, sample, stamp), )+ }
            }

            fn peers(&mut self) -> Option<usize> {
                match self { $( $(#[cfg($cfg)])? Egress::$V(p) => $crate::transport::FrameSink::peers(p), )+ }
            }

            fn unsubscribed(&self) -> u64 {
                match self { $( $(#[cfg($cfg)])? Egress::$V(p) => $crate::transport::FrameSink::unsubscribed(p), )+ }
            }
        }

        /// Every transport's flags.
        #[derive(Debug, Clone, Default, PartialEq, clap::Args)]
        pub struct TransportArgs {
            $( $(#[cfg($cfg)])? #[doc = concat!("The ", stringify!($field), " transport's flags.")] #[command(flatten)] pub $field: <$T as Transport>::Args, )+
        }

        impl $crate::flags::Render for TransportArgs {
            fn render(&self, a: &mut $crate::flags::Argv) {
                $( $(#[cfg($cfg)])? a.group(&self.$field); )+
            }
        }

        /// Why a transport's flags do not fit the lane.
        #[derive(Debug, thiserror::Error)]
        pub enum TransportArgsError {
            $( $(#[cfg($cfg)])? #[doc = concat!("The ", stringify!($field), " transport's.")] #[error(transparent)] $V(<$T as Transport>::ArgsError), )+
        }

        impl TransportArgs {
            /// Checks every transport's flags against the lane `ingress` →
            /// `egress` and its other `flags`.
            pub fn check(&self, ingress: &Endpoint, egress: &Endpoint, flags: LaneFlags<'_>) -> Result<(), TransportArgsError> {
                $(
                    $(#[cfg($cfg)])? {
                        let lane = Lane { sides: Endpoint::sides::<$T>(ingress, egress), ends: (ingress, egress), flags };
                        <$T as Transport>::check(&self.$field, lane).map_err(TransportArgsError::$V)?;
                    }
                )+
                Ok(())
            }

            /// Whether a sample of the lane may carry an opaque payload.
            pub fn opaque(&self, ingress: &Endpoint, egress: &Endpoint) -> bool {
                let mut any = false;
                $( $(#[cfg($cfg)])? { any |= Endpoint::sides::<$T>(ingress, egress).any() && <$T as Transport>::opaque(&self.$field); } )+
                any
            }

            /// The stages the lane's transports cannot apply.
            pub fn unsupported(&self, ingress: &Endpoint, egress: &Endpoint) -> &'static [$crate::model::ModelKind] {
                $(
                    $(#[cfg($cfg)])? {
                        let u = <$T as Transport>::unsupported(&self.$field);
                        if Endpoint::sides::<$T>(ingress, egress).any() && !u.is_empty() {
                            return u;
                        }
                    }
                )+
                &[]
            }

            /// The release queue's default capacity on the lane, where a
            /// transport of it has its own.
            pub fn default_queue_capacity(&self, ingress: &Endpoint, egress: &Endpoint) -> Option<usize> {
                $(
                    $(#[cfg($cfg)])?
                    if Endpoint::sides::<$T>(ingress, egress).any() {
                        if let Some(c) = <$T as Transport>::default_queue_capacity(&self.$field) {
                            return Some(c);
                        }
                    }
                )+
                None
            }
        }

        /// What a lane keeps open of each transport either side is of.
        pub struct Sessions {
            $( $(#[cfg($cfg)])? #[doc = concat!("The ", stringify!($field), " transport's, when a side is of it.")] pub $field: Option<<$T as Transport>::Session>, )+
        }

        /// Why a lane's transports could not be opened.
        #[derive(Debug, thiserror::Error)]
        pub enum OpenError {
            $( $(#[cfg($cfg)])? #[doc = concat!("The ", stringify!($field), " transport's.")] #[error(transparent)] $V(<$T as Transport>::OpenError), )+
            /// No receiver came in time (`--wait-for-peer-s`).
            #[error("no robot subscribed to the emulator → simulator port within {wait_s} s")]
            NoRobot {
                /// How long it waited, s.
                wait_s: f64,
            },
            /// Told to stop while waiting for a receiver.
            #[error("stopped while waiting for a robot")]
            Stopped,
        }

        /// A lane's transports, open.
        pub struct Transports {
            /// Where frames come from.
            pub ingress: Ingress,
            /// Where released frames go.
            pub egress: Egress,
            /// What each transport keeps open.
            pub sessions: Sessions,
        }

        /// Opens `ingress` and `egress` with `args`: each transport either
        /// side is of, then the egress, then (after the wait for a
        /// receiver, when asked) the ingress, so no frame is taken before
        /// there is someone to release it to.
        pub fn open(ingress: &Endpoint, egress: &Endpoint, args: &TransportArgs, w: &Wiring) -> Result<Transports, OpenError> {
            let mut sessions = Sessions {
                $(
                    $(#[cfg($cfg)])?
                    $field: {
                        let sides = Endpoint::sides::<$T>(ingress, egress);
                        match sides.any() {
                            true => Some(<$T as Transport>::session(&args.$field, sides, w).map_err(OpenError::$V)?),
                            false => None,
                        }
                    },
                )+
            };
            let mut egress = match egress {
                $(
                    $(#[cfg($cfg)])?
                    Endpoint::$V(a) => {
                        let s = sessions.$field.as_mut().expect("a session is open for each side's transport");
                        Egress::$V(<$T as Transport>::sink(s, a, &args.$field, w).map_err(OpenError::$V)?)
                    }
                )+
            };
            if let Some(wait_ns) = w.wait_for_peer_ns {
                let stop = || (w.stop)() || sessions.termination_requested();
                $crate::transport::declare::wait_for_receiver(&mut egress, wait_ns, &stop)?;
            }
            let ingress = match ingress {
                $(
                    $(#[cfg($cfg)])?
                    Endpoint::$V(a) => {
                        let s = sessions.$field.as_mut().expect("a session is open for each side's transport");
                        Ingress::$V(<$T as Transport>::source(s, a, &args.$field, w).map_err(OpenError::$V)?)
                    }
                )+
            };
            Ok(Transports { ingress, egress, sessions })
        }

        impl Sessions {
            /// What the lane's log line adds about its transports.
            pub fn describe(&self, args: &TransportArgs, ends: (&dyn std::fmt::Display, &dyn std::fmt::Display)) -> Option<String> {
                let mut said: Option<String> = None;
                $(
                    $(#[cfg($cfg)])?
                    if let Some(s) = self.$field.as_ref().and_then(|s| <$T as Transport>::describe(s, &args.$field, ends)) {
                        said = Some(match said { Some(d) => format!("{d}; {s}"), None => s });
                    }
                )+
                said
            }

            /// Whether a transport's library latched a request to stop.
            pub fn termination_requested(&self) -> bool {
                let mut any = false;
                $( $(#[cfg($cfg)])? { any |= self.$field.as_ref().is_some_and(<$T as Transport>::termination_requested); } )+
                any
            }

            /// What each transport says once open, as `(file, value)`.
            pub fn at_start(&self) -> Vec<(&'static str, serde_json::Value)> {
                let mut out = Vec::new();
                $(
                    $(#[cfg($cfg)])?
                    if let (Some(file), Some(v)) = (<$T as Transport>::START_FILE, self.$field.as_ref().and_then(<$T as Transport>::at_start)) {
                        out.push((file, v));
                    }
                )+
                out
            }

            /// Each transport's report at the end of the lane whose ports
            /// are `ingress` and `egress` (before its paths finish).
            pub fn reports(&self, args: &TransportArgs, ends: (&dyn std::fmt::Display, &dyn std::fmt::Display), ingress: &Ingress, egress: &Egress) -> TransportReports {
                TransportReports {
                    $(
                        $(#[cfg($cfg)])?
                        $field: self.$field.as_ref().and_then(|s| <$T as Transport>::report(s, &args.$field, ends, ingress.of::<$T>(), egress.of::<$T>())),
                    )+
                }
            }
        }

        /// Each transport's part of a lane's report (written to its
        /// transport's own file, and shown in the run report under the
        /// transport's name).
        #[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
        pub struct TransportReports {
            $(
                $(#[cfg($cfg)])?
                #[doc = concat!("The ", stringify!($field), " transport's, when a side is of it.")]
                #[serde(default, skip_serializing_if = "Option::is_none")]
                pub $field: Option<<$T as Transport>::Report>,
            )+
        }

        impl TransportReports {
            /// Each report present, as `(file, value)`.
            pub fn files(&self) -> Vec<(&'static str, serde_json::Value)> {
                let mut out = Vec::new();
                $(
                    $(#[cfg($cfg)])?
                    if let Some(r) = &self.$field {
                        out.push((<$T as Transport>::REPORT_FILE, serde_json::to_value(r).expect("a report serializes")));
                    }
                )+
                out
            }

            /// Reads each transport's report file in `dir`: the reports
            /// found, and `(file, scheme, why)` for each file that is there
            /// but does not read.
            pub fn read(dir: &std::path::Path) -> (TransportReports, Vec<(&'static str, &'static str, String)>) {
                let mut bad = Vec::new();
                let r = TransportReports {
                    $(
                        $(#[cfg($cfg)])?
                        $field: $crate::transport::declare::read_report::<<$T as Transport>::Report>(dir, <$T as Transport>::REPORT_FILE)
                            .unwrap_or_else(|why| {
                                bad.push((<$T as Transport>::REPORT_FILE, <$T as Transport>::SCHEME, why));
                                None
                            }),
                    )+
                };
                (r, bad)
            }

            /// Adds what each transport says of the lane's reverse paths
            /// (their reports by channel name) and of its forward stream's
            /// release lateness.
            pub fn attach(&mut self, paths: &std::collections::BTreeMap<String, serde_json::Value>, forward_lateness: &$crate::metrics::Summary) {
                $( $(#[cfg($cfg)])? if let Some(r) = self.$field.as_mut() { <$T as Transport>::attach(r, paths, forward_lateness); } )+
            }

            /// Whether no transport has a report.
            pub fn is_empty(&self) -> bool {
                let mut none = true;
                $( $(#[cfg($cfg)])? { none &= self.$field.is_none(); } )+
                none
            }

            /// What each report adds to the log line at the lane's end.
            pub fn summary(&self) -> String {
                let mut s = String::new();
                $( $(#[cfg($cfg)])? if let Some(r) = &self.$field { s += &<$T as Transport>::summary(r); } )+
                s
            }

            /// Each report as a line of the run's text report, with its
            /// transport's scheme.
            pub fn lines(&self) -> Vec<(&'static str, String)> {
                let mut out = Vec::new();
                $( $(#[cfg($cfg)])? if let Some(l) = self.$field.as_ref().and_then(<$T as Transport>::line) { out.push((<$T as Transport>::SCHEME, l)); } )+
                out
            }

            /// What the reports say went wrong.
            pub fn faults(&self) -> Vec<String> {
                let mut out = Vec::new();
                $( $(#[cfg($cfg)])? if let Some(r) = &self.$field { out.extend(<$T as Transport>::faults(r)); } )+
                out
            }
        }
    };
}
pub(crate) use transports;

/// Reads `dir/file` as a transport's report: `None` when absent; why,
/// when it is there but does not read.
pub fn read_report<R: DeserializeOwned>(dir: &std::path::Path, file: &'static str) -> Result<Option<R>, String> {
    let path = dir.join(file);
    match std::fs::read(&path) {
        Ok(bytes) => serde_json::from_slice(&bytes).map(Some).map_err(|e| format!("{}: {e}", path.display())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(format!("reading {}: {e}", path.display())),
    }
}

/// Waits up to `wait_ns` for a receiver on `egress` (one that knows its
/// receivers), asking `stop` as it waits.
pub fn wait_for_receiver<K: FrameSink>(egress: &mut K, wait_ns: u64, stop: &dyn Fn() -> bool) -> Result<(), super::OpenError> {
    let deadline = crate::clock::now_ns() + wait_ns;
    while egress.peers() == Some(0) {
        if crate::clock::now_ns() > deadline {
            return Err(super::OpenError::NoRobot { wait_s: wait_ns as f64 / 1e9 });
        }
        if stop() {
            return Err(super::OpenError::Stopped);
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    Ok(())
}
