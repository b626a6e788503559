//! `rackd check-config FILE --explain`: the effective configuration, every key, as TOML,
//! each value followed by where it came from.
//!
//! The output reads back as the same configuration (less `auth.keys_file`, whose keys are
//! shown among `[[auth.keys]]`, and `database.url_file`, whose URL is shown as
//! `database.url` with the file as its origin): devices are written in the file's flat
//! form with every key of their kind, defaults included. A setting that is absent
//! (`serial` on a network protocol, `auth.keys_file` when unset) is left out.
//!
//! Secrets are not printed: the password of a database URL (and of any URL with one, such
//! as `cluster.url`, a webhook's `url` and `proxy`) is shown as `***`, as are the values of
//! a URL's secret query parameters (`?token=`, `?code=`, `?sig=`: [`crate::redact`]), and a
//! webhook's whole `secret` (`secret_file`, a path, is shown). Keys are only ever configured as their
//! hashes, which are not secrets (a key cannot be found from its hash), and are shown. So an
//! output with a webhook's inline `secret` reads back only once the secret is put back.

use std::fmt::Write;

use super::Loaded;

impl Loaded {
    /// The effective configuration as commented TOML.
    pub fn explain(&self) -> String {
        let mut config = self.config.clone();
        config.auth.keys_file = None;
        config.database.url_file = None;
        let urls = [config.database.url.as_mut(), config.cluster.as_mut().and_then(|c| c.url.as_mut())];
        for url in urls.into_iter().flatten() {
            *url = crate::redact::url(url);
        }
        for webhook in &mut config.webhooks {
            webhook.url = crate::redact::url(&webhook.url);
            if let Some(proxy) = &mut webhook.proxy {
                *proxy = crate::redact::url(proxy);
            }
            if let Some(secret) = &mut webhook.secret {
                *secret = "***".into();
            }
        }
        let value = toml::Value::try_from(&config).expect("a loaded configuration serializes");
        let mut out = String::new();
        if let toml::Value::Table(table) = value {
            self.table(&mut out, "", "", &table);
        }
        out
    }

    /// Writes `table`, at key path `path` (`devices[0]`) under TOML header `header`.
    fn table(&self, out: &mut String, path: &str, header: &str, table: &toml::Table) {
        let key_path = |key: &str| if path.is_empty() { key.to_owned() } else { format!("{path}.{key}") };
        let toml_path = |key: &str| {
            let key = bare_or_quoted(key);
            if header.is_empty() { key } else { format!("{header}.{key}") }
        };
        // A device's tags are one line each, as the example file writes them.
        let inline =
            |value: &toml::Value| !is_table(value) && !is_array_of_tables(value) || is_tag_table(path);
        for (key, value) in table.iter().filter(|(_, v)| inline(v)) {
            self.line(out, &key_path(key), &bare_or_quoted(key), value);
        }
        for (key, value) in table.iter().filter(|(_, v)| !inline(v)) {
            match value {
                toml::Value::Table(inner) => {
                    let _ = writeln!(out, "\n[{}]", toml_path(key));
                    self.table(out, &key_path(key), &toml_path(key), inner);
                }
                toml::Value::Array(items) => {
                    for (i, item) in items.iter().enumerate() {
                        let _ = writeln!(out, "\n[[{}]]", toml_path(key));
                        if let toml::Value::Table(inner) = item {
                            self.table(out, &format!("{}[{i}]", key_path(key)), &toml_path(key), inner);
                        }
                    }
                }
                _ => {}
            }
        }
    }

    fn line(&self, out: &mut String, path: &str, key: &str, value: &toml::Value) {
        let text = format!("{key} = {value}");
        let _ = writeln!(out, "{text:<40} # {}", self.origin(path));
    }
}

/// Whether `path` is a device's `tags` table.
fn is_tag_table(path: &str) -> bool {
    path.starts_with("devices[") && path.ends_with("].tags")
}

fn is_table(value: &toml::Value) -> bool {
    matches!(value, toml::Value::Table(_))
}

fn is_array_of_tables(value: &toml::Value) -> bool {
    matches!(value, toml::Value::Array(items) if !items.is_empty() && items.iter().all(is_table))
}

/// A key as TOML writes it: bare when it can be, quoted otherwise.
fn bare_or_quoted(key: &str) -> String {
    if !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        key.to_owned()
    } else {
        toml::Value::String(key.to_owned()).to_string()
    }
}
