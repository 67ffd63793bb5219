//! The UDP bridge's flags, and the checks of them against a lane's sides.

use crate::flags::values;
use crate::flags::{Argv, Render};
use crate::transport::declare::Lane;
use crate::transport::udp::{ConsolePolicy, DEFAULT_UDP_BUFFER_BYTES};
use clap::Args;
use serde::{Deserialize, Serialize};
use std::net::SocketAddr;

/// What a UDP datagram carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Payload {
    /// One ITP frame (124 bytes, checksummed) per datagram, validated.
    #[default]
    Itp,
    /// Any datagram up to 64 KiB, forwarded as opaque bytes.
    Raw,
}

/// The UDP bridge's options.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct UdpArgs {
    /// What a UDP datagram carries: one ITP frame (validated), or any bytes
    /// up to 64 KiB (UDP on both sides).
    #[arg(long, value_enum, default_value_t = Payload::Itp)]
    pub payload: Payload,
    /// Local address the UDP egress sends from (default: an ephemeral port,
    /// on loopback when the robot is on loopback).
    #[arg(long, value_name = "ADDR:PORT")]
    pub egress_bind: Option<SocketAddr>,
    /// With a UDP ingress (required there): the console's address, the
    /// only sender whose datagrams are taken; or `first`: pair with the
    /// first sender, trusted from then on (said on stderr). Datagrams from
    /// anyone else are refused and counted (`foreign_sender` in udp.json).
    #[arg(long, value_name = "ADDR:PORT|first")]
    pub console_from: Option<ConsolePolicy>,
    /// With UDP on both sides: the address the robot answers from, where it
    /// is not the --egress address. Return datagrams from anyone else are
    /// refused and counted (`refused` of the return path in udp.json).
    #[arg(long, value_name = "ADDR:PORT")]
    pub robot_from: Option<SocketAddr>,
    /// Send return datagrams here instead of to the console's
    /// address (`udp://ADDR:PORT`).
    #[arg(long, value_name = "ENDPOINT", value_parser = return_to)]
    pub return_to: Option<SocketAddr>,
    /// Do not relay datagrams from the robot side at all.
    #[arg(long)]
    pub no_return: bool,
    /// Requested kernel receive/send buffer of each UDP socket, bytes (1 to 1 GiB).
    #[arg(long, default_value_t = DEFAULT_UDP_BUFFER_BYTES, value_parser = values::udp_buffer_bytes())]
    pub udp_buffer_bytes: usize,
}

/// `--return-to`: a UDP endpoint.
fn return_to(text: &str) -> Result<SocketAddr, String> {
    match super::transport::parse(text) {
        Some(Ok(a)) => Ok(a),
        Some(Err(e)) => Err(e.to_string()),
        None => Err("--return-to takes udp://ADDR:PORT".into()),
    }
}

impl Default for UdpArgs {
    /// ITP payloads, no addresses named.
    fn default() -> Self {
        UdpArgs {
            payload: Payload::Itp,
            egress_bind: None,
            console_from: None,
            robot_from: None,
            return_to: None,
            no_return: false,
            udp_buffer_bytes: DEFAULT_UDP_BUFFER_BYTES,
        }
    }
}

/// Flags of the UDP bridge that do not fit the lane's sides.
#[derive(Debug, thiserror::Error)]
pub enum UdpArgsError {
    /// Raw payloads with an iceoryx2 side.
    #[error("--payload raw needs UDP on both sides (--ingress udp://… --egress udp://…): an iceoryx2 port carries ITP frames only")]
    RawNeedsUdp,
    /// UDP return options without UDP on both sides.
    #[error("--return-to and --no-return apply to the UDP return path; with iceoryx2 on both sides the feedback goes to the console's `feedback_out` (--no-feedback turns it off)")]
    UdpReturnWithIceoryx2,
    /// Return options with one UDP side.
    #[error("--return-scenario, --return-to and --return-seed apply to the return path, which needs UDP on both sides (or iceoryx2 on both, for the feedback loop)")]
    ReturnNeedsBothSides,
    /// `--robot-from` without UDP on both sides.
    #[error("--robot-from applies to the return path, which needs UDP on both sides")]
    RobotFromNeedsBothSides,
    /// `--no-return` with return options.
    #[error("--no-return cannot be combined with --return-scenario, --return-to or --return-seed")]
    NoReturnWithReturn,
    /// A flag of one UDP side given without that side.
    #[error("{flag} applies to a UDP {side}{more}")]
    NeedsUdpSide {
        /// The flag.
        flag: &'static str,
        /// `ingress` or `egress`.
        side: &'static str,
        /// What else to say.
        more: &'static str,
    },
    /// A robot's address that cannot be sent to.
    #[error("--egress udp://{egress}: the robot's address needs a specific address and a port other than 0")]
    EgressAddress {
        /// What was given.
        egress: SocketAddr,
    },
    /// `--wait-for-peer-s` towards a UDP robot.
    #[error("--wait-for-peer-s waits for a robot on the iceoryx2 egress; a UDP robot does not subscribe")]
    WaitForUdpPeer,
}

impl UdpArgs {
    /// Checks the flags against the lane's sides.
    pub fn check(&self, lane: Lane<'_, SocketAddr>) -> Result<(), UdpArgsError> {
        let (i, e) = (lane.sides.ingress.is_some(), lane.sides.egress.is_some());
        if !(i || e) {
            if self.return_to.is_some() || self.no_return {
                return Err(UdpArgsError::UdpReturnWithIceoryx2);
            }
        }
        if self.payload == Payload::Raw && !(i && e) {
            return Err(UdpArgsError::RawNeedsUdp);
        }
        if self.return_to.is_some() && !(i && e) {
            return Err(UdpArgsError::ReturnNeedsBothSides);
        }
        if self.no_return && self.return_to.is_some() {
            return Err(UdpArgsError::NoReturnWithReturn);
        }
        let side = |flag, side, more| UdpArgsError::NeedsUdpSide { flag, side, more };
        if self.egress_bind.is_some() && !e {
            return Err(side("--egress-bind", "egress", ""));
        }
        if self.robot_from.is_some() && !(i && e) {
            return Err(UdpArgsError::RobotFromNeedsBothSides);
        }
        if self.console_from.is_some() && !i {
            return Err(side("--console-from", "ingress", ""));
        }
        if lane.flags.wait_for_peer && e {
            return Err(UdpArgsError::WaitForUdpPeer);
        }
        if let Some(a) = lane.sides.egress {
            if a.port() == 0 || a.ip().is_unspecified() {
                return Err(UdpArgsError::EgressAddress { egress: *a });
            }
        }
        Ok(())
    }
}

impl Render for UdpArgs {
    /// Only what differs from the defaults: an iceoryx2 emulator's argv
    /// says nothing of UDP.
    fn render(&self, a: &mut Argv) {
        let d = UdpArgs::default();
        let payload = (self.payload != d.payload).then(|| clap::ValueEnum::to_possible_value(&self.payload).map(|v| v.get_name().to_string()));
        a.opt("--payload", payload.flatten())
            .opt("--egress-bind", self.egress_bind)
            .opt("--console-from", self.console_from)
            .opt("--robot-from", self.robot_from)
            .opt("--return-to", self.return_to.map(|a| format!("udp://{a}")))
            .switch("--no-return", self.no_return)
            .unless_default("--udp-buffer-bytes", self.udp_buffer_bytes, d.udp_buffer_bytes);
    }
}
