//! An emulator endpoint as the command line names it (`iceoryx2` or
//! `udp://ADDR:PORT`), and what a UDP datagram carries.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, ToSocketAddrs};
use std::str::FromStr;

/// One side of the emulator: where frames come from, or go to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// The run's iceoryx2 port.
    Iceoryx2,
    /// A UDP socket address.
    Udp(SocketAddr),
}

impl Endpoint {
    /// The socket address of a UDP endpoint.
    pub fn udp(&self) -> Option<SocketAddr> {
        match self {
            Endpoint::Udp(a) => Some(*a),
            Endpoint::Iceoryx2 => None,
        }
    }

    /// Whether this is a UDP endpoint.
    pub fn is_udp(&self) -> bool {
        matches!(self, Endpoint::Udp(_))
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::Iceoryx2 => f.write_str("iceoryx2"),
            Endpoint::Udp(a) => write!(f, "udp://{a}"),
        }
    }
}

/// Why an endpoint could not be parsed.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    /// Neither `iceoryx2` nor `udp://…`.
    #[error("`{text}`: expected `iceoryx2` or `udp://ADDR:PORT` (e.g. udp://127.0.0.1:36000, udp://:36000, udp://[::1]:36000)")]
    Scheme {
        /// What was given.
        text: String,
    },
    /// `udp://` with no usable port.
    #[error("`{text}`: expected a port number 0..=65535 after the last `:`")]
    Port {
        /// What was given.
        text: String,
    },
    /// The host part did not resolve.
    #[error("`{text}`: cannot resolve `{host}`: {source}")]
    Resolve {
        /// What was given.
        text: String,
        /// Its host part.
        host: String,
        /// Why it did not resolve.
        #[source]
        source: std::io::Error,
    },
    /// The host resolved to no address.
    #[error("`{text}`: `{host}` has no address")]
    NoAddress {
        /// What was given.
        text: String,
        /// Its host part.
        host: String,
    },
}

impl FromStr for Endpoint {
    type Err = EndpointError;

    /// `iceoryx2` (or `ipc`); `udp://ADDR:PORT` with an IPv4 address, a
    /// bracketed IPv6 address or a host name; `udp://:PORT` or `udp://PORT`
    /// for loopback (127.0.0.1).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        if text.eq_ignore_ascii_case("iceoryx2") || text.eq_ignore_ascii_case("ipc") {
            return Ok(Endpoint::Iceoryx2);
        }
        let Some(rest) = text.strip_prefix("udp://") else {
            return Err(EndpointError::Scheme { text: text.into() });
        };
        let rest = rest.strip_suffix('/').unwrap_or(rest);
        if let Ok(a) = rest.parse::<SocketAddr>() {
            return Ok(Endpoint::Udp(a));
        }
        let (host, port) = match rest.rsplit_once(':') {
            Some((h, p)) => (h, p),
            None => ("", rest),
        };
        let port: u16 = port.parse().map_err(|_| EndpointError::Port { text: text.into() })?;
        if host.is_empty() {
            return Ok(Endpoint::Udp(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port)));
        }
        let host_plain = host.trim_start_matches('[').trim_end_matches(']');
        let addrs: Vec<SocketAddr> = (host_plain, port)
            .to_socket_addrs()
            .map_err(|source| EndpointError::Resolve { text: text.into(), host: host.into(), source })?
            .collect();
        // Prefer IPv4 (as `localhost` is usually meant), else the first.
        let a = addrs.iter().find(|a| a.is_ipv4()).or(addrs.first()).copied();
        a.map(Endpoint::Udp).ok_or_else(|| EndpointError::NoAddress { text: text.into(), host: host.into() })
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_parse_with_loopback_by_default() {
        let ep = |s: &str| s.parse::<Endpoint>().unwrap();
        assert_eq!(ep("iceoryx2"), Endpoint::Iceoryx2);
        assert_eq!(ep("udp://127.0.0.1:36000"), Endpoint::Udp("127.0.0.1:36000".parse().unwrap()));
        assert_eq!(ep("udp://:36000"), Endpoint::Udp("127.0.0.1:36000".parse().unwrap()));
        assert_eq!(ep("udp://36000"), Endpoint::Udp("127.0.0.1:36000".parse().unwrap()));
        assert_eq!(ep("udp://[::1]:5"), Endpoint::Udp("[::1]:5".parse().unwrap()));
        assert_eq!(ep("udp://0.0.0.0:36000"), Endpoint::Udp("0.0.0.0:36000".parse().unwrap()));
        assert_eq!(ep("udp://localhost:7"), Endpoint::Udp("127.0.0.1:7".parse().unwrap()));
        assert_eq!(ep("udp://127.0.0.1:36000").to_string(), "udp://127.0.0.1:36000");
    }

    #[test]
    fn bad_endpoints_say_what_is_accepted() {
        let e = "tcp://1.2.3.4:5".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Scheme { .. }) && e.to_string().contains("udp://ADDR:PORT"), "{e}");
        let e = "udp://127.0.0.1:http".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Port { .. }), "{e}");
        let e = "udp://127.0.0.1:70000".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Port { .. }), "{e}");
    }
}
