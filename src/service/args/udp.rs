//! The emulator's UDP endpoints and options (`netfi emulator` only).

use super::argv::{Argv, Render};
use super::error::ArgsError;
use super::values;
use crate::transport::udp::DEFAULT_UDP_BUFFER_BYTES;
use crate::transport::{Endpoint, Payload};
use clap::Args;
use std::net::SocketAddr;

/// Where the emulator's frames come from and go to, and the UDP bridge's
/// options.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct UdpArgs {
    /// Where frames come from: `iceoryx2` (the console's port) or
    /// `udp://ADDR:PORT` (a socket bound there; `udp://:PORT` binds loopback).
    #[arg(long, default_value = "iceoryx2", value_name = "ENDPOINT")]
    pub ingress: Endpoint,
    /// Where survivors go: `iceoryx2` (the simulator's port) or
    /// `udp://ADDR:PORT` (the robot's address).
    #[arg(long, default_value = "iceoryx2", value_name = "ENDPOINT")]
    pub egress: Endpoint,
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
    pub console_from: Option<crate::transport::udp::ConsolePolicy>,
    /// With UDP on both sides: the address the robot answers from, where it
    /// is not the --egress address. Return datagrams from anyone else are
    /// refused and counted (`refused` of the return path in udp.json).
    #[arg(long, value_name = "ADDR:PORT")]
    pub robot_from: Option<SocketAddr>,
    /// Send return datagrams here instead of to the console's
    /// address (`udp://ADDR:PORT`).
    #[arg(long, value_name = "ENDPOINT")]
    pub return_to: Option<Endpoint>,
    /// Do not relay datagrams from the robot side at all.
    #[arg(long)]
    pub no_return: bool,
    /// With a UDP ingress: end the run as if the console had ended, once no
    /// datagram has arrived for this many milliseconds, at most a week
    /// (default: run until SIGINT/SIGTERM).
    #[arg(long, value_name = "MS", value_parser = values::idle_end_millis)]
    pub idle_end_ms: Option<f64>,
    /// Requested kernel receive/send buffer of each UDP socket, bytes (1 to 1 GiB).
    #[arg(long, default_value_t = DEFAULT_UDP_BUFFER_BYTES, value_parser = values::udp_buffer_bytes())]
    pub udp_buffer_bytes: usize,
}

impl Default for UdpArgs {
    /// iceoryx2 on both sides.
    fn default() -> Self {
        UdpArgs {
            ingress: Endpoint::Iceoryx2,
            egress: Endpoint::Iceoryx2,
            payload: Payload::Itp,
            egress_bind: None,
            console_from: None,
            robot_from: None,
            return_to: None,
            no_return: false,
            idle_end_ms: None,
            udp_buffer_bytes: DEFAULT_UDP_BUFFER_BYTES,
        }
    }
}

impl UdpArgs {
    /// Whether either side is UDP.
    pub fn any(&self) -> bool {
        self.ingress.is_udp() || self.egress.is_udp()
    }

    /// Checks the options of a bridge with at least one UDP side, with its
    /// return options `return_given` (`--return-scenario`, `--return-seed`)
    /// and whether a run id names its iceoryx2 side.
    pub fn validate(&self, return_given: bool, run_id: bool) -> Result<(), ArgsError> {
        let (i, e) = (self.ingress.is_udp(), self.egress.is_udp());
        if self.payload == Payload::Raw && !(i && e) {
            return Err(ArgsError::RawNeedsUdp);
        }
        let return_opts = return_given || self.return_to.is_some();
        if return_opts && !(i && e) {
            return Err(ArgsError::ReturnNeedsBothSides);
        }
        if self.no_return && return_opts {
            return Err(ArgsError::NoReturnWithReturn);
        }
        let side = |flag, side, more| ArgsError::NeedsUdpSide { flag, side, more };
        if self.idle_end_ms.is_some() && !i {
            return Err(side("--idle-end-ms", "ingress", "; an iceoryx2 console ends its stream itself"));
        }
        if self.egress_bind.is_some() && !e {
            return Err(side("--egress-bind", "egress", ""));
        }
        if self.robot_from.is_some() && !(i && e) {
            return Err(ArgsError::RobotFromNeedsBothSides);
        }
        if self.console_from.is_some() && !i {
            return Err(side("--console-from", "ingress", ""));
        }
        if let Some(a) = self.egress.udp() {
            if a.port() == 0 || a.ip().is_unspecified() {
                return Err(ArgsError::EgressAddress { egress: self.egress });
            }
        }
        // An iceoryx2 side needs the run's id to find its services.
        let iceoryx2_side = !(i && e);
        if iceoryx2_side && !run_id {
            return Err(ArgsError::RunIdNeeded { ingress: self.ingress, egress: self.egress });
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
        a.unless_default("--ingress", self.ingress, d.ingress)
            .unless_default("--egress", self.egress, d.egress)
            .opt("--payload", payload.flatten())
            .opt("--egress-bind", self.egress_bind)
            .opt("--console-from", self.console_from)
            .opt("--robot-from", self.robot_from)
            .opt("--return-to", self.return_to)
            .switch("--no-return", self.no_return)
            .opt("--idle-end-ms", self.idle_end_ms)
            .unless_default("--udp-buffer-bytes", self.udp_buffer_bytes, d.udp_buffer_bytes);
    }
}
