//! `[server] allowed_hosts`: names a request may give in its `Host` and `Origin` when rackd
//! runs without API keys (see `api::keyless`).

use std::fmt;
use std::net::Ipv6Addr;

use serde::{Deserialize, Serialize};

/// One entry: a host name or address, and maybe a port (`wcs.plant.local`, `10.1.2.3:8080`,
/// `[fe80::1]:8080`). Without a port it is allowed at any port.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AllowedHost {
    /// The name, lowercase, without a trailing dot; an IPv6 address in brackets.
    pub name: String,
    /// The one port allowed, if given.
    pub port: Option<u16>,
}

/// An entry that is not `NAME` or `NAME:PORT`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "server.allowed_hosts: {0:?} is not a host name or address with an optional :PORT (no scheme, no path)"
)]
pub struct BadHost(pub String);

impl std::str::FromStr for AllowedHost {
    type Err = BadHost;

    fn from_str(entry: &str) -> Result<AllowedHost, BadHost> {
        let bad = || BadHost(entry.to_owned());
        let (name, port) = if let Some(rest) = entry.strip_prefix('[') {
            let (inside, after) = rest.split_once(']').ok_or_else(bad)?;
            inside.parse::<Ipv6Addr>().map_err(|_| bad())?;
            let port = match after {
                "" => None,
                p => Some(p.strip_prefix(':').ok_or_else(bad)?),
            };
            (format!("[{inside}]"), port)
        } else {
            match entry.split_once(':') {
                Some((name, port)) => (name.to_owned(), Some(port)),
                None => (entry.to_owned(), None),
            }
        };
        let name = name.trim_end_matches('.').to_ascii_lowercase();
        let label = |c: char| c.is_ascii_alphanumeric() || c == '-' || c == '.' || c == '_';
        if name.is_empty() || !(name.starts_with('[') || name.chars().all(label)) {
            return Err(bad());
        }
        let port = port.map(|p| p.parse::<u16>().map_err(|_| bad())).transpose()?;
        Ok(AllowedHost { name, port })
    }
}

impl fmt::Display for AllowedHost {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.port {
            Some(p) => write!(f, "{}:{p}", self.name),
            None => f.write_str(&self.name),
        }
    }
}

impl Serialize for AllowedHost {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// A list of entries, or one string of comma-separated entries (an environment variable
/// holds a scalar: `RACKD_SERVER__ALLOWED_HOSTS=wcs.plant.local,10.1.2.3`).
pub(super) fn list_or_commas<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<AllowedHost>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Either {
        List(Vec<String>),
        Text(String),
    }
    let entries: Vec<String> = match Either::deserialize(d)? {
        Either::List(list) => list,
        Either::Text(text) => {
            text.split(',').map(str::trim).filter(|s| !s.is_empty()).map(str::to_owned).collect()
        }
    };
    entries.iter().map(|e| e.parse().map_err(serde::de::Error::custom)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_are_names_or_addresses_with_an_optional_port() {
        let parsed = |e: &str| e.parse::<AllowedHost>().map(|h| (h.name, h.port));
        assert_eq!(parsed("WCS.plant.local."), Ok(("wcs.plant.local".into(), None)));
        assert_eq!(parsed("wcs:8443"), Ok(("wcs".into(), Some(8443))));
        assert_eq!(parsed("10.1.2.3"), Ok(("10.1.2.3".into(), None)));
        assert_eq!(parsed("[FE80::1]:8080"), Ok(("[fe80::1]".into(), Some(8080))));
        for bad in
            ["", "http://wcs", "wcs/path", "*.plant.local", "wcs:port", "user@wcs", "[nope]", "a:1:2", "wcs:"]
        {
            assert!(bad.parse::<AllowedHost>().is_err(), "{bad}");
        }
        assert_eq!("wcs:9000".parse::<AllowedHost>().unwrap().to_string(), "wcs:9000");
    }
}
