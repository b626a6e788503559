//! Secrets in configuration (findings: `check-config --explain` and `check-config` errors
//! printed `database.url` with its password; the URL could only come from the file or the
//! environment). The real binary, as a site runs it.

use std::path::Path;
use std::process::Command;

const PASSWORD: &str = "S3cret-Pa55word";

fn check_config(file: &Path, explain: bool) -> (bool, String, String) {
    let mut command = Command::new(env!("CARGO_BIN_EXE_rackd"));
    command.args(["check-config", file.to_str().unwrap()]);
    if explain {
        command.arg("--explain");
    }
    let out = command.output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn explain_shows_the_database_url_without_its_password() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    let url = format!("postgres://rackd:{PASSWORD}@db.plant:5432/rackd?sslmode=require");
    std::fs::write(&file, format!("[database]\nurl = \"{url}\"\n")).unwrap();
    let (ok, out, err) = check_config(&file, true);
    assert!(ok, "{err}");
    assert!(!out.contains(PASSWORD) && !err.contains(PASSWORD), "{out}{err}");
    let line = out.lines().find(|l| l.starts_with("url = ")).unwrap_or_else(|| panic!("{out}"));
    assert!(line.contains("postgres://rackd:***@db.plant:5432/rackd?sslmode=require"), "{line}");
}

#[test]
fn an_error_about_the_database_url_does_not_print_its_password() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    for url in [
        format!("mysql://rackd:{PASSWORD}@db.plant/rackd"),
        format!("postgres://rackd:{PASSWORD}@db.plant:notaport/rackd"),
        format!("postgres://rackd@db.plant/rackd?password={PASSWORD}&sslmode=sometimes"),
    ] {
        std::fs::write(&file, format!("[database]\nurl = \"{url}\"\n")).unwrap();
        let (ok, out, err) = check_config(&file, false);
        assert!(!ok && err.contains("database.url"), "{url}: {out}{err}");
        assert!(!err.contains(PASSWORD) && !out.contains(PASSWORD), "{err}");
    }
}

#[test]
fn the_database_url_comes_from_a_secret_file_and_a_bad_one_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let secret = dir.path().join("database_url");
    std::fs::write(&secret, format!("postgres://rackd:{PASSWORD}@db.plant/rackd?sslmode=require\n")).unwrap();
    let file = dir.path().join("site.toml");
    std::fs::write(&file, format!("[database]\nurl_file = {:?}\n", secret.display().to_string())).unwrap();
    let (ok, out, err) = check_config(&file, true);
    assert!(ok, "{err}");
    let line = out.lines().find(|l| l.starts_with("url = ")).unwrap_or_else(|| panic!("{out}"));
    assert!(line.contains("postgres://rackd:***@db.plant/rackd?sslmode=require"), "{line}");
    assert!(line.ends_with(&format!("# {}:1:1", secret.display())), "where it came from: {line}");
    assert!(!out.contains(PASSWORD), "{out}");

    // A file that is missing, or empty, is named with the key that names it.
    let missing = dir.path().join("nowhere");
    std::fs::write(&file, format!("[database]\nurl_file = {:?}\n", missing.display().to_string())).unwrap();
    let (ok, _, err) = check_config(&file, false);
    assert!(!ok && err.contains("site.toml:2:1: database.url_file: "), "{err}");
    assert!(err.contains(&missing.display().to_string()), "{err}");
    std::fs::write(&secret, "\n").unwrap();
    std::fs::write(&file, format!("[database]\nurl_file = {:?}\n", secret.display().to_string())).unwrap();
    let (ok, _, err) = check_config(&file, false);
    assert!(!ok && err.contains("database.url_file: ") && err.contains("empty"), "{err}");

    // Exactly one of the two.
    std::fs::write(
        &file,
        format!("[database]\nurl = \"postgres://h/db\"\nurl_file = {:?}\n", secret.display().to_string()),
    )
    .unwrap();
    let (ok, _, err) = check_config(&file, false);
    assert!(!ok && err.contains("database.url_file: ") && err.contains("database.url"), "{err}");
}

#[test]
fn explain_shows_a_webhooks_secret_as_stars_and_an_error_never_quotes_it() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    let secret = "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw";
    let entry = format!(
        "[[webhooks]]\nname = \"wms\"\nurl = \"https://rackd:{PASSWORD}@wms.plant/events\"\n\
         events = [\"*\"]\nsecret = \"{secret}\"\n"
    );
    std::fs::write(&file, &entry).unwrap();
    let (ok, out, err) = check_config(&file, true);
    assert!(ok, "{err}");
    let line = |start: &str| out.lines().find(|l| l.starts_with(start)).unwrap_or_else(|| panic!("{out}"));
    assert!(line("secret = ").starts_with("secret = \"***\""), "{out}");
    assert!(line("url = ").contains("https://rackd:***@wms.plant/events"), "{out}");
    assert!(!out.contains(&secret[6..]) && !out.contains(PASSWORD), "{out}");

    // A secret one character short of base64 is refused without being quoted.
    std::fs::write(&file, entry.replace(secret, &secret[..secret.len() - 1])).unwrap();
    let (ok, out, err) = check_config(&file, false);
    assert!(!ok && err.contains("site.toml:5:1: webhooks[0].secret: "), "{err}");
    assert!(!err.contains(&secret[6..secret.len() - 1]) && !err.contains(PASSWORD), "{out}{err}");
}
