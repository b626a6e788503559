//! API keys and roles.
//!
//! Keys are long random tokens, so they are stored as a plain SHA-256 hash (`sha256:<hex>`):
//! a slow password hash would protect nothing more for a 32-byte random key and would cost
//! milliseconds on every request. `rackd hash-key` prints the hash of a key, and with
//! `--generate` makes a new random key first.
//!
//! Keys come from `[[auth.keys]]` in the configuration and from `auth.keys_file`, a TOML
//! file of the same `[[keys]]` entries (`name`, `role`, `hash`) for a container secret
//! (`/run/secrets/rackd_keys`); the configuration merges both, refusing a name or a hash
//! that appears twice, and a keys file that names no key (most likely the wrong file).
//!
//! The [`KeyRing`] is what `[auth]` sets at run time, the keys and the failed-key limit
//! together: a reload (`service::reload`) builds a new one and swaps it whole, so a request
//! is checked against one ring from start to end, and a key removed from the file is
//! refused from the next request on.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Duration;

use rand::RngCore;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// `[auth]`: the API keys. Auth owns its configuration section, so the configuration
/// module depends on auth and never the other way round.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct AuthConfig {
    /// Unknown keys one client address may present within `failure_window_secs` before its
    /// requests are answered 429 until the window ends (0: no limit). See `api::failures`.
    pub max_failures: u32,
    /// The window of `max_failures`, in seconds, from an address's first failure.
    pub failure_window_secs: u64,
    /// A TOML file of more `[[keys]]` entries, relative to the working directory like
    /// `database.path`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub keys_file: Option<PathBuf>,
    /// The API keys, stored hashed (`rackd hash-key` prints a hash). Once loaded, those of
    /// `keys_file` too.
    pub keys: Vec<KeyConfig>,
}

/// The largest `auth.max_failures`: the limiter keeps a fingerprint of each unknown key
/// counted, per address (`api::failures`), so this bounds its memory.
pub const MOST_FAILURES: u32 = 100;

impl Default for AuthConfig {
    fn default() -> Self {
        AuthConfig { max_failures: 10, failure_window_secs: 60, keys_file: None, keys: Vec::new() }
    }
}

/// The contents of an `auth.keys_file`: `[[keys]]` entries as in `[[auth.keys]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeysFile {
    /// The keys.
    #[serde(default)]
    pub keys: Vec<KeyConfig>,
}

impl KeysFile {
    /// Reads a keys file's text; the error carries the position of the problem.
    pub fn parse(text: &str) -> Result<KeysFile, toml::de::Error> {
        toml::from_str(text)
    }
}

/// The first key (by index) whose name or hash an earlier key has, with that earlier
/// key's index and which of the two repeats (`"name"` or `"hash"`).
pub fn repeated_key(keys: &[KeyConfig]) -> Option<(usize, usize, &'static str)> {
    keys.iter().enumerate().skip(1).find_map(|(j, k)| {
        keys[..j].iter().enumerate().find_map(|(i, earlier)| {
            (earlier.name == k.name)
                .then_some((j, i, "name"))
                .or_else(|| (earlier.hash == k.hash).then_some((j, i, "hash")))
        })
    })
}

/// One `[[auth.keys]]` entry.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct KeyConfig {
    /// Who holds the key, for logs.
    pub name: String,
    /// `viewer`, `operator` or `admin`.
    pub role: Role,
    /// `sha256:` and the hex SHA-256 of the key.
    pub hash: KeyHash,
}

/// What a key may do. Each role includes the ones before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Reads: jobs, devices, locations, alarms, metrics, the WebSocket.
    Viewer,
    /// Viewer, plus submitting, changing and cancelling jobs.
    Operator,
    /// Everything, device maintenance included.
    Admin,
}

impl Role {
    /// The role's name as the configuration writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Viewer => "viewer",
            Role::Operator => "operator",
            Role::Admin => "admin",
        }
    }
}

/// The stored form of a key: `sha256:` followed by 64 hex digits.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Deserialize)]
#[serde(try_from = "String")]
pub struct KeyHash([u8; 32]);

impl KeyHash {
    /// The hash of a key as presented by a client.
    pub fn of(key: &str) -> KeyHash {
        KeyHash(Sha256::digest(key.as_bytes()).into())
    }
}

impl Serialize for KeyHash {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl std::fmt::Display for KeyHash {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "sha256:{}", hex::encode(self.0))
    }
}

/// Text that is not a key hash.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KeyHashError {
    /// Another algorithm, or a key itself.
    #[error("a key hash starts with `sha256:` (see `rackd hash-key`)")]
    Prefix,
    /// Not 64 hex digits after the prefix.
    #[error("a key hash is `sha256:` and 64 hex digits")]
    Digits,
}

impl TryFrom<String> for KeyHash {
    type Error = KeyHashError;
    fn try_from(text: String) -> Result<Self, KeyHashError> {
        let hex_part = text.strip_prefix("sha256:").ok_or(KeyHashError::Prefix)?;
        let mut bytes = [0u8; 32];
        hex::decode_to_slice(hex_part, &mut bytes).map_err(|_| KeyHashError::Digits)?;
        Ok(KeyHash(bytes))
    }
}

/// The fewest characters `rackd hash-key` accepts in a key.
///
/// Keys are stored as plain SHA-256 (see the module documentation), so a key is as strong
/// as it is long and random: whoever reads a configuration file can try billions of
/// candidates a second against its hashes. 16 characters from a random source are over
/// 90 bits, beyond any such search; a short or human-chosen key is not, and a one-letter
/// key is a typo. `--generate` makes 67 (`rk_` and 64 hex digits, 256 bits).
pub const MIN_KEY_LEN: usize = 16;

/// Whether `key` may become an API key: not empty, at least [`MIN_KEY_LEN`] characters.
pub fn acceptable_key(key: &str) -> Result<(), String> {
    match key.chars().count() {
        0 => Err("no key on standard input (rackd hash-key < FILE, or --generate for a new one)".into()),
        n if n < MIN_KEY_LEN => Err(format!(
            "a key of {n} characters is too short: keys are at least {MIN_KEY_LEN} characters \
             (rackd hash-key --generate makes a strong one)"
        )),
        _ => Ok(()),
    }
}

/// A new random key: 32 random bytes, hex-encoded, prefixed `rk_` so it is easy to spot.
pub fn generate_key() -> String {
    let mut bytes = [0u8; 32];
    rand::rng().fill_bytes(&mut bytes);
    format!("rk_{}", hex::encode(bytes))
}

/// The holder of a key, once recognised.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Principal {
    /// The key's name from the configuration.
    pub name: String,
    /// What it may do.
    pub role: Role,
    /// The key's hash, by which a session opened with it learns that a reload removed it.
    pub hash: KeyHash,
}

/// `auth.max_failures` unknown keys per client address within `auth.failure_window_secs`
/// (`api::failures`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FailureLimit {
    /// Unknown keys before the address is held off (0: no limit).
    pub max: u32,
    /// From the address's first failure.
    pub window: Duration,
}

/// The configured keys, by hash, and the failed-key limit: `[auth]` as it runs.
#[derive(Clone, Debug)]
pub struct KeyRing {
    keys: HashMap<KeyHash, Principal>,
    limit: FailureLimit,
}

impl KeyRing {
    /// The key ring `auth` sets (its keys, those of `keys_file` merged in by the loader).
    pub fn new(auth: &AuthConfig) -> Self {
        let principal =
            |k: &KeyConfig| Principal { name: k.name.clone(), role: k.role, hash: k.hash.clone() };
        let keys = auth.keys.iter().map(|k| (k.hash.clone(), principal(k))).collect();
        let limit =
            FailureLimit { max: auth.max_failures, window: Duration::from_secs(auth.failure_window_secs) };
        KeyRing { keys, limit }
    }

    /// Whether no key is configured (then the server only serves loopback, unauthenticated).
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Who holds `key`, if anyone.
    pub fn identify(&self, key: &str) -> Option<&Principal> {
        self.keys.get(&KeyHash::of(key))
    }

    /// Whether the key of hash `hash` is still one of the ring's.
    pub fn holds(&self, hash: &KeyHash) -> bool {
        self.keys.contains_key(hash)
    }

    /// The failed-key limit.
    pub fn limit(&self) -> FailureLimit {
        self.limit
    }
}

impl Default for KeyRing {
    fn default() -> Self {
        KeyRing::new(&AuthConfig::default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_round_trips_through_text() {
        let h = KeyHash::of("secret");
        assert_eq!(KeyHash::try_from(h.to_string()).unwrap(), h);
        assert!(h.to_string().ends_with("2bb80d537b1da3e38bd30361aa855686bde0eacd7162fef6a25fe97bf527a25b"));
        assert!(KeyHash::try_from("md5:00".to_string()).is_err());
        assert!(KeyHash::try_from("sha256:zz".to_string()).is_err());
    }

    #[test]
    fn a_keys_file_has_the_entries_of_auth_keys_and_repeats_are_found() {
        let text = "[[keys]]\nname = \"a\"\nrole = \"admin\"\nhash = \"sha256:00\"\n";
        let err = KeysFile::parse(text).unwrap_err();
        assert!(err.message().contains("sha256:"), "{err}");
        let hash = KeyHash::of("k");
        let key = |name: &str, hash: &KeyHash| KeyConfig {
            name: name.into(),
            role: Role::Viewer,
            hash: hash.clone(),
        };
        let other = KeyHash::of("other");
        assert_eq!(repeated_key(&[key("a", &hash), key("b", &other)]), None);
        assert_eq!(
            repeated_key(&[key("a", &hash), key("b", &other), key("a", &KeyHash::of("x"))]),
            Some((2, 0, "name"))
        );
        assert_eq!(repeated_key(&[key("a", &hash), key("b", &hash)]), Some((1, 0, "hash")));
    }

    #[test]
    fn roles_are_ordered() {
        assert!(Role::Admin > Role::Operator && Role::Operator > Role::Viewer);
    }

    #[test]
    fn generated_keys_differ() {
        assert_ne!(generate_key(), generate_key());
    }
}
