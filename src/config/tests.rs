//! Loading, refusing, and the example file's claims about defaults.

use std::collections::BTreeSet;

use super::*;
use crate::config::devices::DeviceConfig;

const EXAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/rackd.example.toml");

#[test]
fn the_example_file_loads() {
    let config = Config::load(Path::new(EXAMPLE)).unwrap();
    assert_eq!(config.auth.keys.len(), 3);
    assert_eq!(config.devices.len(), 3);
}

/// Where a key sits: the table's path (`server`, `devices.1`) and the key.
type Place = (String, String);

/// The keys of the example file: those marked `(example)` (this site's own values) and
/// the others, which claim to show the default; whole tables marked `(example)` are left
/// out of both.
fn example_keys(text: &str) -> (BTreeSet<Place>, BTreeSet<Place>) {
    let (mut examples, mut defaults) = (BTreeSet::new(), BTreeSet::new());
    let mut counts = std::collections::BTreeMap::<String, usize>::new();
    let mut table: Option<String> = Some(String::new());
    for line in text.lines().map(str::trim) {
        let (code, comment) = line.split_once('#').unwrap_or((line, ""));
        let marked = comment.trim_start().starts_with("(example)");
        let code = code.trim();
        if let Some(name) = code.strip_prefix("[[").and_then(|c| c.strip_suffix("]]")) {
            let n = counts.entry(name.to_owned()).or_default();
            table = (!marked).then(|| format!("{name}.{n}"));
            *n += 1;
        } else if let Some(name) = code.strip_prefix('[').and_then(|c| c.strip_suffix(']')) {
            let array_entry = counts.get(name.split('.').next().unwrap_or("")).map(|n| n - 1);
            let name = match array_entry {
                Some(n) if name.contains('.') => name.replacen('.', &format!(".{n}."), 1),
                _ => name.to_owned(),
            };
            table = (!marked).then_some(name);
        } else if let (Some(t), Some((key, _))) = (&table, code.split_once('=')) {
            let place = (t.clone(), key.trim().to_owned());
            if marked {
                examples.insert(place)
            } else {
                defaults.insert(place)
            };
        }
    }
    (examples, defaults)
}

/// The example file marks with `(example)` the values that are its own; every other key
/// must equal the code's default: removing all of them must load the same configuration.
#[test]
fn every_key_the_example_file_shows_is_its_default_unless_marked() {
    let text = std::fs::read_to_string(EXAMPLE).unwrap();
    let (examples, defaults) = example_keys(&text);
    assert!(defaults.len() > 40 && examples.len() > 10, "{defaults:?} {examples:?}");
    let mut stripped: toml::Table = toml::from_str(&text).unwrap();
    for (path, key) in &defaults {
        let table = resolve_arrays(&mut stripped, path);
        assert!(table.remove(key).is_some(), "{path}.{key} is not a key the parser saw");
    }
    for (path, key) in &examples {
        assert!(resolve_arrays(&mut stripped, path).contains_key(key), "{path}.{key}");
    }
    let full = Config::parse(&text, Path::new("example")).unwrap();
    let defaulted = Config::parse(&toml::to_string(&stripped).unwrap(), Path::new("stripped")).unwrap();
    assert_eq!(full.server, defaulted.server);
    assert_eq!(full.events, defaulted.events);
    for (a, b) in full.devices.iter().zip(&defaulted.devices) {
        assert_eq!(a, b, "a key of device {:?} is not at its default", a.id());
    }
    assert_eq!(full, defaulted);
}

/// The table at `path`, where `name.N` is entry N of the array of tables `name`.
fn resolve_arrays<'a>(root: &'a mut toml::Table, path: &str) -> &'a mut toml::Table {
    let mut parts: Vec<&str> = path.split('.').collect();
    let mut t = root;
    while !parts.is_empty() {
        let part = parts.remove(0);
        if part.is_empty() {
            continue;
        }
        t = match t.get_mut(part).unwrap_or_else(|| panic!("no {part} in {path}")) {
            toml::Value::Array(items) => {
                let n: usize = parts.remove(0).parse().unwrap();
                items[n].as_table_mut().unwrap()
            }
            v => v.as_table_mut().unwrap(),
        };
    }
    t
}

#[test]
fn unknown_key_is_named_with_its_line() {
    let err = Config::parse("[server]\nlisten = \"127.0.0.1:1\"\nlissen = 3\n", Path::new("x.toml"))
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("x.toml:3:1: server.lissen: unknown field `lissen`"), "{err}");
}

#[test]
fn a_tags_device_table_follows_its_entry() {
    let text = "[[devices]]\nid = \"tower1\"\nkind = \"tags\"\nprotocol = \"ppi-tcp\"\naddress = \"10.0.0.2:102\"\nunit = 2\n\
                [devices.tags]\nbeacon.red = \"Q0.1\"\n\"conveyor.speed\" = { address = \"VD4\", type = \"f32\", max = 2.5 }\n";
    let config = Config::parse(text, Path::new("x.toml")).unwrap();
    let DeviceConfig::Tags(tags) = &config.devices[0] else { panic!("{:?}", config.devices[0]) };
    assert_eq!(tags.tags.0.len(), 2);
    let bad = text.replace("max = 2.5", "mx = 2.5");
    let err = Config::parse(&bad, Path::new("x.toml")).unwrap_err().to_string();
    assert!(err.contains("conveyor.speed") && err.contains("mx"), "{err}");
    assert!(err.starts_with("x.toml:7:10: devices[0].tags: "), "the line of [devices.tags]: {err}");
    let bad = text.replace("VD4", "VD4.1");
    let err = Config::parse(&bad, Path::new("x.toml")).unwrap_err().to_string();
    assert!(err.contains("tower1") && err.contains("conveyor.speed") && err.contains("VD4.1"), "{err}");
    assert!(err.starts_with("x.toml:9:1: devices[0].tags.conveyor.speed: "), "the tag's line: {err}");
}

#[test]
fn bad_layout_is_refused() {
    let text = "[[site.aisles]]\naisle = 1\nrows = 3\nbays = 1\nlevels = 1\npositions = 1\n";
    let err = Config::parse(text, Path::new("x.toml")).unwrap_err();
    assert!(matches!(err, ConfigError::Invalid { source: Invalid::AisleSize(1), .. }), "{err}");
    assert!(err.to_string().starts_with("x.toml:3:1: site.aisles[0].rows: "), "{err}");
}

#[test]
fn devices_are_checked_together() {
    let shelf = |id: &str, aisle: u16| {
        format!("[[devices]]\nid = {id:?}\nkind = \"shelf\"\naddress = \"127.0.0.1:1\"\naisles = [{aisle}]\n")
    };
    let twice = format!("{}{}", shelf("a", 1), shelf("a", 1));
    let err = Config::parse(&twice, Path::new("x.toml")).unwrap_err();
    assert!(matches!(err, ConfigError::Invalid { source: Invalid::DeviceId(_), .. }), "{err}");
    assert!(err.to_string().starts_with("x.toml:7:1: devices[1].id: "), "{err}");
    let shared = format!("{}{}", shelf("a", 1), shelf("b", 1));
    let err = Config::parse(&shared, Path::new("x.toml")).unwrap_err().to_string();
    assert!(err.contains("already served by \"a\""), "{err}");
    assert!(err.starts_with("x.toml:10:1: devices[1].aisles: "), "{err}");
    let err = Config::parse(&shelf("a", 9), Path::new("x.toml")).unwrap_err().to_string();
    assert!(err.contains("aisle 9 is not in site.aisles"), "{err}");
}

#[test]
fn a_cluster_needs_postgresql_and_an_address_the_others_reach() {
    let err = |text: &str| Config::parse(text, Path::new("x.toml")).unwrap_err().to_string();
    let e = err("[cluster]\nnode = \"a\"\n");
    assert!(e.contains("cluster: ") && e.contains("database.url"), "{e}");
    let pg = "[database]\nurl = \"postgres://rackd@db/rackd\"\n";
    let e = err(&format!("{pg}[server]\nlisten = \"0.0.0.0:8080\"\n[cluster]\nnode = \"a\"\n"));
    assert!(e.contains("cluster.url: "), "{e}");
    let e = err(&format!("{pg}[cluster]\nnode = \"a\"\nlease_ms = 1000\nmargin_ms = 50\n"));
    assert!(e.contains("cluster.margin_ms: "), "{e}");
    let ok = Config::parse(&format!("{pg}[cluster]\nnode = \"a\"\n"), Path::new("x.toml")).unwrap();
    let c = ok.cluster.unwrap();
    assert_eq!(c.lease(), (std::time::Duration::from_secs(5), std::time::Duration::from_secs(1)));
    assert_eq!(c.url(ok.server.listen, false), "http://127.0.0.1:8080");
    assert_eq!(c.url(ok.server.listen, true), "https://127.0.0.1:8080", "with [server.tls]");
}

/// Issue 51: the configuration's errors are typed (thiserror), like the rest of the
/// crate's: no `Result` in `src/config.rs` or `src/config/` (their tests aside) has a
/// `String` for its error.
#[test]
fn no_result_in_the_configuration_has_a_string_error() {
    fn sources(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                sources(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    /// The last type argument of each `Result<...>` in `text`.
    fn errors(text: &str) -> Vec<String> {
        let mut found = Vec::new();
        for (at, _) in text.match_indices("Result<") {
            let (mut depth, mut start, mut last) = (0, at + 7, None);
            for (i, c) in text[at + 6..].char_indices().map(|(i, c)| (i + at + 6, c)) {
                match c {
                    '<' | '(' | '[' => depth += 1,
                    '>' | ')' | ']' => {
                        depth -= 1;
                        if depth == 0 {
                            last = Some(text[start..i].trim().to_owned());
                            break;
                        }
                    }
                    ',' if depth == 1 => start = i + 1,
                    _ => {}
                }
            }
            found.extend(last);
        }
        found
    }
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = vec![src.join("config.rs")];
    sources(&src.join("config"), &mut files);
    let mut stringly = Vec::new();
    for file in files {
        let name = file.file_name().unwrap().to_string_lossy();
        if name == "tests.rs" || name.ends_with("_tests.rs") {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap_or_default();
        for (line, text) in code.lines().enumerate() {
            if errors(text).iter().any(|e| e == "String") {
                stringly.push(format!(
                    "{}:{}: {}",
                    file.strip_prefix(&src).unwrap().display(),
                    line + 1,
                    text.trim()
                ));
            }
        }
    }
    assert!(stringly.is_empty(), "Result<_, String> in the configuration:\n{}", stringly.join("\n"));
}

#[test]
fn database_url_may_list_several_hosts_as_libpq_does() {
    let parse = |url: &str| Config::parse(&format!("[database]\nurl = \"{url}\"\n"), Path::new("x.toml"));
    parse("postgres://rackd@db1:5432,db2:5433/rackd?sslmode=disable").unwrap();
    parse("postgres://rackd@db1,db2/rackd?target_session_attrs=read-write&sslmode=disable").unwrap();
    parse("postgres://rackd@db1,db2/rackd?target_session_attrs=primary&sslmode=disable").unwrap();
    let e = parse("postgres://rackd@db1,db2/rackd?target_session_attrs=standby").unwrap_err().to_string();
    assert!(e.starts_with("x.toml:2:1: database.url: ") && e.contains("standby"), "{e}");
    let e = parse("postgres://rackd@/rackd?host=db1,db2").unwrap_err().to_string();
    assert!(e.contains("database.url: ") && e.contains("HOST1:PORT1,HOST2:PORT2"), "{e}");
}
