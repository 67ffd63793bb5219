//! What a lane with a UDP side writes: `udp.json` at its end, and
//! `udp_endpoints.json` (the sockets as bound) before it is ready.

use serde::{Deserialize, Serialize};

/// `udp.json`: the UDP side of an emulator run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UdpReport {
    pub ingress: String,
    pub egress: String,
    pub payload: crate::transport::Payload,
    /// Address the ingress socket is bound to.
    pub ingress_local: Option<std::net::SocketAddr>,
    /// Address the egress socket sends from.
    pub egress_local: Option<std::net::SocketAddr>,
    /// Datagrams taken off the ingress socket (each entered the emulator).
    pub datagrams_in: Option<u64>,
    /// Datagrams the kernel dropped at the ingress socket (receive buffer
    /// full) before the emulator could take them: they never entered.
    pub ingress_kernel_drops: Option<u64>,
    /// Receive buffer of the ingress socket as granted, bytes.
    pub ingress_buffer_bytes: Option<usize>,
    /// The console's address: `--console-from`, or the first sender's.
    pub console: Option<std::net::SocketAddr>,
    /// Ingress datagrams from other senders, dropped before they entered
    /// the link (so not in its accounting).
    #[serde(default)]
    pub foreign_sender: u64,
    /// Who they were: the first distinct senders, with their counts.
    #[serde(default)]
    pub foreign_senders: Vec<ForeignSender>,
    /// Foreign datagrams from senders beyond those named.
    #[serde(default)]
    pub foreign_unnamed: u64,
    /// Raw mode: arena slots, and the most ever in use at once.
    pub arena_slots: Option<usize>,
    pub arena_high_water: Option<usize>,
    /// The return path's report (the path `return` of `emulator.json`).
    pub return_path: Option<serde_json::Value>,
}

/// The endpoints as bound, written to `udp_endpoints.json` before
/// `emulator.ready`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoundEndpoints {
    pub ingress: Option<std::net::SocketAddr>,
    pub egress_local: Option<std::net::SocketAddr>,
    pub egress_peer: Option<std::net::SocketAddr>,
}

/// A sender other than the console, and how many datagrams it sent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForeignSender {
    pub addr: std::net::SocketAddr,
    pub datagrams: u64,
}
