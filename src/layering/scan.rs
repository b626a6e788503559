//! Reading the source for the layering test: which modules each file names, through `use`
//! trees, paths in the code and the names a module re-exports, with tests left out
//! (`#[cfg(test)]` items, and the files such an item declares).
//!
//! Not a Rust parser: a tokenizer that drops comments and literals, a reader of `use`
//! trees, and name resolution against the module tree on disk. A name a module brings in
//! with `use` (public or not: its children see it too) is followed to where it is defined,
//! so `crate::protocols::PlcError` counts as `protocols::error`, where the type lives.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A module path, `["devices", "shelf", "poll"]`; the crate root is empty.
pub type Module = Vec<String>;

/// One dependency between two children of a module: `a::b::c` naming `a::b::d` is `c -> d`
/// inside `a::b` (top-level modules are the children of the root).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Edge {
    /// The module whose children these are.
    pub parent: Module,
    /// The child that names the other.
    pub from: String,
    /// The child named.
    pub to: String,
}

/// Every edge in the crate, with where each is made (`file:line`).
pub type Edges = BTreeMap<Edge, Vec<String>>;

/// The edge that `from` naming `to` makes, if the two lie in different children of a
/// module (a module naming its own parent or child makes none).
pub fn edge(from: &[String], to: &[String]) -> Option<Edge> {
    let common = from.iter().zip(to).take_while(|(a, b)| a == b).count();
    let (a, b) = (from.get(common)?, to.get(common)?);
    Some(Edge { parent: from[..common].to_vec(), from: a.clone(), to: b.clone() })
}

/// Every edge between modules in `sources` (paths relative to `src/`, and their text).
pub fn edges(sources: &[(PathBuf, String)]) -> Edges {
    let scans: Vec<(Module, &Path, Scan)> = sources
        .iter()
        .map(|(path, text)| (module_of(path), path.as_path(), scan(&tokens(text), path)))
        .collect();
    let tests: BTreeSet<&Path> =
        scans.iter().flat_map(|(_, _, s)| s.test_files.iter().map(PathBuf::as_path)).collect();
    let code: Vec<&(Module, &Path, Scan)> = scans
        .iter()
        .filter(|(m, p, s)| !s.test_only && !tests.contains(p) && m.first().is_none_or(|m| m != "layering"))
        .collect();
    let mut known: BTreeSet<Module> = BTreeSet::new();
    for (module, ..) in &code {
        for n in 0..=module.len() {
            known.insert(module[..n].to_vec());
        }
    }
    // What each module's `use`s name, absolute; twice, for a `use` that starts at another.
    let mut exports: BTreeMap<Module, BTreeMap<String, Vec<String>>> = BTreeMap::new();
    for _ in 0..2 {
        for (module, _, scan) in &code {
            let mut names = exports.get(module).cloned().unwrap_or_default();
            for (alias, raw, _) in &scan.uses {
                if let (Some(alias), Some(path)) = (alias, absolute(raw, module, &names, &known)) {
                    names.insert(alias.clone(), path);
                }
            }
            exports.insert(module.clone(), names);
        }
    }
    let mut out = Edges::new();
    for (module, path, scan) in &code {
        let names = &exports[module];
        let named =
            scan.uses.iter().map(|(_, raw, line)| (raw, line)).chain(scan.paths.iter().map(|(r, l)| (r, l)));
        for (raw, line) in named {
            let Some(path_) = absolute(raw, module, names, &known) else { continue };
            let to = target(path_, &known, &exports);
            if let Some(e) = edge(module, &to) {
                out.entry(e).or_default().push(format!("src/{}:{line}", path.display()));
            }
        }
    }
    out
}

/// The module path of a file under `src/` (`devices/shelf/poll.rs`, `devices/shelf/mod.rs`).
pub fn module_of(file: &Path) -> Module {
    let mut parts: Vec<String> = file.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.trim_end_matches(".rs");
    if !matches!(stem, "mod" | "lib") {
        parts.push(stem.to_owned());
    }
    parts
}

/// A path as written, made absolute from `module`: `crate::`, `super::`, `self::`, a name
/// brought in by `use`, or a child module. None for another crate's path or a local item.
fn absolute(
    raw: &[String],
    module: &[String],
    names: &BTreeMap<String, Vec<String>>,
    known: &BTreeSet<Module>,
) -> Option<Vec<String>> {
    let first = raw.first()?;
    let mut path = match first.as_str() {
        "crate" => Vec::new(),
        "self" => module.to_vec(),
        "super" => {
            let supers = raw.iter().take_while(|s| *s == "super").count();
            let mut base = module.to_vec();
            base.truncate(module.len().checked_sub(supers)?);
            base.extend(raw[supers..].iter().cloned());
            return Some(base);
        }
        name => {
            let mut child = module.to_vec();
            child.push(name.to_owned());
            if let Some(path) = names.get(name) {
                path.clone()
            } else if known.contains(&child) {
                child
            } else {
                return None;
            }
        }
    };
    path.extend(raw[1..].iter().cloned());
    Some(path)
}

/// The module an absolute path leads to: its longest prefix that is a module, followed
/// through that module's `use`s when the next name is one of them.
fn target(
    mut path: Vec<String>,
    known: &BTreeSet<Module>,
    exports: &BTreeMap<Module, BTreeMap<String, Vec<String>>>,
) -> Module {
    for _ in 0..16 {
        let n = (0..=path.len()).rev().find(|n| known.contains(&path[..*n])).unwrap_or(0);
        let via = path.get(n).and_then(|name| exports.get(&path[..n])?.get(name));
        match via {
            Some(next) if next.as_slice() != &path[..=n] => {
                let mut next = next.clone();
                next.extend(path[n + 1..].iter().cloned());
                path = next;
            }
            _ => {
                path.truncate(n);
                return path;
            }
        }
    }
    path
}

/// What one file names: its `use`s (the name each brings in, the path as written, the
/// line) and the other paths in its code; and what it says about tests.
#[derive(Debug, Default)]
pub struct Scan {
    /// `use` leaves: (the name brought in, if any; the path as written; the line).
    pub uses: Vec<(Option<String>, Vec<String>, usize)>,
    /// Paths of two or more segments in the code, as written, and their lines.
    pub paths: Vec<(Vec<String>, usize)>,
    /// Files of modules declared under `#[cfg(test)]`.
    pub test_files: Vec<PathBuf>,
    /// The whole file is a test (`#![cfg(test)]`).
    pub test_only: bool,
}

/// A word, `::`, a literal or one punctuation character, and its line.
#[derive(Debug)]
struct Token<'a> {
    text: &'a str,
    line: usize,
}

fn is_word(t: &str) -> bool {
    t.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
}

/// Reads the tokens of a file for paths, `use` trees and test items.
pub fn scan_text(text: &str, file: &Path) -> Scan {
    scan(&tokens(text), file)
}

fn scan(toks: &[Token], file: &Path) -> Scan {
    let text = |i: usize| toks.get(i).map_or("", |t| t.text);
    let mut out = Scan::default();
    let (mut i, mut test_item, mut path_attr) = (0, false, None);
    while i < toks.len() {
        if text(i) == "#" {
            let inner = i + 1 + usize::from(text(i + 1) == "!");
            if text(inner) == "[" {
                let close = closing(toks, inner);
                let words: Vec<&str> = toks[inner + 1..close].iter().map(|t| t.text).collect();
                match words.as_slice() {
                    ["cfg", "(", "test", ")"] if inner == i + 2 => out.test_only = true,
                    ["cfg", "(", "test", ")"] => test_item = true,
                    ["path", "=", p] => path_attr = Some(p.trim_matches('"').to_owned()),
                    _ => {}
                }
                i = close + 1;
                continue;
            }
        }
        if test_item {
            let (end, declared) = item_end(toks, i);
            if let Some(name) = declared {
                out.test_files.extend(module_files(file, &name, path_attr.as_deref()));
            }
            (test_item, path_attr, i) = (false, None, end);
            continue;
        }
        path_attr = None;
        if text(i) == "use" {
            let mut j = i + 1;
            if text(j) == "::" {
                j += 1; // `use ::other_crate`
            }
            let mut leaves = Vec::new();
            j = use_tree(toks, j, Vec::new(), &mut leaves);
            let line = toks[i].line;
            out.uses.extend(leaves.into_iter().map(|(alias, path)| (alias, path, line)));
            while j < toks.len() && text(j) != ";" {
                j += 1;
            }
            i = j;
            continue;
        }
        if is_word(text(i)) && (i == 0 || text(i - 1) != "::") && text(i + 1) == "::" && is_word(text(i + 2))
        {
            let mut path = vec![text(i).to_owned()];
            let mut j = i + 1;
            while text(j) == "::" && is_word(text(j + 1)) {
                path.push(text(j + 1).to_owned());
                j += 2;
            }
            out.paths.push((path, toks[i].line));
            i = j;
            continue;
        }
        i += 1;
    }
    out
}

/// Reads a `use` tree from `i` under `prefix`; returns where it ends.
fn use_tree(
    toks: &[Token],
    mut i: usize,
    prefix: Vec<String>,
    out: &mut Vec<(Option<String>, Vec<String>)>,
) -> usize {
    let text = |i: usize| toks.get(i).map_or("", |t| t.text);
    let mut path = prefix;
    loop {
        match text(i) {
            "{" => {
                i += 1;
                while i < toks.len() && text(i) != "}" {
                    let next = use_tree(toks, i, path.clone(), out);
                    i = if next == i { i + 1 } else { next };
                    if text(i) == "," {
                        i += 1;
                    }
                }
                return i + 1;
            }
            "*" => {
                out.push((None, path));
                return i + 1;
            }
            word if is_word(word) => {
                path.push(word.to_owned());
                i += 1;
                if text(i) == "::" {
                    i += 1;
                    continue;
                }
                let mut alias = Some(word.to_owned());
                if word == "self" {
                    path.pop();
                    alias = path.last().cloned();
                }
                if text(i) == "as" {
                    alias = Some(text(i + 1).to_owned()).filter(|a| a != "_");
                    i += 2;
                }
                out.push((alias, path));
                return i;
            }
            _ => return i,
        }
    }
}

/// The index of the bracket closing the one at `open`.
fn closing(toks: &[Token], open: usize) -> usize {
    let mut depth = 0;
    for (i, t) in toks.iter().enumerate().skip(open) {
        match t.text {
            "(" | "[" | "{" => depth += 1,
            ")" | "]" | "}" => {
                depth -= 1;
                if depth == 0 {
                    return i;
                }
            }
            _ => {}
        }
    }
    toks.len().saturating_sub(1)
}

/// Where the item at `i` ends (the index after it), and the module it declares if it is
/// `mod name;`.
fn item_end(toks: &[Token], mut i: usize) -> (usize, Option<String>) {
    let text = |i: usize| toks.get(i).map_or("", |t| t.text);
    if text(i) == "pub" {
        i += 1;
        if text(i) == "(" {
            i = closing(toks, i) + 1;
        }
    }
    if text(i) == "mod" && text(i + 2) == ";" {
        return (i + 3, Some(text(i + 1).to_owned()));
    }
    let is_use = text(i) == "use";
    let mut depth = 0;
    while i < toks.len() {
        match text(i) {
            ";" if depth == 0 => return (i + 1, None),
            "(" | "[" => depth += 1,
            "{" if is_use => depth += 1,
            "{" => {
                let close = closing(toks, i);
                if depth == 0 {
                    return (close + 1, None);
                }
                i = close;
            }
            ")" | "]" | "}" => depth -= 1,
            _ => {}
        }
        i += 1;
    }
    (i, None)
}

/// The files `mod name;` in `file` may be read from.
fn module_files(file: &Path, name: &str, path_attr: Option<&str>) -> Vec<PathBuf> {
    let dir = file.parent().unwrap_or(Path::new(""));
    if let Some(p) = path_attr {
        return vec![dir.join(p)];
    }
    let stem = file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let dir = if matches!(stem.as_str(), "mod" | "lib" | "main") { dir.to_owned() } else { dir.join(stem) };
    vec![dir.join(format!("{name}.rs")), dir.join(name).join("mod.rs")]
}

/// The tokens of Rust source, comments and whitespace dropped.
fn tokens(src: &str) -> Vec<Token<'_>> {
    let b = src.as_bytes();
    let at = |i: usize| b.get(i).copied().unwrap_or(0);
    let (mut i, mut line, mut out) = (0, 1, Vec::new());
    while i < b.len() {
        let (start, start_line) = (i, line);
        let c = b[i];
        if c == b'\n' {
            line += 1;
            i += 1;
            continue;
        }
        if c.is_ascii_whitespace() || !c.is_ascii() {
            i += 1;
            continue;
        }
        if c == b'/' && at(i + 1) == b'/' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        if c == b'/' && at(i + 1) == b'*' {
            let mut depth = 0;
            while i < b.len() {
                if b[i..].starts_with(b"/*") {
                    (depth, i) = (depth + 1, i + 2);
                } else if b[i..].starts_with(b"*/") {
                    (depth, i) = (depth - 1, i + 2);
                    if depth == 0 {
                        break;
                    }
                } else {
                    line += usize::from(b[i] == b'\n');
                    i += 1;
                }
            }
            continue;
        }
        // Literals: strings (raw, byte, C), characters; a lifetime is a quote and a word.
        let prefix = if c == b'b' || c == b'c' { 1 } else { 0 };
        let raw = at(i + prefix) == b'r';
        let hashes = if raw { b[i + prefix + 1..].iter().take_while(|&&h| h == b'#').count() } else { 0 };
        let quote = i + prefix + usize::from(raw) + hashes;
        if at(quote) == b'"' && (prefix + usize::from(raw) + hashes > 0 || c == b'"') {
            i = quote + 1;
            loop {
                match at(i) {
                    0 => break,
                    b'\\' if !raw => {
                        line += usize::from(at(i + 1) == b'\n');
                        i += 2;
                    }
                    b'"' if b[i + 1..].iter().take(hashes).filter(|&&h| h == b'#').count() == hashes => {
                        i += 1 + hashes;
                        break;
                    }
                    ch => {
                        line += usize::from(ch == b'\n');
                        i += 1;
                    }
                }
            }
            out.push(Token { text: &src[start..i], line: start_line });
            continue;
        }
        if c == b'\'' || (c == b'b' && at(i + 1) == b'\'') {
            let q = i + usize::from(c == b'b');
            let width = src[q + 1..].chars().next().map_or(1, char::len_utf8);
            if at(q + 1) == b'\\' {
                i = q + 2;
                while i < b.len() && b[i] != b'\'' {
                    i += 1;
                }
                i += 1;
                continue;
            }
            if at(q + 1 + width) == b'\'' {
                i = q + 2 + width;
                continue;
            }
            i = q + 1; // a lifetime or a label
            continue;
        }
        if c.is_ascii_alphanumeric() || c == b'_' {
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push(Token { text: &src[start..i], line });
            continue;
        }
        i += if c == b':' && at(i + 1) == b':' { 2 } else { 1 };
        out.push(Token { text: &src[start..i], line });
    }
    out
}
