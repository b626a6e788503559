//! The difference between the running configuration and a new one, as a reload sees it
//! (issue 43): which devices are added, removed or changed (and in which keys), which
//! aisles are added, removed or resized, which API keys are added, removed or changed (and
//! the other `[auth]` keys that changed), and which keys cannot change while rackd runs.
//!
//! Decisions:
//! - Devices are matched by `id`, aisles by their number and API keys by their `name`, not
//!   by their place in the file: moving an entry, or adding one before it, is no change. A
//!   key renamed is one removed and one added.
//! - A device's keys are those of its flat form ([`RawDevice`], every key of its kind
//!   filled in), so a key set to its default in one file and left out in the other is no
//!   change, and a new default in the code never reads as a change of the file.
//! - Lists (a device's `aisles`, `quirks`; `webhooks`) are compared whole and named by
//!   their key: "which entry" says less than "this list" to the one reloading.
//! - `[[devices]]`, `[site]` and `[auth]` change at run time (`[auth]` since issue 51: a
//!   leaked key is revoked by a reload, not a restart). Every other key that changed is
//!   listed in `fixed`, and a reload with any is refused whole: the listen address, the
//!   database and the cluster node because the process holds them open (a socket, a pool,
//!   a lease row); the rest (`webhooks`, `[events]`, ...) because the parts that read them
//!   read them once, at start. Restarting is how they change; a takeover in a cluster is
//!   one.
//! - Only names are reported, never values: `database.url` and the keys' hashes are
//!   secrets, and a name is what the reader looks up in the file. An API key is named by
//!   its `name`, with `role` or `hash` when those changed; never by its hash.

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;

use super::Config;
use super::devices::RawDevice;

/// What a `config_reload` alarm (a refused reload on SIGHUP) asks a person to do.
pub const RELOAD_ACTION: &str = "Fix the configuration file (rackd check-config --config FILE says what is \
     wrong, as the alarm does), then reload again (SIGHUP, or POST /api/v1/config/reload); until then the \
     configuration that ran before runs on, its API keys included.";

/// What a reload would change.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, ToSchema)]
pub struct Difference {
    /// Devices added, removed or changed, in the running file's order (then the added
    /// ones in the new file's order).
    pub devices: Vec<DeviceChange>,
    /// Aisles of `[site]`.
    pub aisles: AisleChanges,
    /// `[auth]`: API keys and the failed-key limit.
    pub auth: AuthChanges,
    /// Keys outside `[[devices]]`, `[site]` and `[auth]` that changed: they cannot change
    /// while rackd runs, and a reload with any is refused whole.
    pub fixed: Vec<String>,
}

/// What changes in `[auth]`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, ToSchema)]
pub struct AuthChanges {
    /// API keys added, removed or changed, by name, in the running file's order (then the
    /// added ones in the new file's order).
    pub keys: Vec<KeyChange>,
    /// Other `[auth]` keys that changed (`auth.max_failures`, `auth.failure_window_secs`,
    /// `auth.keys_file`).
    pub settings: Vec<String>,
}

/// One API key's change: its name, never the key or its hash.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, ToSchema)]
#[schema(example = json!({"name": "wms", "change": "changed", "fields": ["hash"]}))]
pub struct KeyChange {
    /// The key's `name`.
    pub name: String,
    /// Added (valid from now on), removed (refused from now on) or changed.
    pub change: Change,
    /// For a changed key: `role`, `hash` or both.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub fields: Vec<String>,
}

impl AuthChanges {
    /// Whether `[auth]` does not change.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty() && self.settings.is_empty()
    }
}

/// One device's change.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, ToSchema)]
pub struct DeviceChange {
    /// The device's id.
    pub id: String,
    /// Added, removed or changed.
    pub change: Change,
    /// For a changed device: its keys that changed (`address`, `timeout_ms`, ...).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub keys: Vec<String>,
}

/// What happens to a device (or an API key).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Change {
    /// In the new file only: started (a key: valid).
    Added,
    /// In the running file only: stopped (a key: refused).
    Removed,
    /// In both, with other settings: restarted (a key: its new role or hash holds).
    Changed,
}

/// The aisles of `[site]` that change.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, ToSchema)]
pub struct AisleChanges {
    /// Numbers of aisles in the new file only.
    pub added: Vec<u16>,
    /// Numbers of aisles in the running file only.
    pub removed: Vec<u16>,
    /// Aisles in both, of another size or depth.
    pub changed: Vec<AisleChange>,
}

/// One aisle's change.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, ToSchema)]
pub struct AisleChange {
    /// The aisle's number.
    pub aisle: u16,
    /// Its keys that changed (`bays`, `depth`, ...).
    pub keys: Vec<String>,
}

/// Which configuration runs: the hash of its `[site]` and `[[devices]]`
/// ([`Config::site_hash`]) and when it was loaded (the start, or the last reload).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, ToSchema)]
pub struct RunningConfig {
    /// SHA-256 of `[site]` and `[[devices]]`, in hex.
    #[schema(example = "9f2c4e0d3b8a7f61e5d2c9b0a4f7e3d1c8b6a5f4e3d2c1b0a9f8e7d6c5b4a3f2")]
    pub hash: String,
    /// When it was loaded.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub loaded_at: time::OffsetDateTime,
}

impl RunningConfig {
    /// `config`, loaded now.
    pub fn now(config: &Config) -> RunningConfig {
        let now = crate::domain::time::from_ms(crate::domain::time::now_ms());
        RunningConfig { hash: config.site_hash(), loaded_at: now }
    }
}

impl Difference {
    /// Whether nothing changes.
    pub fn is_empty(&self) -> bool {
        self == &Difference::default()
    }
}

impl Config {
    /// What changes from this (running) configuration to `new`.
    pub fn difference(&self, new: &Config) -> Difference {
        let devices = device_changes(self, new);
        let aisles = aisle_changes(self, new);
        let auth = auth_changes(self, new);
        let (mut old_rest, mut new_rest) = (json(self), json(new));
        for rest in [&mut old_rest, &mut new_rest] {
            if let Value::Object(map) = rest {
                map.remove("devices");
                map.remove("site");
                map.remove("auth");
            }
        }
        let mut fixed = Vec::new();
        leaves("", &old_rest, &new_rest, &mut fixed);
        Difference { devices, aisles, auth, fixed }
    }

    /// The hash of what a reload changes, `[site]` and `[[devices]]` (each device with
    /// every key filled in, in id order; aisles in number order): SHA-256, in hex. Two nodes
    /// with the same hash run the same site and devices, however their files are written.
    pub fn site_hash(&self) -> String {
        use sha2::Digest;
        let mut devices: Vec<(String, Value)> =
            self.devices.iter().map(|d| (d.id().to_owned(), json(&RawDevice::from(d)))).collect();
        devices.sort_by(|a, b| a.0.cmp(&b.0));
        let mut aisles: Vec<Value> = self.site.aisles.iter().map(json).collect();
        aisles.sort_by_key(|a| a["aisle"].as_u64());
        let mut site = json(&self.site);
        site["aisles"] = Value::Array(aisles);
        let devices: Vec<Value> = devices.into_iter().map(|(_, d)| d).collect();
        let canonical = serde_json::json!({ "site": site, "devices": devices }).to_string();
        hex::encode(sha2::Sha256::digest(canonical.as_bytes()))
    }
}

fn json(value: &impl Serialize) -> Value {
    // A Config always serializes: its maps have string keys.
    serde_json::to_value(value).unwrap_or(Value::Null)
}

/// Pushes the dotted path of every leaf that differs between `old` and `new`; a value on
/// one side only is a leaf too.
fn leaves(prefix: &str, old: &Value, new: &Value, out: &mut Vec<String>) {
    match (old, new) {
        (Value::Object(a), Value::Object(b)) => {
            let names: BTreeSet<&String> = a.keys().chain(b.keys()).collect();
            for name in names {
                let path = if prefix.is_empty() { name.clone() } else { format!("{prefix}.{name}") };
                let (x, y) = (a.get(name).unwrap_or(&Value::Null), b.get(name).unwrap_or(&Value::Null));
                leaves(&path, x, y, out);
            }
        }
        (a, b) if a != b => out.push(prefix.to_owned()),
        _ => {}
    }
}

fn device_changes(old: &Config, new: &Config) -> Vec<DeviceChange> {
    let flat = |c: &Config| -> BTreeMap<String, Value> {
        c.devices.iter().map(|d| (d.id().to_owned(), json(&RawDevice::from(d)))).collect()
    };
    let (before, after) = (flat(old), flat(new));
    let mut changes = Vec::new();
    for d in &old.devices {
        let id = d.id();
        match after.get(id) {
            None => {
                changes.push(DeviceChange { id: id.to_owned(), change: Change::Removed, keys: Vec::new() })
            }
            Some(now) => {
                let mut keys = Vec::new();
                leaves("", &before[id], now, &mut keys);
                if !keys.is_empty() {
                    changes.push(DeviceChange { id: id.to_owned(), change: Change::Changed, keys });
                }
            }
        }
    }
    for d in new.devices.iter().filter(|d| !before.contains_key(d.id())) {
        changes.push(DeviceChange { id: d.id().to_owned(), change: Change::Added, keys: Vec::new() });
    }
    changes
}

fn auth_changes(old: &Config, new: &Config) -> AuthChanges {
    let mut keys = Vec::new();
    let find = |c: &Config, name: &str| c.auth.keys.iter().find(|k| k.name == name).cloned();
    for was in &old.auth.keys {
        let change = match find(new, &was.name) {
            None => Some((Change::Removed, Vec::new())),
            Some(now) => {
                let mut fields = Vec::new();
                if now.role != was.role {
                    fields.push("role".to_owned());
                }
                if now.hash != was.hash {
                    fields.push("hash".to_owned());
                }
                (!fields.is_empty()).then_some((Change::Changed, fields))
            }
        };
        if let Some((change, fields)) = change {
            keys.push(KeyChange { name: was.name.clone(), change, fields });
        }
    }
    for k in new.auth.keys.iter().filter(|k| find(old, &k.name).is_none()) {
        keys.push(KeyChange { name: k.name.clone(), change: Change::Added, fields: Vec::new() });
    }
    let (mut before, mut after) = (json(&old.auth), json(&new.auth));
    for side in [&mut before, &mut after] {
        if let Value::Object(map) = side {
            map.remove("keys");
        }
    }
    let mut settings = Vec::new();
    leaves("auth", &before, &after, &mut settings);
    AuthChanges { keys, settings }
}

fn aisle_changes(old: &Config, new: &Config) -> AisleChanges {
    let by_number =
        |c: &Config| -> BTreeMap<u16, Value> { c.site.aisles.iter().map(|a| (a.aisle, json(a))).collect() };
    let (before, after) = (by_number(old), by_number(new));
    let mut changes = AisleChanges::default();
    for (aisle, was) in &before {
        match after.get(aisle) {
            None => changes.removed.push(*aisle),
            Some(now) => {
                let mut keys = Vec::new();
                leaves("", was, now, &mut keys);
                if !keys.is_empty() {
                    changes.changed.push(AisleChange { aisle: *aisle, keys });
                }
            }
        }
    }
    changes.added = after.keys().filter(|a| !before.contains_key(a)).copied().collect();
    changes
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    const BASE: &str = r#"
[server]
listen = "127.0.0.1:8080"

[[site.aisles]]
aisle = 1
rows = 2
bays = 10
levels = 6
positions = 4

[[site.aisles]]
aisle = 2
rows = 2
bays = 20
levels = 8
positions = 2

[[devices]]
id = "shelf-1"
kind = "shelf"
address = "127.0.0.1:5020"
aisles = [1]

[[devices]]
id = "crane-2"
kind = "crane"
address = "127.0.0.1:5021"
aisles = [2]
"#;

    fn parse(text: &str) -> Config {
        Config::parse(text, Path::new("rackd.toml")).unwrap()
    }

    #[test]
    fn the_same_file_is_no_difference() {
        assert!(parse(BASE).difference(&parse(BASE)).is_empty());
    }

    #[test]
    fn a_default_written_out_is_no_difference() {
        let shelf = json(&RawDevice::from(&parse(BASE).devices[0]));
        let timeout = shelf["timeout_ms"].as_u64().expect("a shelf's timeout is filled in");
        let written = BASE
            .replace("aisles = [1]", &format!("aisles = [1]\ntimeout_ms = {timeout}"))
            .replace("bays = 10", "bays = 10\ndepth = 1");
        assert!(parse(BASE).difference(&parse(&written)).is_empty());
        let other = BASE.replace("aisles = [1]", &format!("aisles = [1]\ntimeout_ms = {}", timeout + 1));
        assert_eq!(parse(BASE).difference(&parse(&other)).devices[0].keys, ["timeout_ms"]);
    }

    #[test]
    fn devices_are_matched_by_id_not_by_place() {
        let (first, second) = BASE.split_at(BASE.find("[[devices]]\nid = \"crane-2\"").unwrap());
        let devices_at = first.find("[[devices]]").unwrap();
        let swapped = format!("{}{second}\n{}", &first[..devices_at], &first[devices_at..]);
        assert!(parse(BASE).difference(&parse(&swapped)).is_empty());
    }

    #[test]
    fn added_removed_and_changed_devices_with_their_keys() {
        let new = BASE
            .replace("address = \"127.0.0.1:5020\"", "address = \"127.0.0.1:5030\"\ntimeout_ms = 900")
            .replace("id = \"crane-2\"", "id = \"crane-3\"");
        let diff = parse(BASE).difference(&parse(&new));
        assert_eq!(
            diff.devices,
            [
                DeviceChange {
                    id: "shelf-1".into(),
                    change: Change::Changed,
                    keys: vec!["address".into(), "timeout_ms".into()]
                },
                DeviceChange { id: "crane-2".into(), change: Change::Removed, keys: vec![] },
                DeviceChange { id: "crane-3".into(), change: Change::Added, keys: vec![] },
            ]
        );
        assert!(diff.fixed.is_empty(), "{diff:?}");
    }

    #[test]
    fn aisles_added_removed_and_resized() {
        let third =
            "[[site.aisles]]\naisle = 3\nrows = 1\nbays = 5\nlevels = 2\npositions = 4\n\n[[devices]]";
        let new = BASE.replacen("[[devices]]", third, 1).replace("bays = 10", "bays = 12");
        let diff = parse(BASE).difference(&parse(&new));
        assert_eq!(diff.aisles.added, [3]);
        assert_eq!(diff.aisles.changed, [AisleChange { aisle: 1, keys: vec!["bays".into()] }]);
        let without_2 = parse(BASE);
        let mut one = without_2.clone();
        one.site.aisles.retain(|a| a.aisle == 1);
        one.devices.retain(|d| d.id() == "shelf-1");
        let diff = without_2.difference(&one);
        assert_eq!(diff.aisles.removed, [2]);
        assert_eq!(diff.devices[0].change, Change::Removed);
    }

    #[test]
    fn keys_outside_devices_and_site_are_fixed() {
        let old = parse(BASE);
        let mut new = old.clone();
        new.server.listen = "127.0.0.1:9090".parse().unwrap();
        new.database.busy_timeout_ms += 1;
        new.events.buffer += 1;
        let diff = old.difference(&new);
        assert_eq!(diff.fixed, ["database.busy_timeout_ms", "events.buffer", "server.listen"]);

        let mut clustered = old.clone();
        clustered.cluster = Some(crate::config::ClusterConfig {
            node: "a".into(),
            lease_ms: 5000,
            margin_ms: None,
            url: None,
            ca_file: None,
        });
        assert_eq!(old.difference(&clustered).fixed, ["cluster"]);
        let mut renamed = clustered.clone();
        let c = renamed.cluster.as_mut().unwrap();
        c.node = "b".into();
        c.lease_ms = 6000;
        let diff = clustered.difference(&renamed);
        assert_eq!(diff.fixed, ["cluster.lease_ms", "cluster.node"]);
    }

    #[test]
    fn the_site_hash_ignores_order_and_defaults_written_out() {
        let base = parse(BASE);
        let (first, second) = BASE.split_at(BASE.find("[[devices]]\nid = \"crane-2\"").unwrap());
        let devices_at = first.find("[[devices]]").unwrap();
        let swapped = format!("{}{second}\n{}", &first[..devices_at], &first[devices_at..]);
        assert_eq!(parse(&swapped).site_hash(), base.site_hash());
        assert_eq!(parse(&BASE.replace("bays = 10", "bays = 10\ndepth = 1")).site_hash(), base.site_hash());
        let mut other = base.clone();
        other.events.buffer += 1;
        assert_eq!(other.site_hash(), base.site_hash(), "only [site] and [[devices]] count");
        assert_ne!(parse(&BASE.replace("bays = 10", "bays = 11")).site_hash(), base.site_hash());
        assert_eq!(base.site_hash().len(), 64);
    }

    #[test]
    fn the_difference_reads_as_json() {
        let new = BASE.replace("id = \"crane-2\"", "id = \"crane-3\"");
        let diff = parse(BASE).difference(&parse(&new));
        assert_eq!(
            serde_json::to_value(&diff).unwrap(),
            serde_json::json!({
                "devices": [{"id": "crane-2", "change": "removed"}, {"id": "crane-3", "change": "added"}],
                "aisles": {"added": [], "removed": [], "changed": []},
                "auth": {"keys": [], "settings": []},
                "fixed": [],
            })
        );
    }

    #[test]
    fn keys_are_matched_by_name_and_named_never_shown() {
        use crate::auth::{KeyConfig, KeyHash, Role};
        let key =
            |name: &str, role: Role, key: &str| KeyConfig { name: name.into(), role, hash: KeyHash::of(key) };
        let mut old = parse(BASE);
        old.auth.keys = vec![
            key("wms", Role::Operator, "wms-key-1"),
            key("screen", Role::Viewer, "screen-key"),
            key("ops", Role::Operator, "ops-key"),
        ];
        let mut new = old.clone();
        new.auth.keys = vec![
            key("ops", Role::Admin, "ops-key"),
            key("wms", Role::Operator, "wms-key-2"),
            key("tablet", Role::Viewer, "tablet-key"),
        ];
        new.auth.max_failures += 1;
        let diff = old.difference(&new);
        assert!(diff.fixed.is_empty() && diff.devices.is_empty(), "{diff:?}");
        let change = |name: &str, change, fields: &[&str]| KeyChange {
            name: name.into(),
            change,
            fields: fields.iter().map(|f| f.to_string()).collect(),
        };
        assert_eq!(
            diff.auth,
            AuthChanges {
                keys: vec![
                    change("wms", Change::Changed, &["hash"]),
                    change("screen", Change::Removed, &[]),
                    change("ops", Change::Changed, &["role"]),
                    change("tablet", Change::Added, &[]),
                ],
                settings: vec!["auth.max_failures".into()],
            }
        );
        let text = serde_json::to_string(&diff).unwrap();
        assert!(!text.contains("sha256") && !text.contains("-key"), "{text}");
        let mut moved = old.clone();
        moved.auth.keys.reverse();
        assert!(old.difference(&moved).is_empty(), "a key moved in the file is no change");
    }
}
