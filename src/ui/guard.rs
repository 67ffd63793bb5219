//! Who `netfi ui` obeys: its own page, opened by someone who holds its
//! token. Every request goes through [`check`] before any handler:
//!
//! 1. **Host.** The `Host` header must name this server: `localhost`, a
//!    loopback address, the address it is bound to (any IP address when
//!    bound to a wildcard), or a name given with `--allow-host`; and its
//!    port. A page of another name that resolves here (DNS rebinding) is
//!    refused before anything else.
//! 2. **Token.** The server prints a URL carrying a random token once, at
//!    start (as notebook servers do). Opening it sets a cookie holding the
//!    token (`HttpOnly`, `SameSite=Strict`, one name per port) and
//!    redirects to the same page without the token, so it leaves the
//!    address bar; from then on the cookie (or the `?token=` of the printed
//!    URL) is the credential. Without it a request is 401.
//! 3. **State changes.** Every `POST` must be a request no page of another
//!    origin can make without the server's consent: a JSON body
//!    (`Content-Type: application/json`) and the header `X-Netfi-UI`, which
//!    make a cross-origin request need a CORS preflight this server never
//!    grants; and, where the browser says where it comes from (`Origin`,
//!    `Sec-Fetch-Site`), from this very origin. A plain form post is 403.
//!
//! Without a token (`--no-token`) only 1 and 3 hold, and the server
//! listens on loopback only.

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderValue, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

/// The header the page sends with every state change.
pub const UI_HEADER: &str = "x-netfi-ui";

/// Bytes of randomness in a token (printed as twice as many hex digits).
const TOKEN_BYTES: usize = 24;

/// Why a server's guard could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum GuardError {
    /// No randomness for the token.
    #[error("reading /dev/urandom for the token: {0}")]
    Random(#[source] std::io::Error),
    /// A listening address off loopback without the token.
    #[error("netfi ui refuses to listen on {bind} without its token: anyone who reaches that address could start runs on this host (drop --no-token, or bind loopback: --bind 127.0.0.1)")]
    OpenWithoutToken {
        /// The address asked for.
        bind: SocketAddr,
    },
}

/// What requests must carry, fixed at start.
#[derive(Debug, Clone)]
pub struct Guard {
    token: Option<String>,
    cookie: String,
    bound: SocketAddr,
    allow_hosts: Vec<String>,
}

impl Guard {
    /// The guard of a server listening on `bound` (its real port), with
    /// `token` (`None`: no token, loopback only) and the extra host names
    /// it answers to.
    pub fn new(bound: SocketAddr, token: Option<String>, allow_hosts: Vec<String>) -> Result<Guard, GuardError> {
        if token.is_none() && !bound.ip().is_loopback() {
            return Err(GuardError::OpenWithoutToken { bind: bound });
        }
        let allow_hosts = allow_hosts.into_iter().map(|h| h.to_ascii_lowercase()).collect();
        Ok(Guard { token, cookie: format!("netfi-ui-{}", bound.port()), bound, allow_hosts })
    }

    /// The URL to print: the server's, with the token.
    pub fn url(&self) -> String {
        let host = match self.bound.ip() {
            ip if ip.is_unspecified() => "127.0.0.1".to_string(),
            IpAddr::V6(v6) => format!("[{v6}]"),
            IpAddr::V4(v4) => v4.to_string(),
        };
        match &self.token {
            Some(t) => format!("http://{host}:{}/?token={t}", self.bound.port()),
            None => format!("http://{host}:{}/", self.bound.port()),
        }
    }

    /// Whether `host` (a `Host` header's value) names this server.
    fn host_ok(&self, host: &str) -> bool {
        let host = host.to_ascii_lowercase();
        let (name, port) = match host.rsplit_once(':') {
            // `[::1]:8080`, `127.0.0.1:8080`, `localhost:8080`; a bare IPv6
            // literal without a port is bracketed and has no `]:`.
            Some((n, p)) if !n.contains(':') || n.ends_with(']') => (n, p.parse::<u16>().ok()),
            _ => (host.as_str(), Some(80)),
        };
        if port != Some(self.bound.port()) {
            return false;
        }
        let ip = name.trim_start_matches('[').trim_end_matches(']').parse::<IpAddr>().ok();
        match ip {
            // An address is never a rebinding: a page of another origin that
            // reaches this one by its address is cross-origin, and held off
            // by the token and the checks on state changes.
            Some(ip) => ip.is_loopback() || ip == self.bound.ip() || self.bound.ip().is_unspecified(),
            None => name == "localhost" || self.allow_hosts.iter().any(|h| h == name),
        }
    }

    /// The token a request carries in its cookie, or in `?token=`.
    fn presented<'a>(&self, headers: &'a HeaderMap, query: Option<&'a str>) -> (Option<&'a str>, Option<&'a str>) {
        let cookie = headers
            .get_all(header::COOKIE)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(';'))
            .filter_map(|kv| kv.trim().split_once('='))
            .find(|(k, _)| *k == self.cookie)
            .map(|(_, v)| v);
        let in_url = query.and_then(|q| q.split('&').filter_map(|kv| kv.split_once('=')).find(|(k, _)| *k == "token").map(|(_, v)| v));
        (cookie, in_url)
    }

    fn token_ok(&self, given: Option<&str>) -> bool {
        match (&self.token, given) {
            (Some(t), Some(g)) => same(t.as_bytes(), g.as_bytes()),
            _ => false,
        }
    }
}

/// Equal bytes, compared in time that depends on the lengths only.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// A fresh random token, hex.
pub fn new_token() -> Result<String, GuardError> {
    use std::io::Read;
    let mut bytes = [0u8; TOKEN_BYTES];
    std::fs::File::open("/dev/urandom").and_then(|mut f| f.read_exact(&mut bytes)).map_err(GuardError::Random)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

fn refuse(status: StatusCode, why: String) -> Response {
    (status, [(header::CONTENT_TYPE, "text/plain; charset=utf-8")], why).into_response()
}

/// The guard in front of every handler (see the module's docs).
pub async fn check(State(g): State<Arc<Guard>>, req: Request, next: Next) -> Response {
    let headers = req.headers();
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok()).unwrap_or_default();
    if !g.host_ok(host) {
        return refuse(
            StatusCode::FORBIDDEN,
            format!(
                "Host `{host}` is not this server's: netfi ui answers to localhost:{port} and 127.0.0.1:{port}{more} \
                 (a page of another name that resolves here is refused)",
                port = g.bound.port(),
                more = if g.allow_hosts.is_empty() { String::new() } else { format!(", and to {}", g.allow_hosts.join(", ")) },
            ),
        );
    }
    if req.method() != Method::GET && req.method() != Method::HEAD {
        if let Some(why) = not_from_the_page(headers, host) {
            return refuse(StatusCode::FORBIDDEN, why);
        }
    }
    if g.token.is_none() {
        return next.run(req).await;
    }
    let (cookie, in_url) = g.presented(headers, req.uri().query());
    if g.token_ok(cookie) {
        return next.run(req).await;
    }
    if g.token_ok(in_url) && req.method() == Method::GET {
        // The printed URL: the token goes into the cookie and out of the
        // address bar.
        let set = format!("{}={}; HttpOnly; SameSite=Strict; Path=/", g.cookie, g.token.as_deref().unwrap_or_default());
        let mut r = Response::new(axum::body::Body::empty());
        *r.status_mut() = StatusCode::SEE_OTHER;
        let to = HeaderValue::from_str(req.uri().path()).unwrap_or(HeaderValue::from_static("/"));
        r.headers_mut().insert(header::LOCATION, to);
        if let Ok(v) = HeaderValue::from_str(&set) {
            r.headers_mut().insert(header::SET_COOKIE, v);
        }
        return r;
    }
    refuse(
        StatusCode::UNAUTHORIZED,
        "netfi ui needs its token: open the URL it printed when it started (http://…/?token=…)".to_string(),
    )
}

/// Why a state change did not come from the server's own page, if it did
/// not: it must carry a JSON body and the page's header, and where the
/// browser says where it comes from, from this origin (`host`).
fn not_from_the_page(headers: &HeaderMap, host: &str) -> Option<String> {
    let json = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(';').next().is_some_and(|m| m.trim().eq_ignore_ascii_case("application/json")));
    if !json || !headers.contains_key(UI_HEADER) {
        return Some(format!(
            "a state change is a JSON request (Content-Type: application/json) with the `{UI_HEADER}` header, as the page sends: \
             a form post or a simple request is refused"
        ));
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let origin = origin.to_str().unwrap_or("?");
        if !origin.eq_ignore_ascii_case(&format!("http://{host}")) {
            return Some(format!("cross-origin request from `{origin}` refused: netfi ui obeys its own page only"));
        }
    }
    if let Some(site) = headers.get("sec-fetch-site").and_then(|v| v.to_str().ok()) {
        if site != "same-origin" {
            return Some(format!("request from another site (Sec-Fetch-Site: {site}) refused: netfi ui obeys its own page only"));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn guard(bind: &str) -> Guard {
        Guard::new(bind.parse().unwrap(), Some("0123456789abcdef0123".into()), vec!["Lab-PC".into()]).unwrap()
    }

    #[test]
    fn a_host_is_this_server_by_loopback_its_address_or_an_allowed_name_and_its_port() {
        let g = guard("127.0.0.1:8080");
        for ok in ["127.0.0.1:8080", "localhost:8080", "LOCALHOST:8080", "[::1]:8080", "lab-pc:8080"] {
            assert!(g.host_ok(ok), "{ok}");
        }
        for bad in ["evil.example:8080", "127.0.0.1:8081", "localhost", "", "192.0.2.7:8080", "localhost.evil.example:8080", "[::1]"] {
            assert!(!g.host_ok(bad), "{bad}");
        }
        // Bound to every address: any address literal, never a foreign name.
        let g = guard("0.0.0.0:80");
        assert!(g.host_ok("192.0.2.7") && g.host_ok("192.0.2.7:80") && g.host_ok("[2001:db8::1]:80"));
        assert!(!g.host_ok("evil.example") && !g.host_ok("192.0.2.7:81"));
        assert_eq!(g.url(), "http://127.0.0.1:80/?token=0123456789abcdef0123");
    }

    #[test]
    fn a_token_comes_in_the_cookie_of_this_port_or_the_printed_url() {
        let g = guard("127.0.0.1:8080");
        let mut h = HeaderMap::new();
        h.insert(header::COOKIE, HeaderValue::from_static("a=b; netfi-ui-8081=nope; netfi-ui-8080=0123456789abcdef0123"));
        let (cookie, url) = g.presented(&h, Some("x=1&token=zzz"));
        assert!(g.token_ok(cookie) && !g.token_ok(url));
        assert!(!g.token_ok(None) && !g.token_ok(Some("0123456789abcdef012")));
        let t = new_token().unwrap();
        assert_eq!(t.len(), 2 * TOKEN_BYTES);
        assert_ne!(t, new_token().unwrap());
    }

    #[test]
    fn only_a_json_request_with_the_header_from_this_origin_changes_state() {
        let mut h = HeaderMap::new();
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/x-www-form-urlencoded"));
        assert!(not_from_the_page(&h, "127.0.0.1:8080").unwrap().contains("form post"));
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/json; charset=utf-8"));
        assert!(not_from_the_page(&h, "127.0.0.1:8080").is_some(), "no page header");
        h.insert(UI_HEADER, HeaderValue::from_static("1"));
        assert_eq!(not_from_the_page(&h, "127.0.0.1:8080"), None);
        h.insert(header::ORIGIN, HeaderValue::from_static("http://127.0.0.1:9999"));
        assert!(not_from_the_page(&h, "127.0.0.1:8080").unwrap().contains("cross-origin"));
        h.insert(header::ORIGIN, HeaderValue::from_static("http://127.0.0.1:8080"));
        h.insert("sec-fetch-site", HeaderValue::from_static("same-site"));
        assert!(not_from_the_page(&h, "127.0.0.1:8080").unwrap().contains("another site"));
    }

    #[test]
    fn no_token_means_loopback_only() {
        for open in ["0.0.0.0:8080", "[::]:8080", "192.0.2.7:8080"] {
            let e = Guard::new(open.parse().unwrap(), None, Vec::new()).unwrap_err();
            assert!(e.to_string().contains(open) && e.to_string().contains("--no-token"), "{e}");
        }
        assert!(Guard::new("127.0.0.1:8080".parse().unwrap(), None, Vec::new()).is_ok());
        assert!(Guard::new("[::1]:8080".parse().unwrap(), None, Vec::new()).is_ok());
    }
}
