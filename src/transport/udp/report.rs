//! What a lane with a UDP side writes: `udp.json` at its end, and
//! `udp_endpoints.json` (the sockets as bound) before it is ready.

use serde::{Deserialize, Serialize};

/// `udp.json`: the UDP side of an emulator run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UdpReport {
    /// The lane's endpoints, as given.
    pub ingress: String,
    /// Where its frames went.
    pub egress: String,
    /// What a datagram carried.
    pub payload: super::Payload,
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
    /// Raw mode: arena slots.
    pub arena_slots: Option<usize>,
    /// Raw mode: the most arena slots ever in use at once.
    pub arena_high_water: Option<usize>,
    /// The return path's report (the path `return` of `emulator.json`).
    pub return_path: Option<serde_json::Value>,
}

/// The endpoints as bound, written to `udp_endpoints.json` before
/// `emulator.ready`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoundEndpoints {
    /// The ingress socket's address.
    pub ingress: Option<std::net::SocketAddr>,
    /// The address the egress socket sends from.
    pub egress_local: Option<std::net::SocketAddr>,
    /// The robot's address.
    pub egress_peer: Option<std::net::SocketAddr>,
}

/// A sender other than the console, and how many datagrams it sent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForeignSender {
    /// Its address.
    pub addr: std::net::SocketAddr,
    /// The datagrams refused from it.
    pub datagrams: u64,
}

impl UdpReport {
    /// The UDP side of a lane on one line of the run's report: its
    /// sockets, what came in, what the kernel dropped before it, and the
    /// senders it refused.
    pub fn line(&self) -> String {
        let u = self;
        let opt = |v: Option<u64>| v.map_or("?".to_string(), |x| x.to_string());
        let bound = |a: Option<std::net::SocketAddr>, how: &str| a.map_or(String::new(), |a| format!(" ({how} {a})"));
        let mut s = format!(
            "ingress {}{}, egress {}{}, payload {}: {} datagrams in, {} dropped by the kernel before ingress; console {}",
            u.ingress,
            bound(u.ingress_local, "bound"),
            u.egress,
            bound(u.egress_local, "from"),
            serde_json::to_value(u.payload).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default(),
            opt(u.datagrams_in),
            opt(u.ingress_kernel_drops),
            u.console.map_or("?".into(), |c| c.to_string())
        );
        if u.foreign_sender > 0 {
            let who: Vec<String> = u.foreign_senders.iter().map(|f| format!("{} ({})", f.addr, f.datagrams)).collect();
            s += &format!("; {} datagrams from other senders refused: {}", u.foreign_sender, who.join(", "));
            if u.foreign_unnamed > 0 {
                s += &format!(" and {} from others", u.foreign_unnamed);
            }
        }
        s
    }

    /// What went wrong at the UDP side: datagrams the kernel dropped
    /// before the emulator could take them.
    pub fn fault(&self) -> Option<String> {
        let n = self.ingress_kernel_drops.filter(|n| *n > 0)?;
        Some(format!("{n} datagrams dropped by the kernel at the emulator's ingress socket {} (its receive buffer full): they never entered", self.ingress))
    }

    /// What the log line at a lane's end adds: the kernel's drops, the
    /// foreign senders, the return path.
    pub fn summary(&self) -> String {
        let u = self;
        let mut s = String::new();
        if let Some(k) = u.ingress_kernel_drops.filter(|k| *k > 0) {
            s += &format!("; {k} datagrams dropped by the kernel before ingress");
        }
        if u.foreign_sender > 0 {
            let who: Vec<String> = u.foreign_senders.iter().map(|f| format!("{} ({})", f.addr, f.datagrams)).collect();
            s += &format!("; {} datagrams from foreign senders dropped (foreign_sender): {}", u.foreign_sender, who.join(", "));
        }
        if let Some(rp) = &u.return_path {
            let n = |k: &str| rp[k].as_u64().unwrap_or(0);
            let dropped: u64 = rp["dropped"].as_object().map_or(0, |d| d.values().filter_map(|v| v.as_u64()).sum());
            s += &format!(
                "; return path ({}): {} received, {} delivered, {} dropped, {} held, {} unroutable",
                rp["mode"].as_str().unwrap_or("?"),
                n("received"),
                n("delivered"),
                dropped,
                n("held_at_end"),
                n("unroutable")
            );
        }
        s
    }
}
