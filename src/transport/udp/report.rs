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
    /// netfi's own time per datagram, each way: from the moment its
    /// receive returned to the moment its send began, beyond the delay the
    /// scenario injected (each path's release lateness). What netfi adds
    /// over a relay that sends each datagram on as it takes it; the
    /// system calls themselves, the wait in the socket for the loop's next
    /// receive and the hop to the other end are not in it.
    #[serde(default)]
    pub own_time_ns: Option<OwnTime>,
}

/// netfi's own time per datagram, each way ([`UdpReport::own_time_ns`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OwnTime {
    /// Console → robot.
    pub forward: OwnPercentiles,
    /// Robot → console, where there is a return path.
    #[serde(rename = "return")]
    pub return_path: Option<OwnPercentiles>,
}

/// A distribution's count, median and 99th percentile, ns (each at most
/// 0.1 % above the exact value: the histograms' precision).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct OwnPercentiles {
    /// Datagrams sent.
    pub count: u64,
    /// The median.
    pub p50: u64,
    /// The 99th percentile.
    pub p99: u64,
}

impl OwnPercentiles {
    /// Those of `s`.
    pub fn of(s: &crate::metrics::Summary) -> OwnPercentiles {
        OwnPercentiles { count: s.count, p50: s.p50, p99: s.p99 }
    }

    fn text(&self) -> String {
        use crate::metrics::fmt_ns;
        format!("p50 {}, p99 {}", fmt_ns(self.p50), fmt_ns(self.p99))
    }
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
        if let Some(own) = u.own_time_ns.filter(|o| o.forward.count > 0) {
            s += &format!("; netfi's own time per datagram (receive → send, beyond the injected delay): forward {}", own.forward.text());
            if let Some(back) = own.return_path.filter(|b| b.count > 0) {
                s += &format!(", return {}", back.text());
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_shows_netfis_own_time_each_way_once_datagrams_went_through() {
        let mut r = UdpReport {
            ingress: "udp://127.0.0.1:5000".into(),
            egress: "udp://127.0.0.1:6000".into(),
            payload: crate::transport::udp::Payload::Raw,
            ingress_local: None,
            egress_local: None,
            datagrams_in: Some(10),
            ingress_kernel_drops: Some(0),
            ingress_buffer_bytes: None,
            console: None,
            foreign_sender: 0,
            foreign_senders: Vec::new(),
            foreign_unnamed: 0,
            arena_slots: None,
            arena_high_water: None,
            return_path: None,
            own_time_ns: None,
        };
        assert!(!r.line().contains("own time"), "{}", r.line());
        let forward = OwnPercentiles { count: 10, p50: 213, p99: 1_741 };
        r.own_time_ns = Some(OwnTime { forward, return_path: None });
        assert!(r.line().ends_with("; netfi's own time per datagram (receive → send, beyond the injected delay): forward p50 213 ns, p99 1.74 µs"), "{}", r.line());
        r.own_time_ns = Some(OwnTime { forward, return_path: Some(OwnPercentiles { count: 10, p50: 140, p99: 1_534 }) });
        assert!(r.line().ends_with("forward p50 213 ns, p99 1.74 µs, return p50 140 ns, p99 1.53 µs"), "{}", r.line());
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["own_time_ns"]["return"]["p99"], 1_534);
        assert_eq!(serde_json::from_value::<UdpReport>(json).unwrap(), r);
    }
}
