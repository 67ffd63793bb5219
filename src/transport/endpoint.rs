//! Why an emulator endpoint as the command line names it (`iceoryx2`,
//! `udp://ADDR:PORT`) could not be read. The endpoint itself is the
//! registry's ([`super::Endpoint`]): each transport parses its own scheme.

/// Why an endpoint could not be parsed.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    /// No transport's scheme.
    #[error("`{text}`: expected {}", super::endpoint_syntax().join(" or "))]
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

