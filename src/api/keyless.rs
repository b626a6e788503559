//! Keyless mode (no `[[auth.keys]]`: the demo, `--insecure`): what stands in for a key
//! against the web pages the local user opens.
//!
//! Without keys every request is let through, and rackd then listens on loopback only (see
//! [`crate::app`]). Loopback does not keep a browser out: any page the user opens may send
//! requests to `127.0.0.1`, and a page whose own name is made to point at `127.0.0.1` (DNS
//! rebinding) reads the answers as its own. So, on every route a key would guard
//! (`/api/v1/*`, `/metrics`), and only without keys:
//!
//! - **`Host` must name rackd** (421 `host_not_allowed`): `localhost`, `127.0.0.1`, `[::1]`
//!   or the listen address, at the listen port, or an entry of `[server] allowed_hosts`. A
//!   rebinding page's requests carry its own name, which is none of those. Listening on
//!   every interface (`--insecure --listen 0.0.0.0:8080`), an address written as such (an
//!   IP literal) at the listen port is allowed too: no DNS answer is involved, so it cannot
//!   be rebound, and the machine's addresses are not known in advance.
//! - **`Origin`, when sent, must be rackd's own** (403 `origin_not_allowed`): the same as
//!   the `Host` (the dashboard's own requests), or one of the names above at their port,
//!   or an `allowed_hosts` entry. Browsers send `Origin` with every cross-site request and
//!   every WebSocket handshake, so this refuses a cross-site WebSocket and a cross-site
//!   `fetch` or form alike. `Origin: null` (a sandboxed frame, a `file:` page) is refused.
//!   Clients that are not browsers send no `Origin` and are not affected.
//! - **A request that may change something (POST, PUT, PATCH, DELETE) must say
//!   `Content-Type: application/json`** (415 `unsupported_media_type`), even with an empty
//!   body (`POST /api/v1/jobs/7/cancel`). A form or a `no-cors` fetch can only send
//!   `text/plain`, `application/x-www-form-urlencoded` or `multipart/form-data`; anything
//!   else needs a CORS preflight, which rackd never grants. This holds even if the two
//!   checks above were passed somehow.
//!
//! Decisions where the issue is silent:
//! - `Host` is checked with `421 Misdirected Request`: the request names an authority this
//!   server does not answer for, which is what 421 says (RFC 9110 15.5.20); a browser shows
//!   it as an error instead of retrying elsewhere.
//! - An `allowed_hosts` entry without a port allows that name at any port (a reverse proxy
//!   in front of rackd speaks for it on its own port, and a missing port means the
//!   scheme's); `name:port` allows exactly that port. Names are compared without case and
//!   without a trailing dot. `Host` without a port matches the built-in names when rackd
//!   listens on 80 or 443.
//! - The public routes (`/healthz`, `/readyz`, `/openapi.json`, `/docs`, the dashboard's
//!   files) are not checked: they hold nothing a page could misuse, and probes (a
//!   container's health check, a load balancer) name rackd by whatever address they use.
//! - They are made where a key would be checked (`auth::require_key`): like a missing key,
//!   they come before the 405 of a method a route lacks, and before a standby forwards.
//! - With keys configured none of this applies and nothing changes: a page cannot send
//!   the key (it is not a cookie), so the key is the defence.

use std::net::{IpAddr, SocketAddr};

use axum::extract::Request;
use axum::http::{HeaderMap, Method, StatusCode, header};

use super::error::ApiError;
use crate::config::AllowedHost;

/// The hosts keyless mode answers for (see the module doc).
#[derive(Clone, Debug)]
pub struct Hosts {
    /// The address actually bound (the listen port, after port 0 is resolved).
    listen: SocketAddr,
    /// `[server] allowed_hosts`.
    extra: Vec<AllowedHost>,
}

/// A `host[:port]` as a request names it, split without copying: the host without a
/// trailing dot (an IPv6 address in its brackets), compared without case.
#[derive(Clone, Copy, Debug)]
struct Named<'a> {
    host: &'a str,
    port: Option<u16>,
}

impl<'a> Named<'a> {
    /// `authority` split; None for anything but `host[:port]`.
    fn parse(authority: &'a str) -> Option<Named<'a>> {
        if authority.contains(['@', '/', '?', '#', ' ']) {
            return None;
        }
        let (host, port) = if authority.starts_with('[') {
            let (host, rest) = authority.split_at(authority.find(']')? + 1);
            (host, if rest.is_empty() { None } else { Some(rest.strip_prefix(':')?) })
        } else {
            match authority.rsplit_once(':') {
                Some((host, port)) => (host, Some(port)),
                None => (authority, None),
            }
        };
        let port = match port {
            Some(p) => Some(p.parse::<u16>().ok()?),
            None => None,
        };
        let host = host.strip_suffix('.').unwrap_or(host);
        (!host.is_empty()).then_some(Named { host, port })
    }

    /// The host as an address, if it is one.
    fn ip(&self) -> Option<IpAddr> {
        self.host.trim_start_matches('[').trim_end_matches(']').parse().ok()
    }

    /// Whether both name the same host at the same port (`default` where one gives none).
    fn same(&self, other: &Named<'_>, default: Option<u16>) -> bool {
        self.host.eq_ignore_ascii_case(other.host) && self.port.or(default) == other.port.or(default)
    }
}

impl Hosts {
    /// The hosts of a server bound to `listen`, with `[server] allowed_hosts`.
    pub fn new(listen: SocketAddr, allowed_hosts: &[AllowedHost]) -> Hosts {
        Hosts { listen, extra: allowed_hosts.to_vec() }
    }

    /// Whether `named` is one rackd answers for by itself or by `allowed_hosts`; `literal`
    /// also allows any IP literal at the listen port when rackd listens on every interface.
    fn allows(&self, named: Named<'_>, literal: bool) -> bool {
        let listed = |a: &AllowedHost| {
            a.name.eq_ignore_ascii_case(named.host) && (a.port.is_none() || a.port == named.port)
        };
        if self.extra.iter().any(listed) {
            return true;
        }
        let listen_port = self.listen.port();
        let at_listen_port = match named.port {
            Some(p) => p == listen_port,
            None => listen_port == 80 || listen_port == 443,
        };
        if !at_listen_port {
            return false;
        }
        let listen_ip = self.listen.ip();
        named.host.eq_ignore_ascii_case("localhost")
            || named.ip().is_some_and(|ip| {
                ip == IpAddr::from([127, 0, 0, 1])
                    || ip == IpAddr::from(std::net::Ipv6Addr::LOCALHOST)
                    || ip == listen_ip
                    || (literal && listen_ip.is_unspecified())
            })
    }

    /// Keyless mode's checks of one request (see the module doc).
    pub fn check(&self, req: &Request) -> Result<(), ApiError> {
        let authority = match req.headers().get(header::HOST) {
            Some(h) => h.to_str().ok(),
            None => req.uri().authority().map(|a| a.as_str()),
        };
        let host = authority.and_then(Named::parse);
        if !host.is_some_and(|h| self.allows(h, true)) {
            let shown = authority.map_or_else(|| "no host".to_owned(), |a| format!("{a:?}"));
            return Err(ApiError::new(
                StatusCode::MISDIRECTED_REQUEST,
                "host_not_allowed",
                format!(
                    "this rackd runs without API keys and does not answer for {shown}: use \
                     localhost or its listen address, or add the name to server.allowed_hosts"
                ),
            ));
        }
        if let Some(origin) = req.headers().get(header::ORIGIN) {
            let allowed = Origin::parse(origin.as_bytes()).is_some_and(|o| {
                host.is_some_and(|h| o.named.same(&h, Some(o.default_port)))
                    || self.allows(o.named_at_port(), false)
            });
            if !allowed {
                return Err(ApiError::new(
                    StatusCode::FORBIDDEN,
                    "origin_not_allowed",
                    format!(
                        "this rackd runs without API keys and refuses requests from the web page at {:?}; \
                         add its host to server.allowed_hosts if it is to be trusted",
                        String::from_utf8_lossy(origin.as_bytes())
                    ),
                ));
            }
        }
        if takes_body(req.method()) && !is_json(req.headers()) {
            return Err(ApiError::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported_media_type",
                format!(
                    "without API keys, a {} must be sent with `Content-Type: application/json` (even with no body)",
                    req.method()
                ),
            ));
        }
        Ok(())
    }
}

/// An `Origin` header: `http` or `https`, `://`, `host[:port]` (`null` and anything else:
/// none).
struct Origin<'a> {
    named: Named<'a>,
    /// The scheme's port, where the origin gives none.
    default_port: u16,
}

impl<'a> Origin<'a> {
    fn parse(origin: &'a [u8]) -> Option<Origin<'a>> {
        let (scheme, rest) = std::str::from_utf8(origin).ok()?.split_once("://")?;
        let default_port = if scheme.eq_ignore_ascii_case("https") {
            443
        } else if scheme.eq_ignore_ascii_case("http") {
            80
        } else {
            return None;
        };
        Some(Origin { named: Named::parse(rest)?, default_port })
    }

    /// The origin's host at its port, the scheme's if it gives none.
    fn named_at_port(&self) -> Named<'a> {
        Named { port: Some(self.named.port.unwrap_or(self.default_port)), ..self.named }
    }
}

/// Methods whose requests may carry a body that changes something.
fn takes_body(method: &Method) -> bool {
    matches!(*method, Method::POST | Method::PUT | Method::PATCH | Method::DELETE)
}

/// Whether the request says `Content-Type: application/json` (parameters allowed).
fn is_json(headers: &HeaderMap) -> bool {
    headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).is_some_and(|v| {
        v.split(';').next().is_some_and(|t| t.trim().eq_ignore_ascii_case("application/json"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hosts(listen: &str, extra: &[&str]) -> Hosts {
        Hosts::new(listen.parse().unwrap(), &extra.iter().map(|e| e.parse().unwrap()).collect::<Vec<_>>())
    }

    fn request(method: &str, host: Option<&str>, origin: Option<&str>, json: bool) -> Request {
        let mut b = Request::builder().method(method).uri("/api/v1/jobs");
        if let Some(h) = host {
            b = b.header(header::HOST, h);
        }
        if let Some(o) = origin {
            b = b.header(header::ORIGIN, o);
        }
        if json {
            b = b.header(header::CONTENT_TYPE, "application/json; charset=utf-8");
        }
        b.body(axum::body::Body::empty()).unwrap()
    }

    fn code(hosts: &Hosts, req: Request) -> Option<&'static str> {
        hosts.check(&req).err().map(|e| e.code)
    }

    #[test]
    fn the_host_must_name_rackd() {
        let h = hosts("127.0.0.1:8080", &["wcs.plant.local"]);
        for ok in [
            "localhost:8080",
            "LOCALHOST:8080",
            "127.0.0.1:8080",
            "[::1]:8080",
            "wcs.plant.local",
            "wcs.plant.local.:9",
        ] {
            assert_eq!(code(&h, request("GET", Some(ok), None, false)), None, "{ok}");
        }
        for bad in ["evil.example:8080", "localhost:8081", "127.0.0.2:8080", "10.0.0.5:8080", "localhost"] {
            assert_eq!(code(&h, request("GET", Some(bad), None, false)), Some("host_not_allowed"), "{bad}");
        }
        assert_eq!(code(&h, request("GET", None, None, false)), Some("host_not_allowed"));
        let with_port = hosts("127.0.0.1:8080", &["wcs:9000"]);
        assert_eq!(code(&with_port, request("GET", Some("wcs:9000"), None, false)), None);
        assert_eq!(code(&with_port, request("GET", Some("wcs:9001"), None, false)), Some("host_not_allowed"));
    }

    #[test]
    fn on_every_interface_an_address_literal_is_allowed_but_not_as_another_origin() {
        let h = hosts("0.0.0.0:8080", &[]);
        assert_eq!(code(&h, request("GET", Some("192.168.1.5:8080"), None, false)), None);
        assert_eq!(code(&h, request("GET", Some("rackd.lan:8080"), None, false)), Some("host_not_allowed"));
        let own = request("GET", Some("192.168.1.5:8080"), Some("http://192.168.1.5:8080"), false);
        assert_eq!(code(&h, own), None);
        let other = request("GET", Some("192.168.1.5:8080"), Some("http://192.168.1.9:8080"), false);
        assert_eq!(code(&h, other), Some("origin_not_allowed"));
    }

    #[test]
    fn the_origin_must_be_rackd_itself() {
        let h = hosts("127.0.0.1:8080", &["hmi.plant.local"]);
        let at = |origin| code(&h, request("GET", Some("127.0.0.1:8080"), Some(origin), false));
        assert_eq!(at("http://127.0.0.1:8080"), None);
        assert_eq!(at("http://localhost:8080"), None);
        assert_eq!(at("https://hmi.plant.local"), None);
        for bad in [
            "http://evil.example",
            "http://localhost:3000",
            "null",
            "file://",
            "http://127.0.0.1",
            "ftp://localhost:8080",
        ] {
            assert_eq!(at(bad), Some("origin_not_allowed"), "{bad}");
        }
        let default_port = hosts("127.0.0.1:80", &[]);
        let req = request("GET", Some("localhost"), Some("http://localhost"), false);
        assert_eq!(code(&default_port, req), None);
    }

    #[test]
    fn a_change_must_say_json() {
        let h = hosts("127.0.0.1:8080", &[]);
        for method in ["POST", "PUT", "PATCH", "DELETE"] {
            let req = request(method, Some("127.0.0.1:8080"), None, false);
            assert_eq!(code(&h, req), Some("unsupported_media_type"), "{method}");
            assert_eq!(code(&h, request(method, Some("127.0.0.1:8080"), None, true)), None, "{method}");
        }
        let plain = Request::builder()
            .method("POST")
            .uri("/api/v1/jobs/1/cancel")
            .header(header::HOST, "127.0.0.1:8080")
            .header(header::CONTENT_TYPE, "text/plain")
            .body(axum::body::Body::empty())
            .unwrap();
        assert_eq!(code(&h, plain), Some("unsupported_media_type"));
        assert_eq!(code(&h, request("GET", Some("127.0.0.1:8080"), None, false)), None);
    }
}
