//! Secrets out of what rackd prints: [`url`], the one function every message, log line,
//! `check-config --explain` line and API answer that shows a URL goes through (a database
//! URL, a webhook's `url` and `proxy`, `cluster.url`, `rackd healthcheck --url`).
//!
//! Decisions:
//! - **The password of the user part** (`postgres://rackd:***@db/rackd`), whatever
//!   characters it holds: everything from the first `:` of the user part up to the last `@`
//!   before the query. Only the user's name stays.
//! - **A malformed URL is redacted too**, since it is mostly printed *because* it is
//!   malformed: without `://` (`postgres//u:SECRET@host/db`, `postgres:u:SECRET@host`) the
//!   text up to the last `@` is taken as the user part; with no `@` at all, in a URL with
//!   `://`, a "port" that is not a number (`postgres://u:SECRET/db`, an `@` forgotten) is
//!   shown as `***`. Too
//!   much hidden in a URL that was wrong anyway costs nothing; too little leaks.
//! - **Secret query parameters**: the value of a parameter of the query (or of the
//!   fragment, where OAuth's implicit flow puts `access_token`) is `***` when its name,
//!   percent-decoded, lowercased and with `-` read as `_`, is one of [`SECRET_KEYS`]
//!   (`code`, `sig`, `key`, ...) or contains one of [`SECRET_PARTS`] (`token`, `secret`,
//!   `passw`, `signature`, ...): so `?token=`, `?access_token=`, `?X-Amz-Signature=`,
//!   `?client_secret=`, `?password=` (libpq's), `?sslpassword=`, `?api-key=`. Other
//!   parameters are shown: `sslmode`, `sslrootcert` (a path) and the like are what a reader
//!   of an error needs.
//! - Nothing else is touched (host, path, port): they say where, not how to get in.

/// Query parameter names whose value is a secret, as a whole name (after lowercasing, `-`
/// read as `_`).
pub const SECRET_KEYS: &[&str] = &["code", "sig", "key", "auth", "pass", "pwd", "session", "sessionid"];

/// Parts of a query parameter's name that make its value a secret, wherever they are in
/// the name (after lowercasing, `-` read as `_`).
pub const SECRET_PARTS: &[&str] =
    &["token", "secret", "passw", "signature", "api_key", "apikey", "credential", "authorization"];

/// `text`, a URL (or what was meant as one), with its secrets replaced by `***`: the
/// password of its user part, and the values of its secret query parameters (see the
/// module documentation).
pub fn url(text: &str) -> String {
    let (text, fragment) = match text.split_once('#') {
        Some((t, f)) => (t, Some(f)),
        None => (text, None),
    };
    let (before_query, query) = match text.split_once('?') {
        Some((b, q)) => (b, Some(q)),
        None => (text, None),
    };
    let (scheme, rest) = match before_query.split_once("://") {
        Some((scheme, rest)) => (Some(scheme), rest),
        None => (None, before_query),
    };
    let mut out = scheme.map(|s| format!("{s}://")).unwrap_or_default();
    match rest.rsplit_once('@') {
        Some((user, host)) => match user.split_once(':') {
            Some((name, _)) => out.push_str(&format!("{name}:***@{host}")),
            None => out.push_str(rest),
        },
        // Only in a URL: `sqlite:data/rackd.db` is a path, not a host and a port.
        None if scheme.is_some() => out.push_str(&without_word_port(rest)),
        None => out.push_str(rest),
    }
    if let Some(query) = query {
        out.push('?');
        out.push_str(&pairs(query));
    }
    if let Some(fragment) = fragment {
        out.push('#');
        out.push_str(&pairs(fragment));
    }
    out
}

/// `host:port/path` with a port that is not a number (most likely a password whose `@`
/// was forgotten) as `***`.
fn without_word_port(rest: &str) -> String {
    let end = rest.find('/').unwrap_or(rest.len());
    let (authority, path) = rest.split_at(end);
    // `[::1]:5432`: the colons inside the brackets are the address's.
    let after_brackets = authority.rfind(']').map_or(0, |i| i + 1);
    match authority[after_brackets..].find(':').map(|i| i + after_brackets) {
        Some(colon) if !authority[colon + 1..].bytes().all(|b| b.is_ascii_digit()) => {
            format!("{}:***{path}", &authority[..colon])
        }
        _ => rest.to_owned(),
    }
}

/// `a=1&token=x` with each secret parameter's value as `***`, the rest as written.
fn pairs(query: &str) -> String {
    let pairs: Vec<String> = query
        .split('&')
        .map(|pair| match pair.split_once('=') {
            Some((key, _)) if secret_key(key) => format!("{key}=***"),
            _ => pair.to_owned(),
        })
        .collect();
    pairs.join("&")
}

/// Whether a query parameter of this name (as written, percent-encoded) holds a secret.
pub fn secret_key(key: &str) -> bool {
    let decoded: String = form_urlencoded::parse(key.as_bytes()).map(|(k, _)| k.into_owned()).collect();
    let name = decoded.to_ascii_lowercase().replace('-', "_");
    SECRET_KEYS.contains(&name.as_str()) || SECRET_PARTS.iter().any(|part| name.contains(part))
}

#[cfg(test)]
mod tests {
    use super::url;

    #[test]
    fn the_password_of_the_user_part_is_hidden() {
        assert_eq!(url("postgres://h/db"), "postgres://h/db");
        assert_eq!(url("postgres://u@h/db"), "postgres://u@h/db");
        assert_eq!(url("postgres://rackd:s3@db:5432/rackd"), "postgres://rackd:***@db:5432/rackd");
        // Characters a password should have escaped.
        assert_eq!(url("postgres://u:p/a@ss@h/db?x=1"), "postgres://u:***@h/db?x=1");
        assert_eq!(url("https://u:p:q@wms.plant/events"), "https://u:***@wms.plant/events");
    }

    #[test]
    fn a_malformed_url_keeps_its_secret() {
        assert_eq!(url("postgres//u:SECRET@host/db"), "postgres//u:***@host/db");
        assert_eq!(url("postgres:u:SECRET@host/db"), "postgres:***@host/db");
        assert_eq!(url("postgres://u:SECRET/db"), "postgres://u:***/db");
        assert_eq!(url("postgres://db.plant:5432/rackd"), "postgres://db.plant:5432/rackd");
        assert_eq!(url("http://[::1]:8080/x"), "http://[::1]:8080/x");
        assert_eq!(url("data/rackd.db"), "data/rackd.db");
        assert_eq!(url("sqlite:data/rackd.db"), "sqlite:data/rackd.db");
        for text in ["postgres//u:SECRET@host/db", "mysql://u:SECRET@h", "http://u:SECRET", "x@y:SECRET@h"] {
            assert!(!url(text).contains("SECRET"), "{text}: {}", url(text));
        }
    }

    #[test]
    fn secret_query_parameters_are_hidden_and_the_others_shown() {
        assert_eq!(
            url("postgres://u@h/db?password=s3&sslmode=require"),
            "postgres://u@h/db?password=***&sslmode=require"
        );
        assert_eq!(
            url("https://wms.plant/events?token=T&site=north&code=C&sig=S"),
            "https://wms.plant/events?token=***&site=north&code=***&sig=***"
        );
        for key in [
            "access_token",
            "X-Amz-Signature",
            "X-Amz-Security-Token",
            "client_secret",
            "api-key",
            "apiKey",
            "key",
            "sslpassword",
            "pass%77ord",
            "Signature",
        ] {
            let shown = url(&format!("https://h/p?{key}=SECRET&a=1"));
            assert_eq!(shown, format!("https://h/p?{key}=***&a=1"), "{key}");
        }
        for key in ["sslmode", "sslrootcert", "keyword", "site", "codec"] {
            assert_eq!(url(&format!("https://h/p?{key}=v")), format!("https://h/p?{key}=v"), "{key}");
        }
        assert_eq!(url("https://h/cb#access_token=T&state=1"), "https://h/cb#access_token=***&state=1");
    }
}
