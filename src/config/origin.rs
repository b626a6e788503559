//! Where a configuration value came from, and where each key of a TOML file is.
//!
//! Every error and every line of `rackd check-config --explain` names a value's origin:
//! `FILE:LINE:COL` for the file (and for `auth.keys_file`), `env VAR` for the environment,
//! `command line` or `default`. Keys are written as paths, `server.listen`,
//! `devices[2].address`, `devices[0].tags.beacon.red`; a tag's quoted dotted name and its
//! nested form give the same path, as they name the same tag.

use std::collections::BTreeMap;
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use toml_edit::{ImDocument, Item, Table, Value};

/// Where a value came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Origin {
    /// Nobody set it.
    Default,
    /// A file, at a line and column (from 1).
    File {
        /// The file.
        path: PathBuf,
        /// Line, from 1.
        line: usize,
        /// Column, from 1.
        column: usize,
    },
    /// An environment variable.
    Env(String),
    /// A command-line flag.
    CommandLine,
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Origin::Default => f.write_str("default"),
            Origin::File { path, line, column } => write!(f, "{}:{line}:{column}", path.display()),
            Origin::Env(var) => write!(f, "env {var}"),
            Origin::CommandLine => f.write_str("command line"),
        }
    }
}

impl Origin {
    /// The position of byte `offset` of `text`, the contents of `path`.
    pub fn in_file(path: &Path, text: &str, offset: usize) -> Origin {
        let before = &text[..offset.min(text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        Origin::File { path: path.to_owned(), line, column }
    }
}

/// A key path from its parts: numbers are array indexes (`devices`, `2`, `unit` is
/// `devices[2].unit`).
pub fn join<S: AsRef<str>>(parts: &[S]) -> String {
    let mut out = String::new();
    for part in parts.iter().map(AsRef::as_ref) {
        if !out.is_empty() && part.parse::<usize>().is_ok() {
            out.push_str(&format!("[{part}]"));
        } else {
            if !out.is_empty() {
                out.push('.');
            }
            out.push_str(part);
        }
    }
    out
}

/// The position of every key of one TOML file.
#[derive(Clone, Debug, Default)]
pub struct Lines {
    path: PathBuf,
    text: String,
    keys: BTreeMap<String, usize>,
}

/// A TOML file that is not TOML, at its line.
#[derive(Debug, thiserror::Error)]
#[error("{origin}: {message}")]
pub struct SyntaxError {
    /// Where.
    pub origin: Origin,
    /// The parser's words.
    pub message: String,
}

impl Lines {
    /// The keys of `text`, the contents of `path`.
    pub fn parse(path: &Path, text: &str) -> Result<Lines, SyntaxError> {
        let doc = ImDocument::parse(text).map_err(|e| SyntaxError {
            origin: Origin::in_file(path, text, e.span().map_or(0, |s| s.start)),
            message: e.message().trim().to_owned(),
        })?;
        let mut lines = Lines { path: path.to_owned(), text: text.to_owned(), keys: BTreeMap::new() };
        lines.table("", doc.as_table());
        Ok(lines)
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where `key` is written, if it is.
    pub fn find(&self, key: &str) -> Option<Origin> {
        self.keys.get(key).map(|&offset| Origin::in_file(&self.path, &self.text, offset))
    }

    /// Where `key` is written, or else the nearest table or entry around it that is.
    pub fn nearest(&self, key: &str) -> Option<Origin> {
        let mut key = key;
        loop {
            if let Some(origin) = self.find(key) {
                return Some(origin);
            }
            key = &key[..key.rfind(['.', '['])?];
        }
    }

    /// The key written last before byte `offset` (for a parser's error that has a position
    /// and no key).
    pub fn key_at(&self, offset: usize) -> Option<&str> {
        let found = self.keys.iter().filter(|&(_, &at)| at <= offset).max_by_key(|&(_, &at)| at);
        found.map(|(key, _)| key.as_str())
    }

    fn add(&mut self, key: &str, span: Option<Range<usize>>) {
        if let Some(span) = span {
            self.keys.entry(key.to_owned()).or_insert(span.start);
        }
    }

    fn table(&mut self, prefix: &str, table: &Table) {
        for (name, _) in table.iter() {
            let Some((key, item)) = table.get_key_value(name) else { continue };
            let path = join(&[prefix, name].iter().filter(|p| !p.is_empty()).collect::<Vec<_>>());
            self.add(&path, key.span());
            self.item(&path, item);
        }
    }

    fn item(&mut self, path: &str, item: &Item) {
        match item {
            Item::Table(t) => {
                self.add(path, t.span());
                self.table(path, t);
            }
            Item::ArrayOfTables(entries) => {
                for (i, t) in entries.iter().enumerate() {
                    let entry = format!("{path}[{i}]");
                    self.add(&entry, t.span());
                    self.table(&entry, t);
                }
            }
            Item::Value(v) => self.value(path, v),
            Item::None => {}
        }
    }

    fn value(&mut self, path: &str, value: &Value) {
        match value {
            Value::InlineTable(t) => {
                for (name, _) in t.iter() {
                    let Some((key, item)) = t.get_key_value(name) else { continue };
                    let inner = format!("{path}.{name}");
                    self.add(&inner, key.span());
                    self.item(&inner, item);
                }
            }
            Value::Array(items) => {
                for (i, v) in items.iter().enumerate() {
                    let entry = format!("{path}[{i}]");
                    self.add(&entry, v.span());
                    self.value(&entry, v);
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_has_its_line_and_column() {
        let text = "[server]\nlisten = \"x\"\n\n[[devices]]\nid = \"a\"\n[[devices]]\n  unit = 3\n\
                    [devices.tags]\n\"beacon.red\" = \"Q0.1\"\nx = { address = \"VW0\" }\n";
        let lines = Lines::parse(Path::new("f.toml"), text).unwrap();
        let at = |key| lines.find(key).map(|o| o.to_string());
        assert_eq!(at("server.listen").as_deref(), Some("f.toml:2:1"));
        assert_eq!(at("devices[1].unit").as_deref(), Some("f.toml:7:3"));
        assert_eq!(at("devices[1]").as_deref(), Some("f.toml:6:1"));
        assert_eq!(at("devices[1].tags.beacon.red").as_deref(), Some("f.toml:9:1"));
        assert_eq!(at("devices[1].tags.x.address").as_deref(), Some("f.toml:10:7"));
        let nearest = lines.nearest("devices[0].slots").unwrap().to_string();
        assert_eq!(nearest, "f.toml:4:1", "a key left out points at its entry");
        assert_eq!(lines.key_at(text.find("unit").unwrap() + 7), Some("devices[1].unit"));
    }

    #[test]
    fn a_syntax_error_has_its_line() {
        let err = Lines::parse(Path::new("f.toml"), "[server]\nlisten = \n").unwrap_err().to_string();
        assert!(err.starts_with("f.toml:2:"), "{err}");
    }

    #[test]
    fn paths_write_indexes_in_brackets() {
        assert_eq!(join(&["devices", "2", "address"]), "devices[2].address");
        assert_eq!(join(&["server", "listen"]), "server.listen");
    }
}
