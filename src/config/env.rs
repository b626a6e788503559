//! Settings from the environment: `RACKD_<SECTION>__<KEY>` for every setting.
//!
//! Decisions:
//! - A double underscore separates the section from the key (`RACKD_SERVER__LISTEN`,
//!   `RACKD_AUTH__KEYS_FILE`), since keys have single underscores of their own. Names are
//!   read in any case. Values are numbers and `true`/`false` as such, anything else text
//!   (`RACKD_SERVER__LISTEN=0.0.0.0:8080`): every setting outside the arrays of tables is
//!   a scalar.
//! - Arrays of tables (`[[devices]]`, `[[site.aisles]]`, `[[auth.keys]]`) are not settable
//!   from the environment: an entry spread over variables would be unreadable and easy to
//!   half-override. They stay in the file; API keys can also come from `auth.keys_file`
//!   (a container secret). Such a variable is an error, not ignored.
//! - A typo must not be silently ignored: an unknown `RACKD_<SECTION>__<KEY>` is refused
//!   like an unknown key in the file, and so is a section name with a single underscore
//!   (`RACKD_SERVER_LISTEN`).
//! - `RACKD_LISTEN` and `RACKD_DATABASE`, which before issue 13 overrode `server.listen`
//!   and `database.path` from anywhere (an image's `ENV` silently beat a mounted config),
//!   are refused with the new name, so that a forgotten variable cannot quietly decide
//!   where rackd listens or writes. `--listen` and `--database` stay as flags.
//! - Variables without a double underscore are the command line's own (`RACKD_CONFIG`,
//!   `RACKD_LOG`, `RACKD_LOG_FORMAT`, `RACKD_HEALTHCHECK_URL`) and are not settings.
//!
//! Why not figment's own `figment::providers::Env` (figment 0.10.19, `env` feature), which
//! also strips a prefix, splits on `__`, lowercases and parses values. It would replace
//! [`scalar`] and [`insert`], not the checks, and it does not fit around them:
//! - it reads `std::env::vars_os()` itself and takes no list, while the loader takes the
//!   variables as data (`Sources::env`): the configuration tests give theirs that way,
//!   side by side, without touching the process environment (setting a variable is
//!   `unsafe` in edition 2024, which the lints forbid);
//! - the checks need each variable as it was written (the retired names, the suggestion
//!   that keeps the variable's own case, `env RACKD_SERVER__LISTEN` as the origin in
//!   messages), and `Env` hands over only the lowercased key; its filters cannot fail, so
//!   the checks would walk the raw variables anyway;
//! - it drops, silently, a variable with an empty segment (`RACKD_SERVER____LISTEN`), which
//!   is refused here as an unknown key;
//! - its value parser reads more than scalars, so a value would set something else: text
//!   starting with `[`, `{`, `"` or `'` becomes an array, a table, a string without its
//!   quotes or a character, text is trimmed, and `1e3` stays text;
//! - the `env` feature brings pear, pear_codegen (a proc macro), proc-macro2-diagnostics,
//!   inlinable_string and yansi, none of them in the build today.

use figment::value::{Dict, Map, Value};
use figment::{Metadata, Profile, Provider};

/// The prefix of rackd's variables.
pub const PREFIX: &str = "RACKD_";

/// The sections a variable may name.
const SECTIONS: [&str; 10] =
    ["server", "database", "intake", "auth", "site", "events", "retention", "cluster", "devices", "webhooks"];

/// Keys that are arrays of tables, not settable from the environment.
const ARRAYS: [&str; 4] = ["devices", "site.aisles", "auth.keys", "webhooks"];

/// A variable rackd refuses.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EnvError {
    /// A name from before issue 13.
    #[error("{var} is no longer read (it silently overrode the config file): set {instead} or pass {flag}")]
    Retired {
        /// The variable.
        var: String,
        /// The variable to use.
        instead: &'static str,
        /// The flag to use.
        flag: &'static str,
    },
    /// A section and key joined by one underscore.
    #[error("{var}: a section and its key are joined by two underscores, as in {suggestion}")]
    SingleUnderscore {
        /// The variable.
        var: String,
        /// The spelling meant.
        suggestion: String,
    },
    /// An array of tables.
    #[error("{var}: {key} is an array of tables and only comes from the file{hint}")]
    Array {
        /// The variable.
        var: String,
        /// The key it names.
        key: &'static str,
        /// Where else it can come from.
        hint: &'static str,
    },
}

/// The `RACKD_` variables of this process.
pub fn process_vars() -> Vec<(String, String)> {
    std::env::vars_os()
        .filter_map(|(k, v)| Some((k.into_string().ok()?, v.to_string_lossy().into_owned())))
        .filter(|(k, _)| k.starts_with(PREFIX))
        .collect()
}

/// The settings among `vars`, as (variable, dotted key, value); refuses the variables
/// described in the module documentation.
pub fn settings(vars: &[(String, String)]) -> Result<Vec<(String, String, String)>, EnvError> {
    let mut out = Vec::new();
    for (var, value) in vars {
        let Some(rest) = var.strip_prefix(PREFIX) else { continue };
        let retired = match rest {
            "LISTEN" => Some(("RACKD_SERVER__LISTEN", "--listen")),
            "DATABASE" => Some(("RACKD_DATABASE__PATH", "--database")),
            _ => None,
        };
        if let Some((instead, flag)) = retired {
            return Err(EnvError::Retired { var: var.clone(), instead, flag });
        }
        let lower = rest.to_ascii_lowercase();
        if !lower.contains("__") {
            if let Some(section) = SECTIONS.iter().find(|s| lower.starts_with(&format!("{s}_"))) {
                let suggestion =
                    format!("{PREFIX}{}__{}", section.to_uppercase(), &rest[section.len() + 1..]);
                return Err(EnvError::SingleUnderscore { var: var.clone(), suggestion });
            }
            continue;
        }
        let key = lower.replace("__", ".");
        if let Some(array) = ARRAYS.iter().find(|a| key == **a || key.starts_with(&format!("{a}."))) {
            let hint = if *array == "auth.keys" { " or auth.keys_file" } else { "" };
            return Err(EnvError::Array { var: var.clone(), key: array, hint });
        }
        out.push((var.clone(), key, value.clone()));
    }
    Ok(out)
}

/// The variable that sets `key` (`server.listen` is `RACKD_SERVER__LISTEN`).
pub fn var_for(key: &str) -> String {
    format!("{PREFIX}{}", key.replace('.', "__").to_ascii_uppercase())
}

/// The environment as a figment layer.
pub struct EnvLayer(pub Vec<(String, String, String)>);

impl Provider for EnvLayer {
    fn metadata(&self) -> Metadata {
        Metadata::named("environment").interpolater(|_: &Profile, keys: &[&str]| var_for(&keys.join(".")))
    }

    fn data(&self) -> Result<Map<Profile, Dict>, figment::Error> {
        let mut dict = Dict::new();
        for (_, key, value) in &self.0 {
            let parts: Vec<&str> = key.split('.').collect();
            insert(&mut dict, &parts, scalar(value));
        }
        Ok(Profile::Default.collect(dict))
    }
}

/// A variable's text as a value: an integer, a number, `true`/`false`, or else the text.
/// Every setting the environment may set is a scalar, so nothing else is needed.
fn scalar(text: &str) -> Value {
    let t = text.trim();
    if let Ok(n) = t.parse::<u64>() {
        Value::from(n)
    } else if let Ok(n) = t.parse::<i64>() {
        Value::from(n)
    } else if let Ok(x) = t
        .parse::<f64>()
        .map_err(|_| ())
        .and_then(|x| if t.contains(['.', 'e', 'E']) && x.is_finite() { Ok(x) } else { Err(()) })
    {
        Value::from(x)
    } else if let Ok(b) = t.parse::<bool>() {
        Value::from(b)
    } else {
        Value::from(text.to_owned())
    }
}

/// Puts `value` at the dotted `parts` of `dict`, making the tables on the way.
pub fn insert(dict: &mut Dict, parts: &[&str], value: Value) {
    match parts {
        [] => {}
        [last] => {
            dict.insert((*last).to_owned(), value);
        }
        [first, rest @ ..] => {
            let entry = dict.entry((*first).to_owned()).or_insert_with(|| Value::from(Dict::new()));
            if !matches!(entry, Value::Dict(..)) {
                *entry = Value::from(Dict::new());
            }
            if let Value::Dict(_, inner) = entry {
                insert(inner, rest, value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars(list: &[(&str, &str)]) -> Vec<(String, String)> {
        list.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
    }

    #[test]
    fn sections_and_keys_are_joined_by_two_underscores() {
        let got = settings(&vars(&[
            ("RACKD_SERVER__LISTEN", "0.0.0.0:1"),
            ("RACKD_AUTH__KEYS_FILE", "/run/secrets/k"),
            ("RACKD_LOG_FORMAT", "json"),
            ("RACKD_CONFIG", "x.toml"),
            ("PATH", "/bin"),
        ]))
        .unwrap();
        let keys: Vec<_> = got.iter().map(|(_, k, _)| k.as_str()).collect();
        assert_eq!(keys, ["server.listen", "auth.keys_file"]);
        assert_eq!(var_for("intake.queue"), "RACKD_INTAKE__QUEUE");
    }

    #[test]
    fn old_names_typos_and_arrays_are_refused() {
        let err = settings(&vars(&[("RACKD_LISTEN", "0.0.0.0:1")])).unwrap_err().to_string();
        assert!(err.contains("RACKD_SERVER__LISTEN") && err.contains("--listen"), "{err}");
        let err = settings(&vars(&[("RACKD_DATABASE", "x")])).unwrap_err().to_string();
        assert!(err.contains("RACKD_DATABASE__PATH"), "{err}");
        let err = settings(&vars(&[("RACKD_SERVER_LISTEN", "x")])).unwrap_err();
        assert_eq!(
            err,
            EnvError::SingleUnderscore {
                var: "RACKD_SERVER_LISTEN".into(),
                suggestion: "RACKD_SERVER__LISTEN".into()
            }
        );
        let err = settings(&vars(&[("RACKD_DEVICES__0__ADDRESS", "x")])).unwrap_err().to_string();
        assert!(err.contains("devices is an array of tables"), "{err}");
        let err = settings(&vars(&[("RACKD_AUTH__KEYS", "[]")])).unwrap_err().to_string();
        assert!(err.contains("auth.keys_file"), "{err}");
        let err = settings(&vars(&[("RACKD_WEBHOOKS__0__URL", "x")])).unwrap_err().to_string();
        assert!(err.contains("webhooks is an array of tables"), "{err}");
        let err = settings(&vars(&[("RACKD_RETENTION_JOBS_DAYS", "9")])).unwrap_err().to_string();
        assert!(err.contains("RACKD_RETENTION__JOBS_DAYS"), "{err}");
    }
}
