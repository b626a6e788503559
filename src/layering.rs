//! The layering, checked: a test that reads every source file and fails on a path that
//! points up the layers, or on an import cycle between the children of any module, at
//! any depth: between top-level modules, between `devices::shelf` and `devices::crane`,
//! between `protocols::modbus::pdu` and `protocols::modbus::decode`.
//!
//! The layers, top to bottom (what each may use is [`ALLOWED`]):
//!
//! ```text
//! cli, main          the command line
//! app                building and running the service
//! api                HTTP routes, WebSocket, OpenAPI, the dashboard
//! service            intake, the dispatcher, the monitor, the event hub
//! devices            what machines mean (adapters), over a port the service implements
//! config             the configuration: file, environment, layers, checks, every device's settings
//! auth               keys and roles (leaf)
//! store              the database
//! sim                simulated machines, on the protocol servers; the replay of captures
//! wire               the machines' interfaces word by word, in the protocols' notations
//! protocols          how to talk to PLCs
//! capture            frames as the flight recorder keeps them; pcapng files, written and read (leaf)
//! domain             the words of the warehouse (leaf)
//! files, redact      how rackd creates a file of its own; secrets out of printed URLs (leaves)
//! ```
//!
//! What a file names is read by [`scan`]: `use` trees, paths in the code, and the names a
//! module re-exports followed to where they are defined. `a::b::c` naming `a::b::d` is an
//! edge `c -> d` between the children of `a::b`; a module naming its own parent or child
//! makes none. Unit tests (`#[cfg(test)]` items, and the files they declare) are not looked
//! at: a test may build whatever it needs.
//!
//! A Cargo workspace would make an upward `use` a compile error; one crate keeps builds
//! simple on small machines, and this test makes the same promise at `cargo test`.

#![cfg(test)]

mod scan;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use scan::{Edge, Edges, Module};

/// What each top-level module may use, besides itself.
const ALLOWED: &[(&str, &[&str])] = &[
    ("domain", &[]),
    ("capture", &[]),
    ("files", &[]),
    ("redact", &[]),
    // Every client's transport feeds a flight recorder.
    ("protocols", &["capture"]),
    ("wire", &["protocols", "domain"]),
    // The replay reads captures.
    ("sim", &["capture", "wire", "protocols", "domain"]),
    ("store", &["files", "redact", "domain"]),
    ("auth", &[]),
    // config checks a database URL as the store reads it (its TLS mode, its CA), and
    // prints it as the store does, without the password.
    ("config", &["auth", "store", "wire", "protocols", "capture", "redact", "domain"]),
    ("devices", &["config", "wire", "protocols", "capture", "domain"]),
    // A reload swaps the key ring that `[auth]` sets (issue 51).
    (
        "service",
        &["devices", "config", "auth", "store", "wire", "protocols", "capture", "files", "redact", "domain"],
    ),
    (
        "api",
        &[
            "service",
            "devices",
            "config",
            "auth",
            "store",
            "wire",
            "protocols",
            "capture",
            "redact",
            "domain",
        ],
    ),
    (
        "app",
        &["api", "service", "devices", "config", "auth", "store", "protocols", "capture", "redact", "domain"],
    ),
    (
        "cli",
        &[
            "app",
            "api",
            "service",
            "devices",
            "config",
            "auth",
            "store",
            "sim",
            "wire",
            "protocols",
            "capture",
            "files",
            "redact",
            "domain",
        ],
    ),
    ("layering", &[]),
];

/// Every `.rs` file under `dir`, relative to `root`, with its text.
fn sources(root: &Path, dir: &Path, out: &mut Vec<(PathBuf, String)>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(root, &path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap();
            out.push((path.strip_prefix(root).unwrap().to_owned(), text));
        }
    }
}

/// Every edge of the crate.
fn crate_edges() -> Edges {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut all = Vec::new();
    sources(&src, &src, &mut all);
    scan::edges(&all)
}

/// A cycle among `edges` (pairs of names), if there is one.
fn cycle<'a>(edges: impl IntoIterator<Item = (&'a str, &'a str)>) -> Option<Vec<String>> {
    let mut next: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (a, b) in edges {
        next.entry(a).or_default().push(b);
    }
    fn visit<'a>(
        n: &'a str,
        next: &BTreeMap<&'a str, Vec<&'a str>>,
        path: &mut Vec<&'a str>,
        done: &mut BTreeSet<&'a str>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| *p == n) {
            let mut c: Vec<String> = path[at..].iter().map(|s| s.to_string()).collect();
            c.push(n.to_owned());
            return Some(c);
        }
        if !done.insert(n) {
            return None;
        }
        path.push(n);
        for m in next.get(n).into_iter().flatten() {
            if let Some(c) = visit(m, next, path, done) {
                return Some(c);
            }
        }
        path.pop();
        None
    }
    let mut done = BTreeSet::new();
    for n in next.keys() {
        if let Some(c) = visit(n, &next, &mut Vec::new(), &mut done) {
            return Some(c);
        }
    }
    None
}

/// The circles among the children of every module: each group of children that reach
/// one another, with one cycle through them and every edge between them, where it is
/// made; empty when there are none.
fn cycles(edges: &Edges) -> Vec<String> {
    let mut by_parent: BTreeMap<&Module, Vec<&Edge>> = BTreeMap::new();
    for e in edges.keys() {
        by_parent.entry(&e.parent).or_default().push(e);
    }
    let mut found = Vec::new();
    for (parent, inner) in by_parent {
        let pairs: Vec<(&str, &str)> = inner.iter().map(|e| (e.from.as_str(), e.to.as_str())).collect();
        for circle in circles(&pairs) {
            let name = if parent.is_empty() { "the crate".to_owned() } else { parent.join("::") };
            let within = pairs.iter().filter(|(a, b)| circle.contains(a) && circle.contains(b));
            let c = cycle(within.clone().copied()).unwrap_or_default();
            let mut text = format!("inside {name}: {}", c.join(" -> "));
            for (a, b) in within {
                let e = Edge { parent: parent.clone(), from: a.to_string(), to: b.to_string() };
                let mut at = edges[&e].clone();
                at.dedup();
                text.push_str(&format!("\n  {a} -> {b} at {}", at.join(", ")));
            }
            found.push(text);
        }
    }
    found
}

/// The groups of two or more names that reach one another through `pairs`.
fn circles<'a>(pairs: &[(&'a str, &'a str)]) -> Vec<BTreeSet<&'a str>> {
    let mut reach: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for (a, b) in pairs {
        reach.entry(a).or_default().insert(b);
        reach.entry(b).or_default();
    }
    loop {
        let before: usize = reach.values().map(BTreeSet::len).sum();
        for n in reach.keys().copied().collect::<Vec<_>>() {
            let further: BTreeSet<&str> = reach[n].iter().flat_map(|m| reach[m].iter().copied()).collect();
            reach.get_mut(n).unwrap().extend(further);
        }
        if reach.values().map(BTreeSet::len).sum::<usize>() == before {
            break;
        }
    }
    let mut groups: Vec<BTreeSet<&str>> = Vec::new();
    for (n, to) in &reach {
        let group: BTreeSet<&str> = to.iter().copied().filter(|m| reach[m].contains(n)).collect();
        if group.len() > 1 && !groups.contains(&group) {
            groups.push(group);
        }
    }
    groups
}

#[test]
fn dependencies_point_down() {
    let allowed: BTreeMap<&str, &[&str]> = ALLOWED.iter().copied().collect();
    let mut wrong = Vec::new();
    for (e, at) in crate_edges().iter().filter(|(e, _)| e.parent.is_empty()) {
        if !allowed.get(e.from.as_str()).is_some_and(|a| a.contains(&e.to.as_str())) {
            wrong.push(format!("{} -> {} (at {})", e.from, e.to, at.join(", ")));
        }
    }
    assert!(wrong.is_empty(), "upward or unlisted dependencies:\n{}", wrong.join("\n"));
}

#[test]
fn no_import_cycles() {
    let found = cycles(&crate_edges());
    assert!(found.is_empty(), "import cycles:\n{}", found.join("\n"));
}

/// The edges of a made-up source tree, as `parent: from -> to`.
fn edges_of(files: &[(&str, &str)]) -> Vec<String> {
    let files: Vec<(PathBuf, String)> =
        files.iter().map(|(p, t)| (PathBuf::from(p), t.to_string())).collect();
    scan::edges(&files).keys().map(|e| format!("{}: {} -> {}", e.parent.join("::"), e.from, e.to)).collect()
}

#[test]
fn the_scanner_resolves_paths() {
    let m = |s: &str| s.split("::").map(str::to_owned).collect::<Vec<_>>();
    let uses = |code: &str, file: &str| {
        let scan = scan::scan_text(code, Path::new(file));
        scan.uses.into_iter().map(|(_, path, _)| path.join("::")).collect::<Vec<_>>()
    };
    assert_eq!(scan::module_of(Path::new("devices/shelf/poll.rs")), m("devices::shelf::poll"));
    assert_eq!(scan::module_of(Path::new("devices/shelf/mod.rs")), m("devices::shelf"));
    assert_eq!(uses("use crate::store::jobs;", "a.rs"), ["crate::store::jobs"]);
    assert_eq!(
        uses("pub use super::{a::{self, B as C}, d::*};\nuse ::x;", "a.rs"),
        ["super::a", "super::a::B", "super::d", "x"]
    );
    let paths = scan::scan_text("let x = my_crate::y; // crate::z\nlet s = \"crate::w\";", Path::new("a.rs"));
    assert_eq!(paths.paths, [(m("my_crate::y"), 1)]);
    let tests = scan::scan_text("#[cfg(test)]\n#[path = \"x_tests.rs\"]\nmod tests;\n", Path::new("a/x.rs"));
    assert_eq!(tests.test_files, [PathBuf::from("a/x_tests.rs")]);

    let tree = [
        ("lib.rs", "pub mod devices; pub mod store;"),
        ("store/mod.rs", "pub mod jobs; pub use jobs::Job;"),
        ("store/jobs.rs", "pub struct Job;"),
        ("devices/mod.rs", "pub mod shelf; pub mod config; mod wire;"),
        ("devices/config.rs", ""),
        ("devices/wire.rs", ""),
        ("devices/shelf/mod.rs", "pub mod poll; pub mod slot; #[cfg(test)] mod tests;"),
        ("devices/shelf/tests.rs", "use crate::devices::shelf::poll;"),
        ("devices/shelf/slot.rs", "fn f() { super::super::wire::g() }"),
        (
            "devices/shelf/poll.rs",
            "use crate::store::Job;\nuse super::slot::X;\nuse super::super::config as c;",
        ),
    ];
    assert_eq!(
        edges_of(&tree),
        [
            ": devices -> store",
            "devices: shelf -> config",
            "devices: shelf -> wire",
            "devices::shelf: poll -> slot"
        ]
    );
    assert_eq!(cycle([("a", "b")]), None);
    assert!(cycle([("a", "b"), ("b", "a")]).is_some());
}

#[test]
fn a_cycle_deep_down_is_found() {
    let m = |s: &str| s.split("::").map(str::to_owned).collect::<Vec<_>>();
    let mut edges = Edges::new();
    for (from, to) in [
        ("protocols::modbus::x", "protocols::modbus::y::z"),
        ("protocols::modbus::y::w", "protocols::modbus::x"),
    ] {
        edges.insert(scan::edge(&m(from), &m(to)).unwrap(), vec![format!("{from}.rs:1")]);
    }
    let found = cycles(&edges);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].starts_with("inside protocols::modbus: x -> y -> x"), "{}", found[0]);

    // From the source: through a re-export, two levels down.
    let tree = [
        ("lib.rs", "pub mod protocols;"),
        ("protocols/mod.rs", "pub mod modbus;"),
        ("protocols/modbus/mod.rs", "pub mod x; pub mod y;"),
        ("protocols/modbus/x.rs", "use super::y::Helper;\npub fn g() {}"),
        ("protocols/modbus/y/mod.rs", "mod z;\npub use z::Helper;"),
        ("protocols/modbus/y/z.rs", "pub struct Helper;\nfn f() { crate::protocols::modbus::x::g() }"),
    ];
    assert_eq!(edges_of(&tree), ["protocols::modbus: x -> y", "protocols::modbus: y -> x"]);
    let found = cycles(&scan::edges(&tree.map(|(p, t)| (PathBuf::from(p), t.to_owned()))));
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].starts_with("inside protocols::modbus: x -> y -> x"), "{}", found[0]);
    assert!(found[0].contains("y -> x at src/protocols/modbus/y/z.rs:2"), "{}", found[0]);
}
