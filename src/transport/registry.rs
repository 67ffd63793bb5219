//! The transports there are, one line each: the emulator's endpoints are
//! parsed by the scheme each declares, its two sides are enums over them,
//! and every command that opens transports takes each one's flags. A new
//! transport is a folder under `src/transport/` with a [`Transport`]
//! (super::declare::Transport) impl, and a line here.

use super::declare::transports;

transports! {
    /// The run's iceoryx2 port (`iceoryx2`).
    Iceoryx2(iceoryx2): super::ipc::Iceoryx2,
    /// A UDP socket (`udp://ADDR:PORT`).
    Udp(udp): super::udp::Udp,
    /// A Unix datagram socket (`unixgram:PATH`), in test builds.
    [cfg(debug_assertions)] Unixgram(unixgram): super::unixgram::Unixgram,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::EndpointError;

    #[test]
    fn endpoints_parse_by_their_transport_s_scheme_with_loopback_by_default() {
        let ep = |s: &str| s.parse::<Endpoint>().unwrap();
        let udp = |s: &str| Endpoint::Udp(s.parse().unwrap());
        assert_eq!(ep("iceoryx2"), Endpoint::Iceoryx2(()));
        assert_eq!(ep("iox2:"), Endpoint::Iceoryx2(()));
        assert_eq!(ep("udp://127.0.0.1:36000"), udp("127.0.0.1:36000"));
        assert_eq!(ep("udp:127.0.0.1:36000"), udp("127.0.0.1:36000"));
        assert_eq!(ep("udp://:36000"), udp("127.0.0.1:36000"));
        assert_eq!(ep("udp://36000"), udp("127.0.0.1:36000"));
        assert_eq!(ep("udp://[::1]:5"), udp("[::1]:5"));
        assert_eq!(ep("udp://0.0.0.0:36000"), udp("0.0.0.0:36000"));
        assert_eq!(ep("udp://localhost:7"), udp("127.0.0.1:7"));
        assert_eq!(ep("udp://127.0.0.1:36000").to_string(), "udp://127.0.0.1:36000");
        assert_eq!(ep("iox2:").to_string(), "iceoryx2");
        assert_eq!((ep("iceoryx2").scheme(), ep("udp://:1").scheme()), ("iceoryx2", "udp"));
        assert_eq!(ep("udp://:1").socket_addr(), Some("127.0.0.1:1".parse().unwrap()));
        assert_eq!(ep("udp://:1").of::<crate::transport::ipc::Iceoryx2>(), None);
    }

    #[test]
    fn bad_endpoints_say_what_is_accepted() {
        let e = "tcp://1.2.3.4:5".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Scheme { .. }), "{e}");
        assert_eq!(
            e.to_string(),
            "`tcp://1.2.3.4:5`: expected `iceoryx2` or `udp://ADDR:PORT` (e.g. udp://127.0.0.1:36000, udp://:36000, udp://[::1]:36000)"
        );
        let e = "udp://127.0.0.1:http".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Port { .. }), "{e}");
        let e = "udp://127.0.0.1:70000".parse::<Endpoint>().unwrap_err();
        assert!(matches!(e, EndpointError::Port { .. }), "{e}");
    }
}
