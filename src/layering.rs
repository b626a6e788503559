//! The layering, checked: a test that reads every source file and fails on a `crate::`
//! or `super::` path that points up the layers, or on an import cycle between top-level
//! modules or between the modules of one layer (`devices::shelf` and `devices::crane`,
//! say).
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
//! sim                simulated machines, on the protocol servers
//! wire               the machines' interfaces word by word, in the protocols' notations
//! protocols          how to talk to PLCs (leaf)
//! domain             the words of the warehouse (leaf)
//! ```
//!
//! Unit tests (a `mod` under `#[cfg(test)]`, and `*_tests.rs` files) are not looked at: a
//! test may build whatever it needs.
//!
//! A Cargo workspace would make an upward `use` a compile error; one crate keeps builds
//! simple on small machines, and this test makes the same promise at `cargo test`.

#![cfg(test)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// What each top-level module may use, besides itself.
const ALLOWED: &[(&str, &[&str])] = &[
    ("domain", &[]),
    ("protocols", &[]),
    ("wire", &["protocols", "domain"]),
    ("sim", &["wire", "protocols", "domain"]),
    ("store", &["domain"]),
    ("auth", &[]),
    ("config", &["auth", "wire", "protocols", "domain"]),
    ("devices", &["config", "wire", "protocols", "domain"]),
    ("service", &["devices", "config", "store", "wire", "protocols", "domain"]),
    ("api", &["service", "devices", "config", "auth", "store", "wire", "protocols", "domain"]),
    ("app", &["api", "service", "devices", "config", "auth", "store", "protocols", "domain"]),
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
            "domain",
        ],
    ),
    ("layering", &[]),
];

/// A module path (`["devices", "shelf", "poll"]`) for a file under `src/`.
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" && stem != "main" {
        parts.push(stem.to_owned());
    }
    if stem == "main" {
        parts.push("main".to_owned());
    }
    parts
}

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module paths a line of code names: `crate::a::b` and `super::a` (resolved from
/// `module`), first two segments of each.
fn targets(line: &str, module: &[String]) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    for (start, _) in line.match_indices("crate::").chain(line.match_indices("super::")) {
        let before = line[..start].chars().last();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
            continue;
        }
        let rest = &line[start..];
        let mut segs: Vec<&str> = rest.split("::").collect();
        let mut base: Vec<String> = Vec::new();
        let mut i = 0;
        if segs[0] == "crate" {
            i = 1;
        } else {
            // Each `super` names the parent of the module (a `mod.rs` is its folder's).
            base = module.to_vec();
            while i < segs.len() && segs[i] == "super" {
                base.pop();
                i += 1;
            }
        }
        segs.drain(..i);
        for seg in segs.iter().take(2) {
            let name: String = seg.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            if name.is_empty() || name.chars().next().is_some_and(|c| c.is_uppercase()) {
                break;
            }
            base.push(name);
        }
        if !base.is_empty() {
            found.push(base);
        }
    }
    found
}

/// Every edge between modules, at the top level and within each top-level module.
/// Edges between modules (from, to).
type Edges = BTreeSet<(String, String)>;

fn edges() -> (Edges, Edges, Vec<String>) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut all = Vec::new();
    files(&src, &mut all);
    let (mut top, mut inner, mut where_) = (BTreeSet::new(), BTreeSet::new(), Vec::new());
    for file in all {
        let module = module_of(&src, &file);
        if module.is_empty() || module[0] == "layering" {
            continue; // lib.rs, and this file's own examples
        }
        if file.to_string_lossy().ends_with("_tests.rs") {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for (n, line) in lines.iter().enumerate() {
            let code = line.trim_start();
            // A file's tests (a `mod` after `#[cfg(test)]`, at its end by convention) may
            // reach across: a test builds whatever it needs.
            if code == "#[cfg(test)]" && lines.get(n + 1).is_some_and(|l| l.trim_start().starts_with("mod "))
            {
                break;
            }
            if code.starts_with("//") {
                continue;
            }
            let code = code.split(" //").next().unwrap_or(code);
            for target in targets(code, &module) {
                let (from, to) = (&module[0], &target[0]);
                if from != to {
                    top.insert((from.clone(), to.clone()));
                    where_.push(format!("{}:{}: {from} -> {to}", file.display(), n + 1));
                } else if module.len() > 1 && target.len() > 1 && module[1] != target[1] {
                    let a = format!("{from}::{}", module[1]);
                    let b = format!("{to}::{}", target[1]);
                    where_.push(format!("{}:{}: {a} -> {b}", file.display(), n + 1));
                    inner.insert((a, b));
                }
            }
        }
    }
    (top, inner, where_)
}

/// A cycle in `edges`, if there is one.
fn cycle(edges: &Edges) -> Option<Vec<String>> {
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

#[test]
fn dependencies_point_down() {
    let (top, _, where_) = edges();
    let allowed: BTreeMap<&str, &[&str]> = ALLOWED.iter().copied().collect();
    let mut wrong = Vec::new();
    for (from, to) in &top {
        let ok = allowed.get(from.as_str()).is_some_and(|a| a.contains(&to.as_str()));
        if !ok {
            let at: Vec<&String> =
                where_.iter().filter(|w| w.ends_with(&format!(": {from} -> {to}"))).collect();
            wrong.push(format!("{from} -> {to} (at {at:?})"));
        }
    }
    assert!(wrong.is_empty(), "upward or unlisted dependencies:\n{}", wrong.join("\n"));
}

#[test]
fn no_import_cycles() {
    let (top, inner, where_) = edges();
    let mut all = top.clone();
    all.extend(inner.iter().cloned());
    if let Some(c) = cycle(&inner).or_else(|| cycle(&top)) {
        let steps: Vec<String> = c.windows(2).map(|w| format!("{} -> {}", w[0], w[1])).collect();
        let at: Vec<&String> =
            where_.iter().filter(|w| steps.iter().any(|s| w.ends_with(&format!(": {s}")))).collect();
        panic!(
            "a cycle between modules: {}\n{}",
            c.join(" -> "),
            at.iter().map(|s| s.as_str()).collect::<Vec<_>>().join("\n")
        );
    }
}

#[test]
fn the_scanner_resolves_paths() {
    let m = |s: &str| s.split("::").map(str::to_owned).collect::<Vec<_>>();
    assert_eq!(targets("use crate::store::jobs;", &m("devices::shelf::poll")), vec![m("store::jobs")]);
    assert_eq!(targets("use super::config::X;", &m("devices::shelf")), vec![m("devices::config")]);
    assert_eq!(targets("use super::slot::X;", &m("devices::shelf::poll")), vec![m("devices::shelf::slot")]);
    assert_eq!(targets("use super::super::wire;", &m("devices::shelf::poll")), vec![m("devices::wire")]);
    assert_eq!(targets("let x = my_crate::y;", &m("api")), Vec::<Vec<String>>::new());
    let mut edges = BTreeSet::new();
    edges.insert(("a".to_owned(), "b".to_owned()));
    assert_eq!(cycle(&edges), None);
    edges.insert(("b".to_owned(), "a".to_owned()));
    assert!(cycle(&edges).is_some());
}
