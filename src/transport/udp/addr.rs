//! A UDP endpoint as the command line writes it: `udp://ADDR:PORT`.

use crate::transport::EndpointError;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, ToSocketAddrs};

/// `udp://ADDR:PORT` (an IPv4 address, a bracketed IPv6 address or a host
/// name; `udp://:PORT` and `udp://PORT` are loopback); `None` for text of
/// another scheme.
pub fn parse(text: &str) -> Option<Result<SocketAddr, EndpointError>> {
    let rest = text.strip_prefix("udp://").or_else(|| text.strip_prefix("udp:"))?;
    Some(parse_addr(text, rest))
}

fn parse_addr(text: &str, rest: &str) -> Result<SocketAddr, EndpointError> {
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if let Ok(a) = rest.parse::<SocketAddr>() {
        return Ok(a);
    }
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) => (h, p),
        None => ("", rest),
    };
    let port: u16 = port.parse().map_err(|_| EndpointError::Port { text: text.into() })?;
    if host.is_empty() {
        return Ok(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port));
    }
    let host_plain = host.trim_start_matches('[').trim_end_matches(']');
    let addrs: Vec<SocketAddr> = (host_plain, port)
        .to_socket_addrs()
        .map_err(|source| EndpointError::Resolve { text: text.into(), host: host.into(), source })?
        .collect();
    // Prefer IPv4 (as `localhost` is usually meant), else the first.
    let a = addrs.iter().find(|a| a.is_ipv4()).or(addrs.first()).copied();
    a.ok_or_else(|| EndpointError::NoAddress { text: text.into(), host: host.into() })
}

