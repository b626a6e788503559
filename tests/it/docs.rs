//! The docs' commands still work. Every ```` ```sh ```` block of `README.md`,
//! `ARCHITECTURE.md` and `docs/**/*.md` (the runnable ones: output, TOML and JSON go in
//! blocks of their own language) parses as bash; every `rackd ...` in them, and every
//! `cargo run ... -- ...` of the rackd binary, parses with rackd's own command line; every
//! `/api/v1/...` path they send a request to is a route of `openapi/openapi.json`; and the
//! README's test command is the one `.ci/run` runs.
//!
//! The benchmarks' commands (`cargo run --example bench -- ...`) are checked by bash alone:
//! their parser lives in the example, out of this binary's reach.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use clap::Parser;
use serde_json::Value;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md, ARCHITECTURE.md and every page under docs/.
fn pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    let mut pages = vec![root().join("README.md"), root().join("ARCHITECTURE.md")];
    walk(&root().join("docs"), &mut pages);
    pages.sort();
    pages
}

/// A fenced block: the page, the line its fence opens on, its language and its text.
struct Block {
    page: PathBuf,
    line: usize,
    lang: String,
    text: String,
}

impl Block {
    fn at(&self) -> String {
        format!("{}:{}", self.page.strip_prefix(root()).unwrap_or(&self.page).display(), self.line)
    }
}

fn blocks(page: &Path) -> Vec<Block> {
    let text = std::fs::read_to_string(page).unwrap();
    let mut out = Vec::new();
    let mut open: Option<Block> = None;
    for (n, line) in text.lines().enumerate() {
        let fence = line.trim_start().strip_prefix("```");
        match (fence, open.take()) {
            (Some(_), Some(block)) => out.push(block),
            (Some(lang), None) => {
                let lang = lang.trim().to_owned();
                open = Some(Block { page: page.to_owned(), line: n + 1, lang, text: String::new() });
            }
            (None, Some(mut block)) => {
                block.text.push_str(line);
                block.text.push('\n');
                open = Some(block);
            }
            (None, None) => {}
        }
    }
    assert!(open.is_none(), "{}: a fence is never closed", page.display());
    out
}

fn shell_blocks() -> Vec<Block> {
    let all: Vec<Block> = pages().iter().flat_map(|p| blocks(p)).collect();
    for b in &all {
        assert!(
            !b.lang.is_empty(),
            "{}: a fenced block without a language (sh, text, toml, json, ...)",
            b.at()
        );
        assert!(!["bash", "shell", "console"].contains(&b.lang.as_str()), "{}: write ```sh", b.at());
    }
    all.into_iter().filter(|b| b.lang == "sh").collect()
}

/// The simple commands of a shell text, as words: continuations joined, comments, heredoc
/// bodies and redirections dropped, split at `;`, `&`, `&&`, `||` and `|`.
fn commands(text: &str) -> Vec<Vec<String>> {
    let mut lines = Vec::new();
    let mut heredoc: Option<String> = None;
    let mut pending = String::new();
    for line in text.lines() {
        if let Some(end) = &heredoc {
            if line.trim() == end {
                heredoc = None;
            }
            continue;
        }
        if let Some(at) = line.find("<<") {
            let end = line[at + 2..].trim_start_matches('-').trim();
            let end = end.split_whitespace().next().unwrap_or("").trim_matches(['\'', '"']);
            heredoc = Some(end.to_owned());
        }
        match line.strip_suffix('\\') {
            Some(head) => pending.push_str(head),
            None => {
                pending.push_str(line);
                lines.push(std::mem::take(&mut pending));
            }
        }
    }
    lines.iter().flat_map(|l| split_line(l)).filter(|c| !c.is_empty()).collect()
}

/// One line's commands (see [`commands`]).
fn split_line(line: &str) -> Vec<Vec<String>> {
    let (mut commands, mut words, mut word) = (Vec::new(), Vec::new(), String::new());
    let (mut in_word, mut skip_next_word) = (false, false);
    let mut chars = line.chars().peekable();
    let end_word = |word: &mut String, in_word: &mut bool, words: &mut Vec<String>, skip: &mut bool| {
        if *in_word {
            if !std::mem::take(skip) {
                words.push(std::mem::take(word));
            }
            word.clear();
            *in_word = false;
        }
    };
    while let Some(c) = chars.next() {
        match c {
            '\'' => {
                in_word = true;
                for q in chars.by_ref() {
                    if q == '\'' {
                        break;
                    }
                    word.push(q);
                }
            }
            '"' => {
                in_word = true;
                while let Some(q) = chars.next() {
                    match q {
                        '"' => break,
                        '\\' => word.extend(chars.next()),
                        _ => word.push(q),
                    }
                }
            }
            '\\' => {
                in_word = true;
                word.extend(chars.next());
            }
            '#' if !in_word => break,
            ' ' | '\t' => end_word(&mut word, &mut in_word, &mut words, &mut skip_next_word),
            '>' | '<' => {
                // A redirection: `>`, `>>`, `2>`, `>&2`, `2>&1`, `<`; its target is no argument.
                if in_word && word.chars().all(|d| d.is_ascii_digit()) {
                    (word, in_word) = (String::new(), false);
                }
                end_word(&mut word, &mut in_word, &mut words, &mut skip_next_word);
                while chars.peek().is_some_and(|n| *n == '>' || *n == '<') {
                    chars.next();
                }
                if chars.peek() == Some(&'&') {
                    chars.next();
                    while chars.peek().is_some_and(|n| n.is_ascii_digit() || *n == '-') {
                        chars.next();
                    }
                } else {
                    skip_next_word = true;
                }
            }
            ';' | '&' | '|' => {
                end_word(&mut word, &mut in_word, &mut words, &mut skip_next_word);
                while chars.peek().is_some_and(|n| *n == '&' || *n == '|') {
                    chars.next();
                }
                commands.push(std::mem::take(&mut words));
            }
            _ => {
                in_word = true;
                word.push(c);
            }
        }
    }
    end_word(&mut word, &mut in_word, &mut words, &mut skip_next_word);
    commands.push(words);
    commands
}

/// rackd's own arguments, if `words` runs rackd: `rackd ARGS`, `cargo run [OPTIONS]
/// [-- ARGS]` of the package's default binary, or `docker run [OPTIONS] rackd [ARGS]`.
fn rackd_args(words: &[String]) -> Option<Vec<String>> {
    let words: Vec<&str> = words
        .iter()
        .map(String::as_str)
        .skip_while(|w| ["sudo", "exec", "time"].contains(w) || is_assignment(w))
        .collect();
    match words.first().copied()? {
        "rackd" | "./target/release/rackd" | "target/release/rackd" => {
            Some(words[1..].iter().map(|w| w.to_string()).collect())
        }
        "cargo" if words.get(1) == Some(&"run") => {
            let split = words.iter().position(|w| *w == "--").unwrap_or(words.len());
            let options = &words[2..split];
            let other = options.iter().any(|w| ["--example", "--bin", "-p", "--package"].contains(w));
            (!other).then(|| words.get(split + 1..).unwrap_or(&[]).iter().map(|w| w.to_string()).collect())
        }
        // The image, named rackd, and its arguments (`--name rackd` names the container).
        "docker" | "podman" if words.get(1) == Some(&"run") => {
            let image = (2..words.len()).find(|&i| words[i] == "rackd" && words[i - 1] != "--name")?;
            Some(words[image + 1..].iter().map(|w| w.to_string()).collect())
        }
        _ => None,
    }
}

fn is_assignment(word: &str) -> bool {
    word.split_once('=').is_some_and(|(name, _)| {
        !name.is_empty() && name.chars().all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
    })
}

/// The API paths (`/api/v1/...`, query and fragment dropped) a command's words name.
fn api_paths(words: &[String]) -> Vec<String> {
    words
        .iter()
        .filter_map(|w| w.find("/api/v1/").map(|at| &w[at..]))
        .map(|p| p.split(['?', '#']).next().unwrap().trim_end_matches('/').to_owned())
        .collect()
}

/// Whether `path` is an instance of the OpenAPI path `template` (`{name}` is one segment).
fn matches_route(path: &str, template: &str) -> bool {
    let (p, t): (Vec<&str>, Vec<&str>) = (path.split('/').collect(), template.split('/').collect());
    p.len() == t.len()
        && p.iter().zip(&t).all(|(s, t)| (t.starts_with('{') && t.ends_with('}') && !s.is_empty()) || s == t)
}

#[test]
fn every_shell_block_of_the_docs_parses_as_bash() {
    let blocks = shell_blocks();
    assert!(blocks.len() >= 20, "the docs' shell blocks were found: {}", blocks.len());
    let mut wrong = Vec::new();
    for b in &blocks {
        let mut bash = Command::new("bash")
            .arg("-n")
            .stdin(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("bash runs");
        std::io::Write::write_all(&mut bash.stdin.take().unwrap(), b.text.as_bytes()).unwrap();
        let out = bash.wait_with_output().unwrap();
        if !out.status.success() {
            wrong.push(format!("{}: {}", b.at(), String::from_utf8_lossy(&out.stderr).trim()));
        }
    }
    assert!(wrong.is_empty(), "shell blocks bash refuses:\n{}", wrong.join("\n"));
}

#[test]
fn every_rackd_command_in_the_docs_parses() {
    let mut checked = 0;
    let mut wrong = Vec::new();
    for b in shell_blocks() {
        for words in commands(&b.text) {
            let Some(args) = rackd_args(&words) else { continue };
            checked += 1;
            let argv = std::iter::once("rackd".to_owned()).chain(args);
            if let Err(e) = rackd::cli::Cli::try_parse_from(argv) {
                use clap::error::ErrorKind::{DisplayHelp, DisplayVersion};
                if !matches!(e.kind(), DisplayHelp | DisplayVersion) {
                    wrong.push(format!("{}: `{}`: {}", b.at(), words.join(" "), e.render()));
                }
            }
        }
    }
    assert!(checked >= 20, "rackd commands were found in the docs: {checked}");
    assert!(wrong.is_empty(), "rackd commands its parser refuses:\n{}", wrong.join("\n"));
}

#[test]
fn every_api_path_in_the_docs_is_a_route() {
    let text = std::fs::read_to_string(root().join("openapi/openapi.json")).unwrap();
    let doc: Value = serde_json::from_str(&text).unwrap();
    let routes: Vec<&String> = doc["paths"].as_object().unwrap().keys().collect();
    let (mut checked, mut wrong) = (0, Vec::new());
    for b in shell_blocks() {
        for words in commands(&b.text) {
            for path in api_paths(&words) {
                checked += 1;
                if !routes.iter().any(|r| matches_route(&path, r)) {
                    wrong.push(format!("{}: {path}", b.at()));
                }
            }
        }
    }
    assert!(checked >= 20, "API paths were found in the docs: {checked}");
    assert!(wrong.is_empty(), "paths that are no route of openapi/openapi.json:\n{}", wrong.join("\n"));
}

#[test]
fn the_readme_opens_with_the_two_commands_and_ci_runs_its_test_command() {
    let readme = blocks(&root().join("README.md"));
    let first = readme.first().expect("the README has a fenced block");
    let two = commands(&first.text);
    assert_eq!(two.len(), 2, "the README's first block holds two commands: {}", first.text);
    assert_eq!(two[0], ["cargo", "run", "--release"], "the first runs the demo");
    let test = two[1].join(" ");
    let ci = std::fs::read_to_string(root().join(".ci/run")).unwrap();
    let runs = ci.lines().flat_map(split_line).any(|words| words.join(" ").ends_with(&test));
    assert!(runs, ".ci/run runs the README's test command `{test}`");
    let lines = std::fs::read_to_string(root().join("README.md")).unwrap().lines().count();
    assert!(lines <= 200, "the README is a front door of at most 200 lines, not {lines}");
}

#[test]
fn the_shell_splitter_finds_commands_words_and_paths() {
    let text = "B=http://x\n# a comment\ncurl -s \"$B/api/v1/jobs?state=queued\" | jq . # shown\n\
                rackd plc --address 10.0.0.5:502 \\\n  read 4x0 > out.txt 2>&1 && echo 'a # b'\n\
                cat <<'EOF'\nrackd nonsense\nEOF\ncargo run --release -- sim shelf\n\
                cargo run --release --example bench -- crane\n";
    let commands = commands(text);
    let words: Vec<String> = commands.iter().map(|c| c.join(" ")).collect();
    assert_eq!(
        words,
        [
            "B=http://x",
            "curl -s $B/api/v1/jobs?state=queued",
            "jq .",
            "rackd plc --address 10.0.0.5:502 read 4x0",
            "echo a # b",
            "cat",
            "cargo run --release -- sim shelf",
            "cargo run --release --example bench -- crane"
        ]
    );
    assert_eq!(api_paths(&commands[1]), ["/api/v1/jobs"]);
    assert_eq!(rackd_args(&commands[3]).unwrap(), ["plc", "--address", "10.0.0.5:502", "read", "4x0"]);
    assert_eq!(rackd_args(&commands[6]).unwrap(), ["sim", "shelf"]);
    assert_eq!(rackd_args(&commands[7]), None);
    assert!(matches_route("/api/v1/jobs/7/history", "/api/v1/jobs/{id}/history"));
    assert!(!matches_route("/api/v1/jobs/7/nothing", "/api/v1/jobs/{id}/history"));
}
