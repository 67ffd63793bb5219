//! Who a UDP port takes datagrams from: the console a UDP ingress serves
//! ([`ConsolePolicy`]), and the count of what was refused from anyone else
//! ([`ForeignSenders`], reported as [`Refused`]).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::net::SocketAddr;
use std::str::FromStr;

/// Which sender a UDP ingress takes frames from. There is no default: a
/// UDP ingress is told which console it serves, or told to pair with the
/// first sender, and anything else is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConsolePolicy {
    /// The console's address: datagrams from it only, from the start.
    Named(SocketAddr),
    /// Trust on first datagram: the first sender becomes the console for
    /// the whole run (said on stderr, with its address); from then on
    /// datagrams from anyone else are refused. Whoever speaks first wins,
    /// so name the console where its address is known.
    FirstDatagram,
}

impl From<SocketAddr> for ConsolePolicy {
    fn from(addr: SocketAddr) -> Self {
        ConsolePolicy::Named(addr)
    }
}

impl fmt::Display for ConsolePolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConsolePolicy::Named(a) => write!(f, "{a}"),
            ConsolePolicy::FirstDatagram => f.write_str("first"),
        }
    }
}

/// Why a console policy could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{text}`: expected the console's ADDR:PORT (e.g. 192.0.2.1:36000, [::1]:36000) or `first` (pair with the first sender)")]
pub struct ConsolePolicyError {
    /// What was given.
    pub text: String,
}

impl FromStr for ConsolePolicy {
    type Err = ConsolePolicyError;

    /// `first`, or a socket address (`192.0.2.1:36000`, `[::1]:36000`).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        if text.eq_ignore_ascii_case("first") {
            return Ok(ConsolePolicy::FirstDatagram);
        }
        text.parse::<SocketAddr>().map(ConsolePolicy::Named).map_err(|_| ConsolePolicyError { text: text.into() })
    }
}

/// Whether datagrams from `from` come from `peer`. A socket bound to
/// IPv6's wildcard (`[::]`) also takes IPv4 datagrams, and gives their
/// senders as IPv4-mapped addresses (`[::ffff:127.0.0.1]:5`): such an
/// address is the same sender as its IPv4 self, however either was
/// named.
#[inline]
pub fn same_sender(peer: SocketAddr, from: SocketAddr) -> bool {
    peer.port() == from.port() && peer.ip().to_canonical() == from.ip().to_canonical()
}

/// How many distinct refused senders are named in a report; datagrams from
/// further ones are counted together.
pub const FOREIGN_SENDERS_NAMED: usize = 16;

/// Datagrams refused because they came from an address other than the
/// port's peer: counted per sender, never taken. A fixed table, so that a
/// flood from many addresses costs no allocation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ForeignSenders {
    named: [Option<(SocketAddr, u64)>; FOREIGN_SENDERS_NAMED],
    /// All refused datagrams.
    pub total: u64,
    /// Those from senders beyond the first [`FOREIGN_SENDERS_NAMED`].
    pub unnamed: u64,
}

impl ForeignSenders {
    /// Counts one datagram from `from`.
    #[inline]
    pub fn count(&mut self, from: SocketAddr) {
        // An IPv4 sender is named as such, also on a dual-stack socket.
        let from = SocketAddr::new(from.ip().to_canonical(), from.port());
        self.total += 1;
        for slot in self.named.iter_mut() {
            match slot {
                Some((a, n)) if *a == from => {
                    *n += 1;
                    return;
                }
                Some(_) => {}
                None => {
                    *slot = Some((from, 1));
                    return;
                }
            }
        }
        self.unnamed += 1;
    }

    /// The senders named, with their datagram counts, in the order first seen.
    pub fn named(&self) -> impl Iterator<Item = (SocketAddr, u64)> + '_ {
        self.named.iter().flatten().copied()
    }

    /// The counts as a report embeds them (off the hot path: it allocates).
    pub fn report(&self) -> Refused {
        Refused {
            datagrams: self.total,
            senders: self.named().map(|(addr, datagrams)| RefusedSender { addr, datagrams }).collect(),
            unnamed: self.unnamed,
        }
    }
}

/// What a port refused, for a report (`udp.json`): `datagrams` in all,
/// the first [`FOREIGN_SENDERS_NAMED`] senders with their counts, and the
/// datagrams of the senders beyond them.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Refused {
    /// Datagrams refused.
    pub datagrams: u64,
    /// Who sent them, in the order first seen.
    pub senders: Vec<RefusedSender>,
    /// Datagrams from senders beyond those named.
    pub unnamed: u64,
}

/// A sender whose datagrams were refused, and how many.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RefusedSender {
    /// Its address.
    pub addr: SocketAddr,
    /// Its datagrams refused.
    pub datagrams: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_policy_is_an_address_or_first_and_anything_else_says_what_is_accepted() {
        assert_eq!("first".parse(), Ok(ConsolePolicy::FirstDatagram));
        assert_eq!("192.0.2.1:36000".parse(), Ok(ConsolePolicy::Named("192.0.2.1:36000".parse().unwrap())));
        assert_eq!("[::1]:5".parse::<ConsolePolicy>().unwrap().to_string(), "[::1]:5");
        assert_eq!(ConsolePolicy::FirstDatagram.to_string(), "first");
        for bad in ["", "any", "192.0.2.1", "udp://192.0.2.1:5", "192.0.2.1:70000"] {
            let e = bad.parse::<ConsolePolicy>().unwrap_err();
            assert!(e.to_string().contains("ADDR:PORT") && e.to_string().contains("`first`"), "{e}");
        }
    }

    #[test]
    fn an_ipv4_mapped_sender_is_its_ipv4_self_and_nothing_else() {
        let v4: SocketAddr = "127.0.0.1:4000".parse().unwrap();
        let mapped: SocketAddr = "[::ffff:127.0.0.1]:4000".parse().unwrap();
        assert!(same_sender(v4, mapped) && same_sender(mapped, v4) && same_sender(mapped, mapped) && same_sender(v4, v4));
        for other in ["[::ffff:127.0.0.1]:4001", "[::ffff:127.0.0.2]:4000", "[::1]:4000", "[::127.0.0.1]:4000", "127.0.0.2:4000"] {
            assert!(!same_sender(v4, other.parse().unwrap()), "{other}");
        }
        let v6: SocketAddr = "[2001:db8::1]:4000".parse().unwrap();
        assert!(same_sender(v6, v6) && !same_sender(v6, "[2001:db8::2]:4000".parse().unwrap()));
        let mut f = ForeignSenders::default();
        f.count(mapped);
        f.count(v4);
        assert_eq!(f.report().senders, [RefusedSender { addr: v4, datagrams: 2 }]);
    }

    #[test]
    fn senders_are_counted_each_then_together_past_the_table() {
        let mut f = ForeignSenders::default();
        let addr = |p: u16| SocketAddr::from(([127, 0, 0, 1], p));
        for p in 0..FOREIGN_SENDERS_NAMED as u16 + 3 {
            f.count(addr(p));
            f.count(addr(p));
        }
        f.count(addr(0));
        let r = f.report();
        assert_eq!(r.datagrams, 2 * (FOREIGN_SENDERS_NAMED as u64 + 3) + 1);
        assert_eq!(r.senders.len(), FOREIGN_SENDERS_NAMED);
        assert_eq!(r.senders[0], RefusedSender { addr: addr(0), datagrams: 3 });
        assert_eq!(r.unnamed, 6);
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["senders"][1]["addr"], "127.0.0.1:1");
    }
}
